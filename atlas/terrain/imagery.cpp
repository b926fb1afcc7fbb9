// Terrain imagery through GDAL: reprojection with GDALWarp onto the DEM's refined sample lattice,
// a global [1 2 1] pyramid, and per-chart attribute files.
#include "atlas/terrain/imagery.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>

#include <gdal_alg.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>
#include <tbb/parallel_for.h>

#include "atlas/terrain/gdal_util.h"
#include "core/progress.h"

namespace gimlod {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void fail(const fs::path& file, const std::string& what) {
  throw InputError(file.string() + ": " + what);
}

// A virtual copy of `src` (nothing is read) whose geotransform and reference system can be set.
DatasetPtr virtualCopy(GDALDataset* src, const fs::path& path, const GdalErrorCapture& cap) {
  GDALDriver* vrt = GetGDALDriverManager()->GetDriverByName("VRT");
  if (!vrt) fail(path, "GDAL has no VRT driver");
  DatasetPtr copy(vrt->CreateCopy("", src, FALSE, nullptr, nullptr, nullptr));
  if (!copy) fail(path, withGdal("cannot make a virtual copy", cap));
  return copy;
}

// The source's pixel size expressed in the DEM's units (GDAL's suggested warp output).
double pixelSizeInDemUnits(GDALDataset* src, const std::string& demWkt, const fs::path& path,
                           const GdalErrorCapture& cap) {
  CPLStringList options;
  if (!demWkt.empty() && src->GetSpatialRef()) options.SetNameValue("DST_SRS", demWkt.c_str());
  void* transformer = GDALCreateGenImgProjTransformer2(GDALDataset::ToHandle(src), nullptr, options.List());
  if (!transformer) fail(path, withGdal("cannot be transformed into the DEM's reference system", cap));
  double gt[6];
  int pixels = 0, lines = 0;
  const CPLErr err =
      GDALSuggestedWarpOutput(GDALDataset::ToHandle(src), GDALGenImgProjTransform, transformer, gt, &pixels, &lines);
  GDALDestroyGenImgProjTransformer(transformer);
  if (err != CE_None) fail(path, withGdal("cannot be placed in the DEM's reference system", cap));
  return std::sqrt(std::abs(gt[1] * gt[5]));
}

}  // namespace

void validateImageryOptions(const ImageryOptions& o) {
  if (o.scaleLog2 != kAutoImageryScale && (o.scaleLog2 < 0 || o.scaleLog2 > int(kMaxImageryScaleLog2)))
    throw InputError(optionRef("imageryScale") + " " + std::to_string(1 << std::clamp(o.scaleLog2, 0, 30)) +
                     " must be 1, 2 or 4 imagery samples per DEM sample interval");
  if (o.extent) {
    const auto& e = *o.extent;
    if (!std::all_of(e.begin(), e.end(), [](double v) { return std::isfinite(v); }) || !(e[2] > e[0]) ||
        !(e[3] > e[1]))
      throw InputError(optionRef("imageryExtent") + " must be finite WEST,SOUTH,EAST,NORTH with east > west and north > south");
  }
}

std::string imageryFileName(uint32_t id) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "imagery/chart_%04u.bin", id);
  return buf;
}

ImageryRaster loadImagery(const DemRaster& dem, const fs::path& demPath, const ImageryOptions& o) {
  validateImageryOptions(o);
  const fs::path& path = o.path;
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "no such file");
  if (fs::is_directory(path, ec)) fail(path, "is a directory, not a raster file");
  const auto& dgt = dem.georef.geotransform;
  if (dgt == std::array<double, 6>{0, 1, 0, 0, 0, 1} || dem.width < 2 || dem.height < 2)
    fail(demPath, "has no georeference, so imagery cannot be placed on it");
  registerGdalOnce();
  GdalErrorCapture cap;
  DatasetPtr src(GDALDataset::FromHandle(
      GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR, nullptr, nullptr, nullptr)));
  if (!src) fail(path, withGdal("not a raster GDAL can read", cap));
  const int bands = src->GetRasterCount();
  if (src->GetRasterXSize() < 1 || src->GetRasterYSize() < 1 || bands < 1) fail(path, "raster has no pixels");
  for (int b = 1; b <= bands; ++b) {
    GDALRasterBand* band = src->GetRasterBand(b);
    if (band->GetRasterDataType() != GDT_Byte)
      fail(path, std::string("band ") + std::to_string(b) + " is " + GDALGetDataTypeName(band->GetRasterDataType()) +
                     "; imagery must be 8-bit colour (convert with gdal_translate -ot Byte -scale)");
  }
  if (src->GetRasterBand(1)->GetColorTable())
    fail(path, "is a paletted image; expand it first (gdal_translate -expand rgba)");
  const bool alpha = bands > 1 && src->GetRasterBand(bands)->GetColorInterpretation() == GCI_AlphaBand;
  const int colourBands = bands - (alpha ? 1 : 0);
  if (colourBands != 1 && colourBands != 3)
    fail(path, std::to_string(bands) + " bands; imagery must be grey, grey + alpha, RGB or RGBA");

  ImageryRaster out;
  // The source, or a virtual copy of it carrying the georeference it lacks.
  GDALDataset* source = src.get();
  DatasetPtr placed;
  double sgt[6];
  if (source->GetGeoTransform(sgt) != CE_None) {
    if (!o.extent)
      fail(path, "has no georeference (no geotransform or world file); give " + optionRef("imageryExtent") +
                     " WEST,SOUTH,EAST,NORTH in the DEM's reference system");
    const auto& e = *o.extent;
    placed = virtualCopy(source, path, cap);
    const double gt[6] = {e[0], (e[2] - e[0]) / source->GetRasterXSize(), 0.0,
                          e[3], 0.0, -(e[3] - e[1]) / source->GetRasterYSize()};
    placed->SetGeoTransform(const_cast<double*>(gt));
    if (!dem.georef.wkt.empty()) placed->SetProjection(dem.georef.wkt.c_str());
    source = placed.get();
    source->GetGeoTransform(sgt);
  } else if (!source->GetSpatialRef() && !dem.georef.wkt.empty()) {
    out.warnings.push_back("imagery has no reference system; taken to be the DEM's");
    placed = virtualCopy(source, path, cap);
    placed->SetProjection(dem.georef.wkt.c_str());
    source = placed.get();
  }

  // Scale: the power of two nearest the DEM spacing over the imagery's pixel size.
  const double demPixel = std::sqrt(std::abs(dgt[1] * dgt[5]));
  const double ratio = demPixel / pixelSizeInDemUnits(source, dem.georef.wkt, path, cap);
  out.scaleLog2 = o.scaleLog2 != kAutoImageryScale
                      ? uint32_t(o.scaleLog2)
                      : uint32_t(std::clamp<long>(std::lround(std::log2(std::max(ratio, 1e-9))), 0,
                                                  long(kMaxImageryScaleLog2)));
  const double s = double(1u << out.scaleLog2);
  out.resampling = ratio / s > 1.5 ? "average" : "bilinear";

  // Geographic imagery spanning the globe is also placed 360 degrees east and west of itself, so
  // a DEM in 0..360 longitudes (or one crossing the antimeridian) finds it.
  std::vector<DatasetPtr> wrapped;
  std::vector<GDALDatasetH> sources{GDALDataset::ToHandle(source)};
  const OGRSpatialReference* ssrs = source->GetSpatialRef();
  const bool geographic = dem.georef.geographic && (ssrs ? bool(ssrs->IsGeographic()) : true);
  if (geographic && sgt[2] == 0.0 && std::abs(sgt[1]) * source->GetRasterXSize() >= 360.0 - 1.5 * std::abs(sgt[1])) {
    for (const double shift : {-360.0, 360.0}) {
      DatasetPtr copy = virtualCopy(source, path, cap);
      double gt[6] = {sgt[0] + shift, sgt[1], sgt[2], sgt[3], sgt[4], sgt[5]};
      copy->SetGeoTransform(gt);
      sources.push_back(GDALDataset::ToHandle(copy.get()));
      wrapped.push_back(std::move(copy));
    }
  }

  // The target: the DEM's lattice refined by s, in the DEM's raster orientation (row 0 = the
  // source DEM's first row). Target pixel centre c lies at DEM pixel coordinate c / s + 0.5.
  out.width = uint32_t((dem.width - 1) * uint64_t(s)) + 1;
  out.height = uint32_t((dem.height - 1) * uint64_t(s)) + 1;
  const int targetBands = colourBands + 1;
  GDALDriver* mem = GetGDALDriverManager()->GetDriverByName("MEM");
  if (!mem) fail(path, "GDAL has no MEM driver");
  DatasetPtr target(mem->Create("", int(out.width), int(out.height), targetBands, GDT_Byte, nullptr));
  if (!target) fail(path, withGdal("cannot allocate the reprojected imagery (" + std::to_string(out.width) + " x " +
                                       std::to_string(out.height) + ")",
                                   cap));
  const double off = 0.5 - 0.5 / s;
  double tgt[6] = {dgt[0] + off * (dgt[1] + dgt[2]), dgt[1] / s, dgt[2] / s,
                   dgt[3] + off * (dgt[4] + dgt[5]), dgt[4] / s, dgt[5] / s};
  target->SetGeoTransform(tgt);
  if (!dem.georef.wkt.empty()) target->SetProjection(dem.georef.wkt.c_str());
  target->GetRasterBand(targetBands)->SetColorInterpretation(GCI_AlphaBand);

  CPLStringList args;
  for (const char* a : {"-r", out.resampling.c_str(), "-dstalpha", "-q"}) args.AddString(a);
  GDALWarpAppOptions* wopts = GDALWarpAppOptionsNew(args.List(), nullptr);
  int usageError = 0;
  cap.clear();
  GDALDatasetH done = GDALWarp(nullptr, GDALDataset::ToHandle(target.get()), int(sources.size()), sources.data(),
                               wopts, &usageError);
  GDALWarpAppOptionsFree(wopts);
  if (!done || usageError || !cap.failures().empty())
    fail(path, withGdal("reprojection onto the DEM failed (unreadable or truncated imagery?)", cap));

  // Read back, south row first.
  const size_t n = size_t(out.width) * out.height;
  std::vector<std::vector<uint8_t>> planes(static_cast<size_t>(targetBands), std::vector<uint8_t>(n, 0));
  for (int b = 0; b < targetBands; ++b)
    if (target->GetRasterBand(b + 1)->RasterIO(GF_Read, 0, 0, int(out.width), int(out.height), planes[b].data(),
                                               int(out.width), int(out.height), GDT_Byte, 0, 0) != CE_None)
      fail(path, withGdal("cannot read the reprojected imagery", cap));
  const bool flip = dgt[5] < 0;  // as loadDem: GDAL row 0 is north for north-up rasters
  out.rgba.resize(n);
  uint64_t covered = 0;
  for (uint32_t q = 0; q < out.height; ++q) {
    const size_t row = size_t(flip ? out.height - 1 - q : q) * out.width;
    for (uint32_t x = 0; x < out.width; ++x) {
      const size_t i = size_t(q) * out.width + x;
      const uint8_t a = planes[size_t(targetBands) - 1][i];
      const uint8_t r = planes[0][i];
      out.rgba[row + x] = colourBands == 1 ? PackedColour{r, r, r, a} : PackedColour{r, planes[1][i], planes[2][i], a};
      covered += a > 0;
    }
  }
  out.coverage = double(covered) / double(n);
  if (covered == 0) fail(path, "does not overlap the DEM " + demPath.string());
  for (const std::string& w : cap.warnings()) out.warnings.push_back(w);
  return out;
}

ImageryPyramid::ImageryPyramid(const ImageryRaster& raster, uint32_t chartsX, uint32_t chartsY, uint32_t chartSize,
                               uint32_t levels)
    : chartIntervals_((chartSize - 1) << raster.scaleLog2) {
  if (raster.rgba.size() != size_t(raster.width) * raster.height || raster.width == 0 || levels == 0 ||
      (chartIntervals_ >> (levels - 1)) == 0)
    throw std::invalid_argument("ImageryPyramid: inconsistent raster or levels");
  levels_.resize(levels);
  Level& base = levels_[0];
  base.width = chartsX * chartIntervals_ + 1;
  base.height = chartsY * chartIntervals_ + 1;
  base.rgba.resize(size_t(base.width) * base.height);
  for (uint32_t y = 0; y < base.height; ++y) {
    const size_t src = size_t(std::min(y, raster.height - 1)) * raster.width;
    for (uint32_t x = 0; x < base.width; ++x)
      base.rgba[size_t(y) * base.width + x] = raster.rgba[src + std::min(x, raster.width - 1)];
  }
  for (uint32_t k = 1; k < levels; ++k) {
    const Level& f = levels_[k - 1];
    Level& c = levels_[k];
    c.width = (f.width - 1) / 2 + 1;
    c.height = (f.height - 1) / 2 + 1;
    c.rgba.resize(size_t(c.width) * c.height);
    tbb::parallel_for(uint32_t(0), c.height, [&](uint32_t y) {
      const uint32_t fy[3] = {y > 0 ? 2 * y - 1 : 0, 2 * y, std::min(2 * y + 1, f.height - 1)};
      for (uint32_t x = 0; x < c.width; ++x) {
        const uint32_t fx[3] = {x > 0 ? 2 * x - 1 : 0, 2 * x, std::min(2 * x + 1, f.width - 1)};
        uint32_t sum[4] = {0, 0, 0, 0};
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < 3; ++i) {
            const uint32_t w = (i == 1 ? 2u : 1u) * (j == 1 ? 2u : 1u);
            const PackedColour& p = f.rgba[size_t(fy[j]) * f.width + fx[i]];
            for (int ch = 0; ch < 4; ++ch) sum[ch] += w * p[size_t(ch)];
          }
        PackedColour& o = c.rgba[size_t(y) * c.width + x];
        for (int ch = 0; ch < 4; ++ch) o[size_t(ch)] = uint8_t((sum[ch] + 8) >> 4);
      }
    });
  }
}

ChartPyramid ImageryPyramid::chart(int32_t gridX, int32_t gridY) const {
  ChartPyramid p;
  p.colours.resize(levels_.size());
  for (uint32_t k = 0; k < levels_.size(); ++k) {
    const Level& l = levels_[k];
    const uint32_t side = (chartIntervals_ >> k) + 1;
    const size_t ox = (size_t(gridX) * chartIntervals_) >> k, oy = (size_t(gridY) * chartIntervals_) >> k;
    auto& c = p.colours[k];
    c.resize(size_t(side) * side);
    for (uint32_t v = 0; v < side; ++v)
      std::copy_n(l.rgba.begin() + std::ptrdiff_t((oy + v) * l.width + ox), side, c.begin() + std::ptrdiff_t(v) * side);
  }
  return p;
}

ImageryWriteStats writeImageryCharts(const ImageryRaster& raster, const std::string& source, const fs::path& dir,
                                     AtlasManifest& m) {
  const auto start = std::chrono::steady_clock::now();
  std::error_code ec;
  fs::create_directories(dir / "imagery", ec);
  if (ec || !fs::is_directory(dir / "imagery"))
    throw InputError((dir / "imagery").string() + ": cannot create directory: " +
                     (ec ? ec.message() : std::string("not a directory")));
  const uint32_t levels = m.intervalsLog2() + 1;
  const ImageryPyramid pyramid(raster, m.chartsX, m.chartsY, m.chartSize, levels);
  m.imagery.present = true;
  m.imagery.scaleLog2 = raster.scaleLog2;
  m.imagery.source = source;
  m.imagery.coverage = raster.coverage;
  const uint32_t chartSize = m.imagery.chartSize(m.chartSize);
  const uint32_t blockIntervals = m.blockIntervals << raster.scaleLog2;
  std::atomic<uint64_t> bytes{0}, samples{0};
  const progress::ProgressStage stage("imagery charts", m.charts.size());
  tbb::parallel_for(size_t{0}, m.charts.size(), [&](size_t i) {
    ChartInfo& c = m.charts[i];
    c.imageryFile = imageryFileName(c.id);
    const ChartPyramid p = pyramid.chart(c.gridX, c.gridY);
    uint64_t n = 0;
    for (const auto& level : p.colours) n += level.size();
    samples += n;
    ChartCoding coding;
    coding.compressed = m.compression.present;  // coded like the atlas's geometry
    bytes += writeChartFile(dir / c.imageryFile, p, chartSize, blockIntervals, coding);
    progress::advance();
  });
  ImageryWriteStats st;
  st.bytesOnDisk = bytes.load();
  st.storedSamples = samples.load();
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

}  // namespace gimlod

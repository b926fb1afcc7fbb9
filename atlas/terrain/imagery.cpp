// Terrain imagery through GDAL: reprojection with GDALWarp onto the DEM's refined sample lattice,
// a global [1 2 1] pyramid, and per-chart attribute files.
#include "atlas/terrain/imagery.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <list>
#include <stdexcept>

#include <gdal_alg.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>
#include <tbb/parallel_for.h>

#include "atlas/terrain/gdal_util.h"
#include "atlas/terrain/terrain_atlas.h"
#include "core/progress.h"

namespace gimlod {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void fail(const fs::path& file, const std::string& what) { throw InputError(file.string() + ": " + what); }

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
    if (!std::all_of(e.begin(), e.end(), [](double v) { return std::isfinite(v); }) || !(e[2] > e[0]) || !(e[3] > e[1]))
      throw InputError(optionRef("imageryExtent") +
                       " must be finite WEST,SOUTH,EAST,NORTH with east > west and north > south");
  }
}

std::string imageryFileName(uint32_t id) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "imagery/chart_%04u.bin", id);
  return buf;
}

struct ImagerySource::Impl {
  fs::path path;
  DatasetPtr src, placed;
  std::vector<DatasetPtr> wrapped;
  std::vector<GDALDatasetH> sources;
  std::string wkt;
  std::array<double, 6> tgt{};  // the whole lattice's geotransform, GDAL row order
  bool flip = false;            // GDAL row 0 is north (as loadDem: rows are turned south first)
  int colourBands = 0;
  uint32_t scaleLog2 = 0, width = 0, height = 0;
  std::string resampling;
  std::vector<std::string> warnings;

  // Warped tiles kept for the next windows (GDAL row order, tw x th), least recently used first.
  struct Tile {
    uint64_t key = 0;
    std::vector<PackedColour> rgba;
  };
  std::list<Tile> cache;
  uint64_t cacheTiles = 0;  // the most tiles kept

  // GDAL-order tile (tx, ty) of the lattice, tw x th samples, warped (or from the cache).
  const std::vector<PackedColour>& tile(uint32_t tx, uint32_t ty, uint32_t tw, uint32_t th) {
    const uint64_t key = (uint64_t(ty) << 32) | tx;
    for (auto it = cache.begin(); it != cache.end(); ++it)
      if (it->key == key) {
        cache.splice(cache.end(), cache, it);
        return cache.back().rgba;
      }
    std::vector<std::vector<uint8_t>> planes;
    warpTile(tx, ty, tw, th, planes);
    Tile t{key, std::vector<PackedColour>(size_t(tw) * th)};
    const uint8_t* a = planes.back().data();
    for (size_t i = 0; i < t.rgba.size(); ++i) {
      const uint8_t r = planes[0][i];
      t.rgba[i] = colourBands == 1 ? PackedColour{r, r, r, a[i]} : PackedColour{r, planes[1][i], planes[2][i], a[i]};
    }
    while (!cache.empty() && cache.size() >= std::max<uint64_t>(cacheTiles, 1)) cache.pop_front();
    cache.push_back(std::move(t));
    return cache.back().rgba;
  }

  // GDAL-order tile (tx, ty) of the lattice, warped into `planes` (its bands, row-major).
  void warpTile(uint32_t tx, uint32_t ty, uint32_t tw, uint32_t th, std::vector<std::vector<uint8_t>>& planes) {
    GdalErrorCapture cap;
    const int targetBands = colourBands + 1;
    GDALDriver* mem = GetGDALDriverManager()->GetDriverByName("MEM");
    if (!mem) fail(path, "GDAL has no MEM driver");
    DatasetPtr target(mem->Create("", int(tw), int(th), targetBands, GDT_Byte, nullptr));
    if (!target) fail(path, withGdal("cannot allocate a reprojection tile", cap));
    const double x = double(tx) * kImageryTile, y = double(ty) * kImageryTile;
    double gt[6] = {tgt[0] + x * tgt[1] + y * tgt[2], tgt[1], tgt[2], tgt[3] + x * tgt[4] + y * tgt[5], tgt[4], tgt[5]};
    target->SetGeoTransform(gt);
    if (!wkt.empty()) target->SetProjection(wkt.c_str());
    target->GetRasterBand(targetBands)->SetColorInterpretation(GCI_AlphaBand);
    CPLStringList args;
    for (const char* a : {"-r", resampling.c_str(), "-dstalpha", "-q"}) args.AddString(a);
    GDALWarpAppOptions* wopts = GDALWarpAppOptionsNew(args.List(), nullptr);
    int usageError = 0;
    cap.clear();
    GDALDatasetH done =
        GDALWarp(nullptr, GDALDataset::ToHandle(target.get()), int(sources.size()), sources.data(), wopts, &usageError);
    GDALWarpAppOptionsFree(wopts);
    if (!done || usageError || !cap.failures().empty())
      fail(path, withGdal("reprojection onto the DEM failed (unreadable or truncated imagery?)", cap));
    planes.assign(size_t(targetBands), std::vector<uint8_t>(size_t(tw) * th, 0));
    for (int b = 0; b < targetBands; ++b)
      if (target->GetRasterBand(b + 1)->RasterIO(GF_Read, 0, 0, int(tw), int(th), planes[size_t(b)].data(), int(tw),
                                                 int(th), GDT_Byte, 0, 0) != CE_None)
        fail(path, withGdal("cannot read the reprojected imagery", cap));
    for (const std::string& w : cap.warnings())
      if (warnings.size() < 8 && std::find(warnings.begin(), warnings.end(), w) == warnings.end())
        warnings.push_back(w);
  }
};

ImagerySource::ImagerySource(const DemRaster& dem, const fs::path& demPath, const ImageryOptions& o)
    : impl_(std::make_unique<Impl>()) {
  validateImageryOptions(o);
  Impl& im = *impl_;
  const fs::path& path = o.path;
  im.path = path;
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "no such file");
  if (fs::is_directory(path, ec)) fail(path, "is a directory, not a raster file");
  const auto& dgt = dem.georef.geotransform;
  if (dgt == std::array<double, 6>{0, 1, 0, 0, 0, 1} || dem.width < 2 || dem.height < 2)
    fail(demPath, "has no georeference, so imagery cannot be placed on it");
  registerGdalOnce();
  GdalErrorCapture cap;
  im.src.reset(GDALDataset::FromHandle(
      GDALOpenEx(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR, nullptr, nullptr, nullptr)));
  if (!im.src) fail(path, withGdal("not a raster GDAL can read", cap));
  const int bands = im.src->GetRasterCount();
  if (im.src->GetRasterXSize() < 1 || im.src->GetRasterYSize() < 1 || bands < 1) fail(path, "raster has no pixels");
  for (int b = 1; b <= bands; ++b) {
    GDALRasterBand* band = im.src->GetRasterBand(b);
    if (band->GetRasterDataType() != GDT_Byte)
      fail(path, std::string("band ") + std::to_string(b) + " is " + GDALGetDataTypeName(band->GetRasterDataType()) +
                     "; imagery must be 8-bit colour (convert with gdal_translate -ot Byte -scale)");
  }
  if (im.src->GetRasterBand(1)->GetColorTable())
    fail(path, "is a paletted image; expand it first (gdal_translate -expand rgba)");
  const bool alpha = bands > 1 && im.src->GetRasterBand(bands)->GetColorInterpretation() == GCI_AlphaBand;
  im.colourBands = bands - (alpha ? 1 : 0);
  if (im.colourBands != 1 && im.colourBands != 3)
    fail(path, std::to_string(bands) + " bands; imagery must be grey, grey + alpha, RGB or RGBA");

  // The source, or a virtual copy of it carrying the georeference it lacks.
  GDALDataset* source = im.src.get();
  double sgt[6];
  if (source->GetGeoTransform(sgt) != CE_None) {
    if (!o.extent)
      fail(path, "has no georeference (no geotransform or world file); give " + optionRef("imageryExtent") +
                     " WEST,SOUTH,EAST,NORTH in the DEM's reference system");
    const auto& e = *o.extent;
    im.placed = virtualCopy(source, path, cap);
    const double gt[6] = {e[0], (e[2] - e[0]) / source->GetRasterXSize(), 0.0, e[3],
                          0.0,  -(e[3] - e[1]) / source->GetRasterYSize()};
    im.placed->SetGeoTransform(const_cast<double*>(gt));
    if (!dem.georef.wkt.empty()) im.placed->SetProjection(dem.georef.wkt.c_str());
    source = im.placed.get();
    source->GetGeoTransform(sgt);
  } else if (!source->GetSpatialRef() && !dem.georef.wkt.empty()) {
    im.warnings.push_back("imagery has no reference system; taken to be the DEM's");
    im.placed = virtualCopy(source, path, cap);
    im.placed->SetProjection(dem.georef.wkt.c_str());
    source = im.placed.get();
  }

  // Scale: the power of two nearest the DEM spacing over the imagery's pixel size.
  const double demPixel = std::sqrt(std::abs(dgt[1] * dgt[5]));
  const double ratio = demPixel / pixelSizeInDemUnits(source, dem.georef.wkt, path, cap);
  im.scaleLog2 =
      o.scaleLog2 != kAutoImageryScale
          ? uint32_t(o.scaleLog2)
          : uint32_t(std::clamp<long>(std::lround(std::log2(std::max(ratio, 1e-9))), 0, long(kMaxImageryScaleLog2)));
  const double s = double(1u << im.scaleLog2);
  im.resampling = ratio / s > 1.5 ? "average" : "bilinear";

  // Geographic imagery spanning the globe is also placed 360 degrees east and west of itself, so
  // a DEM in 0..360 longitudes (or one crossing the antimeridian) finds it.
  im.sources.push_back(GDALDataset::ToHandle(source));
  const OGRSpatialReference* ssrs = source->GetSpatialRef();
  const bool geographic = dem.georef.geographic && (ssrs ? bool(ssrs->IsGeographic()) : true);
  if (geographic && sgt[2] == 0.0 && std::abs(sgt[1]) * source->GetRasterXSize() >= 360.0 - 1.5 * std::abs(sgt[1])) {
    for (const double shift : {-360.0, 360.0}) {
      DatasetPtr copy = virtualCopy(source, path, cap);
      double gt[6] = {sgt[0] + shift, sgt[1], sgt[2], sgt[3], sgt[4], sgt[5]};
      copy->SetGeoTransform(gt);
      im.sources.push_back(GDALDataset::ToHandle(copy.get()));
      im.wrapped.push_back(std::move(copy));
    }
  }

  // The target: the DEM's lattice refined by s, in the DEM's raster orientation (row 0 = the
  // source DEM's first row). Target pixel centre c lies at DEM pixel coordinate c / s + 0.5.
  im.width = uint32_t((dem.width - 1) * uint64_t(s)) + 1;
  im.height = uint32_t((dem.height - 1) * uint64_t(s)) + 1;
  const double off = 0.5 - 0.5 / s;
  im.tgt = {dgt[0] + off * (dgt[1] + dgt[2]), dgt[1] / s, dgt[2] / s,
            dgt[3] + off * (dgt[4] + dgt[5]), dgt[4] / s, dgt[5] / s};
  im.wkt = dem.georef.wkt;
  im.flip = dgt[5] < 0;
  for (const std::string& w : cap.warnings()) im.warnings.push_back(w);
}

ImagerySource::~ImagerySource() = default;
uint32_t ImagerySource::scaleLog2() const { return impl_->scaleLog2; }
uint32_t ImagerySource::width() const { return impl_->width; }
uint32_t ImagerySource::height() const { return impl_->height; }
const std::string& ImagerySource::resampling() const { return impl_->resampling; }
std::vector<std::string> ImagerySource::warnings() const { return impl_->warnings; }
void ImagerySource::keepTiles(uint64_t bytes) {
  impl_->cacheTiles = bytes / (uint64_t(kImageryTile) * kImageryTile * sizeof(PackedColour));
  while (impl_->cache.size() > impl_->cacheTiles) impl_->cache.pop_front();
}

std::vector<PackedColour> ImagerySource::window(uint32_t x0, uint32_t y0, uint32_t w, uint32_t h) const {
  Impl& im = *impl_;
  if (w == 0 || h == 0 || x0 + uint64_t(w) > im.width || y0 + uint64_t(h) > im.height)
    throw std::invalid_argument("ImagerySource::window: outside the lattice");
  std::vector<PackedColour> out(size_t(w) * h);
  // GDAL rows of the window (row 0 of the lattice is south).
  const uint32_t g0 = im.flip ? im.height - (y0 + h) : y0;
  for (uint32_t ty = g0 / kImageryTile; ty * uint64_t(kImageryTile) < g0 + uint64_t(h); ++ty)
    for (uint32_t tx = x0 / kImageryTile; tx * uint64_t(kImageryTile) < x0 + uint64_t(w); ++tx) {
      const uint32_t tx0 = tx * kImageryTile, ty0 = ty * kImageryTile;
      const uint32_t tw = std::min(kImageryTile, im.width - tx0), th = std::min(kImageryTile, im.height - ty0);
      const std::vector<PackedColour>& t = im.tile(tx, ty, tw, th);
      const uint32_t gx0 = std::max(tx0, x0), gx1 = std::min(tx0 + tw, x0 + w);
      for (uint32_t gy = std::max(ty0, g0); gy < std::min(ty0 + th, g0 + h); ++gy) {
        const uint32_t q = im.flip ? im.height - 1 - gy : gy;  // lattice row, south first
        std::copy(t.begin() + std::ptrdiff_t(size_t(gy - ty0) * tw + (gx0 - tx0)),
                  t.begin() + std::ptrdiff_t(size_t(gy - ty0) * tw + (gx1 - tx0)),
                  out.begin() + std::ptrdiff_t(size_t(q - y0) * w + (gx0 - x0)));
      }
    }
  return out;
}

ImageryRaster loadImagery(const DemRaster& dem, const fs::path& demPath, const ImageryOptions& o) {
  const ImagerySource source(dem, demPath, o);
  ImageryRaster out;
  out.scaleLog2 = source.scaleLog2();
  out.width = source.width();
  out.height = source.height();
  out.resampling = source.resampling();
  out.rgba = source.window(0, 0, out.width, out.height);
  const uint64_t covered =
      uint64_t(std::count_if(out.rgba.begin(), out.rgba.end(), [](const PackedColour& c) { return c[3] > 0; }));
  out.coverage = double(covered) / double(out.rgba.size());
  if (covered == 0) fail(o.path, "does not overlap the DEM " + demPath.string());
  out.warnings = source.warnings();
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
  buildLevels(levels, base.width, base.height);
}

ImageryPyramid::ImageryPyramid(std::vector<PackedColour> rgba, const ImageryWindow& window, const ImageryGrid& grid,
                               uint32_t levels)
    : chartIntervals_((grid.chartSize - 1) << grid.scaleLog2) {
  const uint32_t x0 = window.x0, y0 = window.y0, w = window.w, h = window.h;
  const uint32_t chartsX = grid.chartsX, chartsY = grid.chartsY;
  const uint32_t align = levels == 0 ? 1 : 1u << (levels - 1);
  if (levels == 0 || (chartIntervals_ >> (levels - 1)) == 0 || rgba.size() != size_t(w) * h || w == 0 || h == 0 ||
      x0 % align || y0 % align || x0 + uint64_t(w) > uint64_t(chartsX) * chartIntervals_ + 1 ||
      y0 + uint64_t(h) > uint64_t(chartsY) * chartIntervals_ + 1)
    throw std::invalid_argument("ImageryPyramid: inconsistent window or levels");
  levels_.resize(levels);
  levels_[0] = {x0, y0, w, h, std::move(rgba)};
  buildLevels(levels, chartsX * chartIntervals_ + 1, chartsY * chartIntervals_ + 1);
}

void ImageryPyramid::buildLevels(uint32_t levels, uint32_t gridWidth, uint32_t gridHeight) {
  for (uint32_t k = 1; k < levels; ++k) {
    const Level& f = levels_[k - 1];
    Level& c = levels_[k];
    const uint32_t x0 = levels_[0].x0, y0 = levels_[0].y0;
    c.x0 = x0 >> k;
    c.y0 = y0 >> k;
    c.width = ((x0 + levels_[0].width - 1) >> k) - c.x0 + 1;
    c.height = ((y0 + levels_[0].height - 1) >> k) - c.y0 + 1;
    // The whole finer level's last sample, and the window's: the filter clamps to both (the same
    // on the whole grid).
    const uint32_t fLastX = std::min((gridWidth - 1) >> (k - 1), f.x0 + f.width - 1);
    const uint32_t fLastY = std::min((gridHeight - 1) >> (k - 1), f.y0 + f.height - 1);
    c.rgba.resize(size_t(c.width) * c.height);
    tbb::parallel_for(uint32_t(0), c.height, [&](uint32_t y) {
      const uint32_t gy = c.y0 + y;
      uint32_t fy[3] = {gy > 0 ? 2 * gy - 1 : 0, 2 * gy, std::min(2 * gy + 1, fLastY)};
      for (uint32_t& v : fy) v = std::max(v, f.y0) - f.y0;
      for (uint32_t x = 0; x < c.width; ++x) {
        const uint32_t gx = c.x0 + x;
        uint32_t fx[3] = {gx > 0 ? 2 * gx - 1 : 0, 2 * gx, std::min(2 * gx + 1, fLastX)};
        for (uint32_t& v : fx) v = std::max(v, f.x0) - f.x0;
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
    const size_t gx = (size_t(gridX) * chartIntervals_) >> k, gy = (size_t(gridY) * chartIntervals_) >> k;
    if (gx < l.x0 || gy < l.y0 || gx + side > size_t(l.x0) + l.width || gy + side > size_t(l.y0) + l.height)
      throw std::invalid_argument("ImageryPyramid::chart: the chart is outside the window");
    const size_t ox = gx - l.x0, oy = gy - l.y0;
    auto& c = p.colours[k];
    c.resize(size_t(side) * side);
    for (uint32_t v = 0; v < side; ++v)
      std::copy_n(l.rgba.begin() + std::ptrdiff_t((oy + v) * l.width + ox), side, c.begin() + std::ptrdiff_t(v) * side);
  }
  return p;
}

const PackedColour* ImageryPyramid::at(uint32_t k, uint64_t x, uint64_t y) const {
  const Level& l = levels_.at(k);
  if (x < l.x0 || y < l.y0 || x >= uint64_t(l.x0) + l.width || y >= uint64_t(l.y0) + l.height)
    throw std::invalid_argument("ImageryPyramid::at: outside the window");
  return l.rgba.data() + (y - l.y0) * l.width + (x - l.x0);
}

namespace {

void makeImageryDir(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir / "imagery", ec);
  if (ec || !fs::is_directory(dir / "imagery"))
    throw InputError((dir / "imagery").string() +
                     ": cannot create directory: " + (ec ? ec.message() : std::string("not a directory")));
}

void setImageryInfo(AtlasManifest& m, uint32_t scaleLog2, const std::string& source, double coverage) {
  m.imagery.present = true;
  m.imagery.scaleLog2 = scaleLog2;
  m.imagery.source = source;
  m.imagery.coverage = coverage;
}

// A square of one pyramid level that a chart file's level holds: its sample (0, 0) at `origin`,
// rows `stride` apart, `intervals` a side, in the file's blocks from (bx0, by0).
struct ColourSquare {
  const PackedColour* origin = nullptr;
  size_t stride = 0;
  uint32_t intervals = 0, fileLevel = 0, bx0 = 0, by0 = 0;
};

// The square's blocks of `file` (of min(blockIntervals, intervals) a side), coded in parallel, in
// the file's order (rows of blocks); returns their samples.
uint64_t writeColourSquare(const ColourSquare& sq, ChartFileWriter& file) {
  const uint32_t b = std::min(file.blockIntervals(), sq.intervals);
  const uint32_t n = sq.intervals / b;
  std::vector<ChartFileWriter::CodedBlock> blocks(size_t(n) * n);
  tbb::parallel_for(size_t{0}, blocks.size(), [&](size_t i) {
    const uint32_t bx = uint32_t(i % n), by = uint32_t(i / n);
    BlockData d;
    d[kChannelColours] = {sq.origin + size_t(by) * b * sq.stride + size_t(bx) * b, sq.stride};
    blocks[i] = file.code(sq.fileLevel, sq.bx0 + bx, sq.by0 + by, d);
  });
  for (const auto& block : blocks) file.append(block);
  return uint64_t(sq.intervals + 1) * (sq.intervals + 1);
}

// The colours of the antimeridian on a planet whose charts circle it: the west border column of the
// first column of charts, per chart row and level, which the last column of charts takes as its
// east border (the same place), so that both hold the same colours at every level. A coarser
// level's filter is edge-clamped on either side of the antimeridian; without this the two borders
// would differ where the colours change across it, and level 0's last column is the imagery's
// east edge as reprojected, not its west edge.
class AntimeridianColumns {
 public:
  explicit AntimeridianColumns(const AtlasManifest& m)
      : ci_(uint64_t(m.chartSize - 1) << m.imagery.scaleLog2),
        east_(m.chartsX - 1),
        active_(m.planet.present && m.planet.wrapColumns != 0 &&
                uint64_t(m.chartsX) * (m.chartSize - 1) == m.planet.wrapColumns) {
    if (!active_) return;
    columns_.assign(m.chartsY, std::vector<std::vector<PackedColour>>(m.pyramidLevels()));
    for (auto& row : columns_)
      for (uint32_t k = 0; k < row.size(); ++k) row[k].resize(size_t(ci_ >> k) + 1);
  }
  bool east(const ChartInfo& c) const { return active_ && uint32_t(c.gridX) == east_; }
  // Records rows [y0, y0 + n] of chart row gy's west border at file level k from `pyramid`'s level
  // k - first, which holds them.
  void record(const ImageryPyramid& pyramid, uint32_t first, uint32_t k, uint32_t gy, uint64_t y0, uint64_t n) {
    if (!active_) return;
    const uint64_t y = (uint64_t(gy) * ci_ >> k) + y0;
    const PackedColour* p = pyramid.at(k - first, 0, y);
    for (uint64_t v = 0; v <= n; ++v) columns_[gy][k][size_t(y0 + v)] = p[v * pyramid.stride(k - first)];
  }
  // The levels first and up of every chart row's west border, from a pyramid of the whole grid.
  void recordAll(const ImageryPyramid& pyramid, uint32_t first) {
    for (uint32_t gy = 0; active_ && gy < columns_.size(); ++gy)
      for (uint32_t k = first; k < columns_[gy].size(); ++k) record(pyramid, first, k, gy, 0, ci_ >> k);
  }
  // `sq`, rows [y0, y0 + sq.intervals] of chart row gy's east border chart at its level, with its
  // last column the west border's (copied into `buffer`).
  ColourSquare eastBorder(const ColourSquare& sq, uint32_t gy, uint64_t y0, std::vector<PackedColour>& buffer) const {
    const size_t side = size_t(sq.intervals) + 1;
    buffer.resize(side * side);
    const std::vector<PackedColour>& west = columns_[gy][sq.fileLevel];
    for (size_t v = 0; v < side; ++v) {
      std::copy_n(sq.origin + v * sq.stride, side - 1, buffer.begin() + std::ptrdiff_t(v * side));
      buffer[v * side + side - 1] = west[size_t(y0) + v];
    }
    ColourSquare out = sq;
    out.origin = buffer.data();
    out.stride = side;
    return out;
  }

 private:
  uint64_t ci_ = 0;
  uint32_t east_ = 0;
  bool active_ = false;
  std::vector<std::vector<std::vector<PackedColour>>> columns_;  // [gridY][level][row]
};

ChartFileShape imageryShape(const AtlasManifest& m) {
  return {m.imagery.chartSize(m.chartSize), m.blockIntervals << m.imagery.scaleLog2, m.pyramidLevels(),
          1u << kChannelColours};
}

ChartCoding imageryCoding(const AtlasManifest& m) {
  ChartCoding coding;
  coding.compressed = m.compression.present;  // coded like the atlas's geometry
  return coding;
}

std::unique_ptr<ChartFileWriter> openImageryChart(const fs::path& dir, const AtlasManifest& m, ChartInfo& c) {
  c.imageryFile = imageryFileName(c.id);
  return std::make_unique<ChartFileWriter>(dir / c.imageryFile, imageryShape(m), imageryCoding(m));
}

// Levels first and up of chart `c`'s file, cut from `pyramid` whose level 0 is the file's level
// `first`; returns their samples.
// A chart at the antimeridian's east side takes its east border from `seam`.
uint64_t writeChartLevels(const ImageryPyramid& pyramid, uint32_t first, const AtlasManifest& m, const ChartInfo& c,
                          ChartFileWriter& file, const AntimeridianColumns& seam) {
  const uint64_t ci = uint64_t(m.chartSize - 1) << m.imagery.scaleLog2;
  uint64_t samples = 0;
  std::vector<PackedColour> buffer;
  for (uint32_t k = first; k < m.pyramidLevels(); ++k) {
    const uint32_t j = k - first;
    const uint64_t x = (uint64_t(c.gridX) * ci) >> k, y = (uint64_t(c.gridY) * ci) >> k;
    ColourSquare sq{pyramid.at(j, x, y), pyramid.stride(j), uint32_t(ci >> k), k, 0, 0};
    if (seam.east(c)) sq = seam.eastBorder(sq, uint32_t(c.gridY), 0, buffer);
    samples += writeColourSquare(sq, file);
  }
  return samples;
}

// Writes chart `c`'s imagery file, cut from `pyramid`; returns its bytes and adds its samples.
uint64_t writeImageryChart(const ImageryPyramid& pyramid, const fs::path& dir, const AtlasManifest& m, ChartInfo& c,
                           std::atomic<uint64_t>& samples, const AntimeridianColumns& seam) {
  const auto file = openImageryChart(dir, m, c);
  samples += writeChartLevels(pyramid, 0, m, c, *file, seam);
  return file->commit();
}

// The grid's level-0 samples of `window` (the lattice edge-clamped onto the chart grid),
// reprojected by `imagery`; adds to `covered` the lattice samples with alpha > 0 in the part the
// caller owns, owned = {x0, y0, x1, y1} (half-open; empty where it owns none).
std::vector<PackedColour> gridWindow(const ImagerySource& imagery, const ImageryWindow& window,
                                     const std::array<uint64_t, 4>& owned, uint64_t& covered) {
  const uint64_t x0 = window.x0, y0 = window.y0, x1 = x0 + window.w, y1 = y0 + window.h;
  const uint32_t latW = imagery.width(), latH = imagery.height();
  const uint32_t lx0 = uint32_t(std::min<uint64_t>(x0, latW - 1)), ly0 = uint32_t(std::min<uint64_t>(y0, latH - 1));
  const uint32_t lx1 = std::max(uint32_t(std::min<uint64_t>(x1, latW)), lx0 + 1);
  const uint32_t ly1 = std::max(uint32_t(std::min<uint64_t>(y1, latH)), ly0 + 1);
  const std::vector<PackedColour> lattice = imagery.window(lx0, ly0, lx1 - lx0, ly1 - ly0);
  const uint32_t lw = lx1 - lx0;
  for (uint64_t y = owned[1]; y < std::min<uint64_t>(owned[3], latH); ++y)
    for (uint64_t x = owned[0]; x < std::min<uint64_t>(owned[2], latW); ++x)
      covered += lattice[size_t(y - ly0) * lw + size_t(x - lx0)][3] > 0;
  const uint32_t w = uint32_t(x1 - x0), h = uint32_t(y1 - y0);
  std::vector<PackedColour> base(size_t(w) * h);
  for (uint32_t y = 0; y < h; ++y) {
    const size_t src = size_t(std::min<uint64_t>(y0 + y, latH - 1) - ly0) * lw;
    for (uint32_t x = 0; x < w; ++x)
      base[size_t(y) * w + x] = lattice[src + (std::min<uint64_t>(x0 + x, latW - 1) - lx0)];
  }
  return base;
}

}  // namespace

ImageryWriteStats writeImageryCharts(const ImageryRaster& raster, const std::string& source, const fs::path& dir,
                                     AtlasManifest& m) {
  const auto start = std::chrono::steady_clock::now();
  makeImageryDir(dir);
  const ImageryPyramid pyramid(raster, m.chartsX, m.chartsY, m.chartSize, m.intervalsLog2() + 1);
  setImageryInfo(m, raster.scaleLog2, source, raster.coverage);
  AntimeridianColumns seam(m);
  seam.recordAll(pyramid, 0);
  std::atomic<uint64_t> bytes{0}, samples{0};
  const progress::ProgressStage stage("imagery charts", m.charts.size());
  tbb::parallel_for(size_t{0}, m.charts.size(), [&](size_t i) {
    bytes += writeImageryChart(pyramid, dir, m, m.charts[i], samples, seam);
    progress::advance();
  });
  ImageryWriteStats st;
  st.bytesOnDisk = bytes.load();
  st.storedSamples = samples.load();
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

namespace {

// Samples in every level of a chart's imagery of `ci` level-0 intervals.
uint64_t chartSamples(uint64_t ci, uint32_t levels) {
  uint64_t n = 0;
  for (uint32_t k = 0; k < levels; ++k) n += ((ci >> k) + 1) * ((ci >> k) + 1);
  return n;
}

// The tiles of a chart grid's imagery (tiling p.t, scaled by the imagery's scale) that the charts
// p.selected flags hold, each reprojected with a margin of 2^coarseLevel level-0 samples into its
// levels below the coarse level (written into the chart's file in `files`) and its coarse level
// (into p.coarse, the whole grid's level, cw x ch). A chart row whose east chart is selected at the
// antimeridian also takes the first column's west tiles, whose border its east border is.
struct TilePass {
  ChartTiling t;
  std::vector<uint8_t> selected;  // by chart
  std::vector<PackedColour> coarse;
  uint64_t cw = 0, ch = 0;
  uint64_t covered = 0, windows = 0, most = 0;
};

void passImageryTiles(ImagerySource& imagery, const fs::path& dir, AtlasManifest& m,
                      std::vector<std::unique_ptr<ChartFileWriter>>& files, AntimeridianColumns& seam, TilePass& p) {
  const ChartTiling& t = p.t;
  const uint32_t s = imagery.scaleLog2(), kc = t.coarseLevel, per = t.tilesPerSide;
  const uint64_t ci = uint64_t(m.chartSize - 1) << s, tile = uint64_t(t.tile) << s, margin = uint64_t(1) << kc;
  const uint64_t gridW = m.chartsX * ci + 1, gridH = m.chartsY * ci + 1;
  const uint64_t latW = imagery.width(), latH = imagery.height();
  std::vector<int64_t> at(size_t(m.chartsX) * m.chartsY, -1);
  for (size_t i = 0; i < m.charts.size(); ++i)
    at[size_t(m.charts[i].gridY) * m.chartsX + m.charts[i].gridX] = int64_t(i);
  p.cw = ((gridW - 1) >> kc) + 1, p.ch = ((gridH - 1) >> kc) + 1;
  p.coarse.assign(p.cw * p.ch, PackedColour{});
  std::vector<PackedColour> buffer;
  uint64_t tiles = 0;
  for (uint8_t x : p.selected) tiles += x ? uint64_t(per) * per : 0;
  const progress::ProgressStage stage("imagery tiles", tiles);
  for (uint32_t cy = 0; cy < m.chartsY; ++cy) {
    const int64_t eastChart = at[size_t(cy) * m.chartsX + m.chartsX - 1];
    const bool westBorder = eastChart >= 0 && p.selected[size_t(eastChart)] && seam.east(m.charts[size_t(eastChart)]);
    for (uint32_t cx = 0; cx < m.chartsX; ++cx) {
      const int64_t chart = at[size_t(cy) * m.chartsX + cx];
      const bool mine = chart >= 0 && p.selected[size_t(chart)];
      if (!mine && !(cx == 0 && westBorder)) continue;
      if (mine) files[size_t(chart)] = openImageryChart(dir, m, m.charts[size_t(chart)]);
      for (uint32_t ty = 0; ty < per; ++ty)
        for (uint32_t tx = 0; tx < (mine ? per : 1); ++tx) {
          const uint64_t ox = cx * ci + tx * tile, oy = cy * ci + ty * tile;
          const uint64_t x0 = ox > margin ? ox - margin : 0, y0 = oy > margin ? oy - margin : 0;
          const uint64_t x1 = std::min(gridW, ox + tile + margin + 1), y1 = std::min(gridH, oy + tile + margin + 1);
          const bool lastX = cx + 1 == m.chartsX && tx + 1 == per, lastY = cy + 1 == m.chartsY && ty + 1 == per;
          const std::array<uint64_t, 4> owned =
              mine ? std::array<uint64_t, 4>{ox, oy, lastX ? latW : ox + tile, lastY ? latH : oy + tile}
                   : std::array<uint64_t, 4>{};
          const uint32_t w = uint32_t(x1 - x0), h = uint32_t(y1 - y0);
          const ImageryWindow window{uint32_t(x0), uint32_t(y0), w, h};
          const ImageryPyramid pyramid(gridWindow(imagery, window, owned, p.covered), window,
                                       {m.chartsX, m.chartsY, m.chartSize, s}, kc + 1);
          for (uint32_t k = 0; k < kc && cx == 0 && tx == 0; ++k)
            seam.record(pyramid, 0, k, cy, ty * (tile >> k), tile >> k);
          ++p.windows;
          p.most = std::max<uint64_t>(p.most, uint64_t(w) * h);
          if (!mine) continue;
          for (uint32_t k = 0; k < kc; ++k) {
            const uint32_t perTile = uint32_t((tile >> k) / (uint64_t(m.blockIntervals) << s));
            ColourSquare sq{
                pyramid.at(k, ox >> k, oy >> k), pyramid.stride(k), uint32_t(tile >> k), k, tx * perTile, ty * perTile};
            if (tx + 1 == per && seam.east(m.charts[size_t(chart)]))
              sq = seam.eastBorder(sq, cy, ty * (tile >> k), buffer);
            writeColourSquare(sq, *files[size_t(chart)]);
          }
          const uint64_t n = (tile >> kc) + 1;
          for (uint64_t v = 0; v < n; ++v)
            std::copy_n(pyramid.at(kc, ox >> kc, (oy >> kc) + v), n,
                        p.coarse.begin() + std::ptrdiff_t(((oy >> kc) + v) * p.cw + (ox >> kc)));
          progress::advance();
        }
    }
  }
}

// Samples in every level of a chart's imagery of `ci` level-0 intervals from level `first`.
uint64_t chartSamplesFrom(uint64_t ci, uint32_t first, uint32_t levels) {
  return chartSamples(ci, levels) - chartSamples(ci, first);
}

// The levels from p.t.coarseLevel up of every chart with a file in `files`, from the whole grid's
// coarse level in p (its west borders recorded into `seam`), each file then committed.
uint64_t finishImageryFiles(const AtlasManifest& m, TilePass& p, std::vector<std::unique_ptr<ChartFileWriter>>& files,
                            AntimeridianColumns& seam) {
  const uint32_t kc = p.t.coarseLevel, levels = m.pyramidLevels();
  const uint64_t ci = uint64_t(m.chartSize - 1) << m.imagery.scaleLog2;
  const ImageryPyramid top(std::move(p.coarse), {0, 0, uint32_t(p.cw), uint32_t(p.ch)},
                           {m.chartsX, m.chartsY, uint32_t(ci >> kc) + 1, 0}, levels - kc);
  seam.recordAll(top, kc);
  std::atomic<uint64_t> bytes{0};
  tbb::parallel_for(size_t{0}, m.charts.size(), [&](size_t i) {
    if (!files[i]) return;
    writeChartLevels(top, kc, m, m.charts[i], *files[i], seam);
    bytes += files[i]->commit();
    files[i].reset();
  });
  return bytes.load();
}

// writeImageryChartsWindowed for charts built in tiles (imagery.h says how).
ImageryWriteStats writeImageryTiles(ImagerySource& imagery, const std::string& source, const fs::path& dir,
                                    AtlasManifest& m, const ImageryWindowing& windowing,
                                    ImageryWindowStats* windowStats) {
  const auto start = std::chrono::steady_clock::now();
  imagery.keepTiles(windowing.memoryBytes / 4);
  setImageryInfo(m, imagery.scaleLog2(), source, 0.0);
  AntimeridianColumns seam(m);
  TilePass p;
  p.t = chartTiling(m.chartSize, m.blockIntervals, windowing.maxTile);
  std::vector<std::unique_ptr<ChartFileWriter>> files(m.charts.size());
  p.selected.assign(m.charts.size(), 1);
  passImageryTiles(imagery, dir, m, files, seam, p);
  if (p.covered == 0) fail(m.imagery.source, "does not overlap the DEM");
  m.imagery.coverage = double(p.covered) / (double(imagery.width()) * double(imagery.height()));
  if (windowStats) *windowStats = {p.windows, p.most};
  ImageryWriteStats st;
  st.coveredSamples = p.covered;
  st.bytesOnDisk = finishImageryFiles(m, p, files, seam);
  st.storedSamples =
      chartSamples(uint64_t(m.chartSize - 1) << imagery.scaleLog2(), m.pyramidLevels()) * m.charts.size();
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

}  // namespace

ChartTiling shardImageryTiling(const AtlasManifest& m, uint32_t maxTile) {
  const ChartTiling t = chartTiling(m.chartSize, m.blockIntervals, maxTile);
  if (t.tiled()) return t;
  ChartTiling whole;
  whole.tile = m.chartSize - 1;
  whole.tilesPerSide = 1;
  whole.coarseLevel = std::min<uint32_t>(m.pyramidLevels() - 1, kShardImageryCoarseLevel);
  return whole;
}

ImageryPart writeImageryChartsPart(ImagerySource& imagery, const std::string& source, const fs::path& dir,
                                   AtlasManifest& m, const ImageryWindowing& windowing,
                                   const std::vector<uint32_t>& charts) {
  const auto start = std::chrono::steady_clock::now();
  makeImageryDir(dir);
  imagery.keepTiles(windowing.memoryBytes / 4);
  setImageryInfo(m, imagery.scaleLog2(), source, 0.0);
  AntimeridianColumns seam(m);
  TilePass p;
  p.t = shardImageryTiling(m, windowing.maxTile);
  p.selected.assign(m.charts.size(), 0);
  for (uint32_t c : charts) p.selected.at(c) = 1;
  std::vector<std::unique_ptr<ChartFileWriter>> files(m.charts.size());
  passImageryTiles(imagery, dir, m, files, seam, p);
  ImageryPart part;
  part.coarseLevel = p.t.coarseLevel;
  const uint64_t ci = uint64_t(m.chartSize - 1) << imagery.scaleLog2(), n = (ci >> p.t.coarseLevel) + 1;
  for (uint32_t c : charts) {
    const ChartInfo& chart = m.charts[c];
    const uint64_t x0 = (uint64_t(chart.gridX) * ci) >> p.t.coarseLevel,
                   y0 = (uint64_t(chart.gridY) * ci) >> p.t.coarseLevel;
    for (uint64_t v = 0; v < n; ++v)
      part.coarse.insert(part.coarse.end(), p.coarse.begin() + std::ptrdiff_t((y0 + v) * p.cw + x0),
                         p.coarse.begin() + std::ptrdiff_t((y0 + v) * p.cw + x0 + n));
    part.stats.bytesOnDisk += files[c]->commitPartial();
    files[c].reset();
  }
  part.stats.coveredSamples = p.covered;
  part.stats.storedSamples = chartSamplesFrom(ci, 0, p.t.coarseLevel) * charts.size();
  part.windows = {p.windows, p.most};
  part.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return part;
}

ImageryWriteStats finishImageryCharts(const fs::path& dir, AtlasManifest& m, const std::vector<fs::path>& partials,
                                      std::vector<PackedColour> coarse, uint32_t coarseLevel) {
  const auto start = std::chrono::steady_clock::now();
  makeImageryDir(dir);
  const uint64_t ci = uint64_t(m.chartSize - 1) << m.imagery.scaleLog2, n = (ci >> coarseLevel) + 1;
  if (partials.size() != m.charts.size() || coarse.size() != n * n * m.charts.size() ||
      coarseLevel >= m.pyramidLevels())
    throw std::invalid_argument("finishImageryCharts: a partial file and coarse samples per chart");
  TilePass p;
  p.t.coarseLevel = coarseLevel;
  p.cw = ((m.chartsX * ci) >> coarseLevel) + 1, p.ch = ((m.chartsY * ci) >> coarseLevel) + 1;
  p.coarse.assign(p.cw * p.ch, PackedColour{});
  std::vector<std::unique_ptr<ChartFileWriter>> files(m.charts.size());
  for (size_t c = 0; c < m.charts.size(); ++c) {
    ChartInfo& chart = m.charts[c];
    const uint64_t x0 = (uint64_t(chart.gridX) * ci) >> coarseLevel, y0 = (uint64_t(chart.gridY) * ci) >> coarseLevel;
    for (uint64_t v = 0; v < n; ++v)
      std::copy_n(coarse.begin() + std::ptrdiff_t((c * n + v) * n), n,
                  p.coarse.begin() + std::ptrdiff_t((y0 + v) * p.cw + x0));
    chart.imageryFile = imageryFileName(chart.id);
    files[c] =
        std::make_unique<ChartFileWriter>(dir / chart.imageryFile, imageryShape(m), imageryCoding(m), partials[c]);
  }
  coarse = {};
  AntimeridianColumns seam(m);
  ImageryWriteStats st;
  st.bytesOnDisk = finishImageryFiles(m, p, files, seam);
  st.storedSamples = chartSamplesFrom(ci, coarseLevel, m.pyramidLevels()) * m.charts.size();
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

ImageryWriteStats writeImageryChartsWindowed(ImagerySource& imagery, const std::string& source, const fs::path& dir,
                                             AtlasManifest& m, const ImageryWindowing& windowing,
                                             ImageryWindowStats* windowStats) {
  const auto start = std::chrono::steady_clock::now();
  makeImageryDir(dir);
  if (chartTiling(m.chartSize, m.blockIntervals, windowing.maxTile).tiled())
    return writeImageryTiles(imagery, source, dir, m, windowing, windowStats);
  const uint64_t memoryBytes = windowing.memoryBytes;
  const uint32_t levels = m.intervalsLog2() + 1;
  const uint32_t s = imagery.scaleLog2();
  const uint64_t ci = uint64_t(m.chartSize - 1) << s;  // imagery intervals per chart
  const uint64_t margin = uint64_t(1) << (levels - 1);
  const uint64_t gridW = m.chartsX * ci + 1, gridH = m.chartsY * ci + 1;
  const uint32_t latW = imagery.width(), latH = imagery.height();
  // A quarter of the memory keeps reprojected tiles (each window's margin is its neighbours'); the
  // rest holds square blocks of n charts a side: the window, its lattice and its pyramid, in
  // 2.5 x 4 bytes per level-0 sample.
  imagery.keepTiles(memoryBytes / 4);
  uint64_t n = 1;
  auto windowBytes = [&](uint64_t k) { return (k * ci + 2 * margin + 1) * (k * ci + 2 * margin + 1) * 10; };
  while (n < std::max(m.chartsX, m.chartsY) && windowBytes(n + 1) <= memoryBytes / 4 * 3) ++n;
  // Charts by grid cell.
  std::vector<int64_t> at(size_t(m.chartsX) * m.chartsY, -1);
  for (size_t i = 0; i < m.charts.size(); ++i)
    at[size_t(m.charts[i].gridY) * m.chartsX + m.charts[i].gridX] = int64_t(i);
  setImageryInfo(m, s, source, 0.0);
  AntimeridianColumns seam(m);
  std::atomic<uint64_t> bytes{0}, samples{0};
  uint64_t covered = 0, windows = 0, most = 0;
  const progress::ProgressStage stage("imagery charts", m.charts.size());
  for (uint64_t cy0 = 0; cy0 < m.chartsY; cy0 += n)
    for (uint64_t cx0 = 0; cx0 < m.chartsX; cx0 += n) {
      const uint64_t cx1 = std::min<uint64_t>(cx0 + n, m.chartsX), cy1 = std::min<uint64_t>(cy0 + n, m.chartsY);
      std::vector<size_t> charts;
      for (uint64_t cy = cy0; cy < cy1; ++cy)
        for (uint64_t cx = cx0; cx < cx1; ++cx)
          if (at[cy * m.chartsX + cx] >= 0) charts.push_back(size_t(at[cy * m.chartsX + cx]));
      if (charts.empty()) continue;
      // The grid's level-0 window (edge-clamped onto the lattice), the charts and their margin; the
      // coverage over the lattice samples these charts own (the last column and row with the last
      // charts).
      const uint64_t x0 = cx0 * ci > margin ? cx0 * ci - margin : 0, y0 = cy0 * ci > margin ? cy0 * ci - margin : 0;
      const uint64_t x1 = std::min(gridW, cx1 * ci + margin + 1), y1 = std::min(gridH, cy1 * ci + margin + 1);
      const std::array<uint64_t, 4> owned{cx0 * ci, cy0 * ci, cx1 == m.chartsX ? latW : cx1 * ci,
                                          cy1 == m.chartsY ? latH : cy1 * ci};
      const uint32_t w = uint32_t(x1 - x0), h = uint32_t(y1 - y0);
      const ImageryWindow window{uint32_t(x0), uint32_t(y0), w, h};
      std::vector<PackedColour> base = gridWindow(imagery, window, owned, covered);
      const ImageryPyramid pyramid(std::move(base), window, {m.chartsX, m.chartsY, m.chartSize, s}, levels);
      for (uint64_t cy = cy0; cy < cy1 && cx0 == 0; ++cy)
        for (uint32_t k = 0; k < levels; ++k) seam.record(pyramid, 0, k, uint32_t(cy), 0, ci >> k);
      tbb::parallel_for(size_t{0}, charts.size(), [&](size_t i) {
        bytes += writeImageryChart(pyramid, dir, m, m.charts[charts[i]], samples, seam);
        progress::advance();
      });
      ++windows;
      most = std::max<uint64_t>(most, uint64_t(w) * h);
    }
  if (covered == 0) fail(m.imagery.source, "does not overlap the DEM");
  m.imagery.coverage = double(covered) / (double(latW) * double(latH));
  if (windowStats) *windowStats = {windows, most};
  ImageryWriteStats st;
  st.coveredSamples = covered;
  st.bytesOnDisk = bytes.load();
  st.storedSamples = samples.load();
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

}  // namespace gimlod

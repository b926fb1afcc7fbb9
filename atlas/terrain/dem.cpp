// DEM loading through GDAL and void filling.
// Based on: pull-push scattered-data interpolation (Gortler, Grzeszczuk, Szeliski, Cohen,
// "The Lumigraph", SIGGRAPH 1996, section 3.4; Grossman and Dally, "Point Sample Rendering",
// EGWR 1998), applied to DEM voids; degree-to-metre series from the WGS84 ellipsoid (as in
// the USGS/NGA "length of a degree" formulas).
#include "atlas/terrain/dem.h"
#include "atlas/terrain/planet_grid.h"
#include "atlas/terrain/gdal_util.h"
#include "core/progress.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <stdexcept>

#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_string.h>
#include <gdal.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

namespace gimlod {

namespace fs = std::filesystem;

const char* const kVoidFillMethod =
    "pull-push: valid samples are averaged into a half-resolution pyramid ([1 3 3 1] filter) "
    "until no cell is void, then voids are filled top-down by bilinear interpolation of the next "
    "coarser level plus 4 membrane relaxation sweeps per level (Gauss-Seidel on the coarse levels, "
    "Jacobi on the 4 finest, so that a raster larger than memory is filled window by window with "
    "the same values; linear time, deterministic, fills stay within the range of valid samples)";

namespace {

std::string formatNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

[[noreturn]] void fail(const fs::path& file, const std::string& what) { throw InputError(file.string() + ": " + what); }

DatasetPtr openRaster(const std::string& name) {
  constexpr unsigned kFlags = GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR;
  DatasetPtr ds(GDALDataset::FromHandle(GDALOpenEx(name.c_str(), kFlags, nullptr, nullptr, nullptr)));
  // note: GDAL's ESRI ASCII grid driver types the band Int32 when the first values look integral,
  // and then reads "nan" tokens as 0; reopen such grids as Float32 so NaN voids are seen.
  if (ds && ds->GetDriver() && EQUAL(ds->GetDriver()->GetDescription(), "AAIGrid") && ds->GetRasterCount() > 0 &&
      GDALDataTypeIsInteger(ds->GetRasterBand(1)->GetRasterDataType())) {
    const char* const openOptions[] = {"DATATYPE=Float32", nullptr};
    const char* const drivers[] = {"AAIGrid", nullptr};
    DatasetPtr f(GDALDataset::FromHandle(GDALOpenEx(name.c_str(), kFlags, drivers, openOptions, nullptr)));
    if (f) return f;
  }
  return ds;
}

// Number of dimensions in a subdataset description like "[2161x4320] ROSE (32-bit float)";
// 0 if it has no such prefix.
int descriptionDims(const std::string& desc) {
  if (desc.empty() || desc[0] != '[') return 0;
  const size_t close = desc.find(']');
  if (close == std::string::npos) return 0;
  return 1 + static_cast<int>(std::count(desc.begin(), desc.begin() + close, 'x'));
}

// Opens the dataset and, for containers such as netCDF, the wanted (or first 2D) subdataset.
DatasetPtr openDem(const fs::path& path, const DemOptions& options, GdalErrorCapture& cap,
                   std::vector<std::string>& warnings) {
  DatasetPtr ds = openRaster(path.string());
  if (!ds) fail(path, withGdal("not a raster GDAL can read", cap));
  struct Sub {
    std::string name, desc;
  };
  std::vector<Sub> subs;
  if (char** md = ds->GetMetadata("SUBDATASETS")) {
    for (int i = 1;; ++i) {
      const std::string key = "SUBDATASET_" + std::to_string(i);
      const char* name = CSLFetchNameValue(md, (key + "_NAME").c_str());
      if (!name) break;
      const char* desc = CSLFetchNameValue(md, (key + "_DESC").c_str());
      subs.push_back({name, desc ? desc : ""});
    }
  }
  const std::string& want = options.subdataset;
  if (!want.empty()) {
    if (subs.empty()) {
      // A single-variable netCDF opens directly; accept its own variable name.
      const char* var = ds->GetRasterCount() > 0 ? ds->GetRasterBand(1)->GetMetadataItem("NETCDF_VARNAME") : nullptr;
      if (var && want == var) return ds;
      fail(path,
           "has no subdataset '" + want + "'" + (var ? std::string(" (its only variable is '") + var + "')" : ""));
    }
    for (const Sub& s : subs) {
      const size_t colon = s.name.rfind(':');
      const std::string var = colon == std::string::npos ? s.name : s.name.substr(colon + 1);
      if (s.name == want || var == want) {
        DatasetPtr sub = openRaster(s.name);
        if (!sub) fail(path, withGdal("cannot open subdataset '" + want + "'", cap));
        return sub;
      }
    }
    std::string list;
    for (const Sub& s : subs) list += (list.empty() ? "" : ", ") + s.desc;
    fail(path, "has no subdataset '" + want + "' (available: " + list + ")");
  }
  if (ds->GetRasterCount() > 0) return ds;
  for (const Sub& s : subs) {
    if (descriptionDims(s.desc) != 2) continue;
    DatasetPtr sub = openRaster(s.name);
    if (sub && sub->GetRasterCount() == 1) {
      warnings.push_back("using subdataset " + s.desc + " (first 2D variable)");
      return sub;
    }
  }
  std::string why = subs.empty() ? "no raster bands" : "no 2D subdataset among " + std::to_string(subs.size());
  fail(path, withGdal("not a raster GDAL can read (" + why + ")", cap));
}

// Metres per unit of a vertical unit string, or 0 if unknown.
double verticalUnitToMetres(std::string unit) {
  std::transform(unit.begin(), unit.end(), unit.begin(), [](unsigned char c) { return std::tolower(c); });
  if (unit.empty() || unit == "m" || unit == "metre" || unit == "metres" || unit == "meter" || unit == "meters")
    return 1.0;
  if (unit == "ft" || unit == "foot" || unit == "feet" || unit == "international foot") return 0.3048;
  if (unit == "us-ft" || unit == "ftus" || unit == "us survey foot" || unit == "foot_us") return 1200.0 / 3937.0;
  return 0.0;
}

}  // namespace

double metresPerDegreeLatitude(double phiDeg) {
  const double phi = phiDeg * std::numbers::pi / 180.0;
  return 111132.92 - 559.82 * std::cos(2 * phi) + 1.175 * std::cos(4 * phi);
}

double metresPerDegreeLongitude(double phiDeg) {
  const double phi = std::clamp(phiDeg, -89.0, 89.0) * std::numbers::pi / 180.0;
  return 111412.84 * std::cos(phi) - 93.5 * std::cos(3 * phi);
}

struct DemSource::Impl {
  fs::path path;
  DatasetPtr ds;
  GDALRasterBand* band = nullptr;
  bool nodataInFloat = false, nodataHuge = false, maskBand = false;
  float nodataF = 0.f;
  double scale = 1.0, offset = 0.0, zScale = 1.0;
  bool flip = true;
  // A planet build: how the rows read are laid from the raster's (DemOptions::planetRadius).
  std::optional<PlanetGrid> planet;
  std::vector<float> rowHeights;
  std::vector<uint8_t> rowValid;
  // The last chunk read (GDAL rows [chunk * kDemChunkRows, ...)), raw, with its mask.
  int64_t chunk = -1;
  std::vector<float> chunkHeights;
  std::vector<uint8_t> chunkMask;
};

DemSource::DemSource(const fs::path& path, const DemOptions& options) : impl_(std::make_unique<Impl>()) {
  if (!std::isfinite(options.zScale) || options.zScale == 0.0)
    fail(path, "z-scale " + formatNumber(options.zScale) + " must be finite and non-zero");
  for (double s : options.spacing)
    if (!(s == 0.0 && options.spacing[0] == 0.0 && options.spacing[1] == 0.0) &&
        !(s > 0.0 && std::isfinite(s) && s < 1e9))
      fail(path, optionRef("spacing") + " " + formatNumber(s) + " m must be positive and finite");
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "no such file");
  if (fs::is_directory(path, ec)) fail(path, "is a directory, not a raster file");

  registerGdalOnce();
  if (options.gdalCacheBytes > 0) GDALSetCacheMax64(GIntBig(options.gdalCacheBytes));
  GdalErrorCapture cap;
  DemRaster& dem = info_;
  Impl& im = *impl_;
  im.path = path;
  im.zScale = options.zScale;
  im.ds = openDem(path, options, cap, dem.warnings);
  const DatasetPtr& ds = im.ds;

  const int w = ds->GetRasterXSize(), h = ds->GetRasterYSize();
  if (w <= 0 || h <= 0) fail(path, "raster has zero size");
  if (ds->GetRasterCount() < 1) fail(path, "not a raster GDAL can read (no bands)");
  const int bands = ds->GetRasterCount();
  if (options.band > uint32_t(bands))
    fail(path, optionRef("band") + " " + std::to_string(options.band) + ": the raster has " + std::to_string(bands) +
                   " band" + (bands == 1 ? "" : "s"));
  if (options.band == 0 && bands > 1) {
    bool bytes = true;
    for (int b = 1; b <= bands; ++b) bytes = bytes && ds->GetRasterBand(b)->GetRasterDataType() == GDT_Byte;
    if (bytes && (bands == 3 || bands == 4))
      fail(path, std::to_string(bands) + " bands of bytes: a colour image (" + (bands == 3 ? "RGB" : "RGBA") +
                     "), not heights; drape it over a DEM with " + optionRef("imagery") + ", or give " +
                     optionRef("band") + " N to read one band as heights");
    dem.warnings.push_back(std::to_string(bands) + " bands; using band 1 as heights (" + optionRef("band") +
                           " N chooses another)");
  }
  dem.width = static_cast<uint32_t>(w);
  dem.height = static_cast<uint32_t>(h);
  GDALRasterBand* band = im.band = ds->GetRasterBand(options.band == 0 ? 1 : int(options.band));

  // Voids: declared nodata, NaN, inf, and an explicit mask band if the file has one.
  int hasNodata = 0;
  const double nodata = band->GetNoDataValue(&hasNodata);
  im.nodataInFloat = hasNodata && std::isfinite(nodata) && std::fabs(nodata) <= std::numeric_limits<float>::max();
  im.nodataF = im.nodataInFloat ? static_cast<float>(nodata) : 0.f;
  // note: a double raster's nodata beyond float range reads back as +-FLT_MAX or inf.
  im.nodataHuge = hasNodata && std::isfinite(nodata) && !im.nodataInFloat;
  const int maskFlags = band->GetMaskFlags();
  im.maskBand = !(maskFlags & GMF_ALL_VALID) && !(maskFlags & GMF_NODATA);

  // Height units: band scale/offset (packed data), vertical unit, user z-scale.
  int hasScale = 0, hasOffset = 0;
  const double bandScale = band->GetScale(&hasScale);
  const double bandOffset = band->GetOffset(&hasOffset);
  double unit = verticalUnitToMetres(band->GetUnitType() ? band->GetUnitType() : "");
  if (unit == 0.0) {
    dem.warnings.push_back(std::string("vertical unit '") + band->GetUnitType() + "' not recognised; assumed metres");
    unit = 1.0;
  } else if (unit != 1.0) {
    dem.warnings.push_back(std::string("vertical unit '") + band->GetUnitType() + "' converted to metres");
  }
  im.scale = (hasScale ? bandScale : 1.0) * unit * options.zScale;
  im.offset = (hasOffset ? bandOffset : 0.0) * unit * options.zScale;
  // Georeference and spacing.
  std::array<double, 6> gt{0, 1, 0, 0, 0, 1};
  const bool hasGt = ds->GetGeoTransform(gt.data()) == CE_None;
  dem.georef.geotransform = gt;
  const OGRSpatialReference* srs = ds->GetSpatialRef();
  if (srs) {
    char* wkt = nullptr;
    const char* const wktOptions[] = {"FORMAT=WKT2_2019", nullptr};
    if (srs->exportToWkt(&wkt, wktOptions) == OGRERR_NONE && wkt) dem.georef.wkt = wkt;
    CPLFree(wkt);
  }
  if (!hasGt) {
    // note: without a geotransform the raster is treated as an image whose top row is north.
    if (options.spacing[0] > 0)
      dem.warnings.push_back("no geotransform: top row taken as north");
    else
      dem.warnings.push_back("no geotransform: sample spacing taken as 1 m (" + optionRef("spacing") +
                             " X[,Y] gives it in metres), top row taken as north");
    dem.spacing = {1.0, 1.0};
  } else {
    const double sx = std::hypot(gt[1], gt[4]), sy = std::hypot(gt[2], gt[5]);
    if (!(sx > 0) || !(sy > 0) || !std::isfinite(sx) || !std::isfinite(sy))
      fail(path, "invalid geotransform (zero or non-finite pixel size)");
    if (gt[2] != 0.0 || gt[4] != 0.0) dem.warnings.push_back("rotated geotransform: rotation ignored");
    im.flip = gt[5] < 0;  // GDAL row 0 is north for the usual north-up rasters
    const double cxDeg = gt[0] + gt[1] * w * 0.5 + gt[2] * h * 0.5;
    const double cyDeg = gt[3] + gt[4] * w * 0.5 + gt[5] * h * 0.5;
    bool geographic = false;
    double angularToDeg = 1.0;
    if (srs) {
      if (srs->IsGeographic()) {
        geographic = true;
        angularToDeg = srs->GetAngularUnits() * 180.0 / std::numbers::pi;
        if (!(angularToDeg > 0)) angularToDeg = 1.0;
      } else {
        const double linear = srs->GetLinearUnits();
        if (linear > 0 && std::isfinite(linear) && linear != 1.0) {
          dem.spacing = {sx * linear, sy * linear};
        } else {
          dem.spacing = {sx, sy};
        }
        if (!srs->IsProjected() && !srs->IsLocal())
          dem.warnings.push_back(
              "spatial reference is neither geographic nor projected; "
              "horizontal units taken as its linear units");
      }
    } else {
      // No SRS: degrees if the pixel extent fits the globe and pixels are under a degree. The
      // globe's bounds get half a degree of slack at least: a global grid's pixels are often
      // centred on the poles and the meridian, so its extent passes them by half a pixel of the
      // grid it was made at, however finely it was resampled since (ETOPO5 through a VRT).
      const double x0 = std::min(gt[0], gt[0] + gt[1] * w), x1 = std::max(gt[0], gt[0] + gt[1] * w);
      const double y0 = std::min(gt[3], gt[3] + gt[5] * h), y1 = std::max(gt[3], gt[3] + gt[5] * h);
      const double slackX = std::max(sx, 0.5), slackY = std::max(sy, 0.5);
      geographic = sx < 1.0 && sy < 1.0 && x0 >= -180.0 - slackX && x1 <= 360.0 + slackX && y0 >= -90.0 - slackY &&
                   y1 <= 90.0 + slackY;
      if (geographic) {
        dem.warnings.push_back(
            "no spatial reference; extent fits longitude/latitude, so units "
            "are taken as degrees");
      } else {
        dem.warnings.push_back("no spatial reference; geotransform units taken as metres");
        dem.spacing = {sx, sy};
      }
    }
    if (geographic) {
      const double phi = std::clamp(cyDeg * angularToDeg, -90.0, 90.0);
      dem.georef.geographic = true;
      dem.georef.centreLatitudeDeg = phi;
      dem.spacing = {sx * angularToDeg * metresPerDegreeLongitude(phi),
                     sy * angularToDeg * metresPerDegreeLatitude(phi)};
      (void)cxDeg;
    }
  }

  if (options.spacing[0] > 0) {
    if (hasGt)
      dem.warnings.push_back("spacing " + formatNumber(options.spacing[0]) + " x " + formatNumber(options.spacing[1]) +
                             " m given, in place of the georeference's " + formatNumber(dem.spacing[0]) + " x " +
                             formatNumber(dem.spacing[1]) + " m");
    dem.spacing = options.spacing;
  }
  for (const std::string& wmsg : cap.warnings()) dem.warnings.push_back(wmsg);
  if (options.planetRadius > 0.0) layPlanetGrid(options);
}

DemSource::~DemSource() = default;

// A planet build: what the rows read are laid from (atlas/terrain/planet_grid.h), and the raster
// they make.
void DemSource::layPlanetGrid(const DemOptions& options) {
  Impl& im = *impl_;
  DemRaster& dem = info_;
  const fs::path& path = im.path;
  // Whole metres stay whole (an integer raster, a whole scale and offset).
  const bool integer = GDALDataTypeIsInteger(im.band->GetRasterDataType()) && im.scale == std::nearbyint(im.scale) &&
                       im.offset == std::nearbyint(im.offset);
  PlanetGrid g = planPlanetGrid({dem.georef, dem.width, dem.height, integer}, path, options.planetRadius,
                                options.planetChartIntervals);
  g.info.flattening = options.planetFlattening;
  if (!g.warning.empty()) dem.warnings.push_back(g.warning);
  std::vector<float> row(dem.width);
  std::vector<uint8_t> valid(dem.width);
  if (g.southRows > 0) {
    readSourceRows(g.southMeanRow, 1, row.data(), valid.data(), false);
    g.southMean = poleRowMean(g, row.data(), valid.data(), path);
  }
  if (g.northFrom < g.height()) {
    readSourceRows(g.northMeanRow, 1, row.data(), valid.data(), false);
    g.northMean = poleRowMean(g, row.data(), valid.data(), path);
  }
  dem.width = g.width();
  dem.height = g.height();
  dem.georef = planetGridGeoref(g, dem.georef);
  dem.spacing = planetGridSpacing(g);
  dem.planet = g.info;
  im.planet = g;
}

void DemSource::readRows(uint32_t y0, uint32_t rows, float* heights, uint8_t* valid, bool showProgress) const {
  Impl& im = *impl_;
  if (!im.planet) return readSourceRows(y0, rows, heights, valid, showProgress);
  const PlanetGrid& g = *im.planet;
  if (rows == 0) return;
  if (uint64_t{y0} + rows > g.height()) throw std::logic_error("DemSource::readRows: rows beyond the raster");
  // The source rows these rows come from, read at once (the chunks' order as the plain reads').
  int64_t s0 = -1, s1 = -1;
  for (uint32_t y = y0; y < y0 + rows; ++y)
    if (const int64_t s = g.sourceRow(y); s >= 0) {
      if (s0 < 0) s0 = s;
      s1 = s;
    }
  const size_t sw = g.sourceWidth, w = g.width();
  if (s0 >= 0) {
    im.rowHeights.resize(size_t(s1 - s0 + 1) * sw);
    im.rowValid.resize(im.rowHeights.size());
    readSourceRows(uint32_t(s0), uint32_t(s1 - s0 + 1), im.rowHeights.data(), im.rowValid.data(), showProgress);
  }
  for (uint32_t y = y0; y < y0 + rows; ++y) {
    const int64_t s = g.sourceRow(y);
    const size_t at = s < 0 ? 0 : size_t(s - s0) * sw;
    planetGridRow(g, y, s < 0 ? nullptr : im.rowHeights.data() + at, s < 0 ? nullptr : im.rowValid.data() + at,
                  heights + size_t(y - y0) * w, valid + size_t(y - y0) * w);
  }
}

void DemSource::readSourceRows(uint32_t y0, uint32_t rows, float* heights, uint8_t* valid, bool showProgress) const {
  Impl& im = *impl_;  // its chunk cache changes
  const fs::path& path = im.path;
  const uint32_t w = im.planet ? im.planet->sourceWidth : info_.width,
                 h = im.planet ? im.planet->sourceHeight : info_.height;
  if (rows == 0) return;
  if (uint64_t{y0} + rows > h) throw std::logic_error("DemSource::readRows: rows beyond the raster");
  // GDAL's rows run north to south when the raster is north-up (flip): ours south to north.
  const int gy0 = im.flip ? int(h - y0 - rows) : int(y0);
  const size_t n = size_t{w} * rows;
  // GDAL resamples a VRT window by window, and a sample's last bits can depend on the window asked
  // for: every read goes in the same chunks of kDemChunkRows GDAL rows, whoever asks and however
  // many rows, so a DEM reads the same whichever path builds it. The last chunk is kept for the
  // next call (bands of rows overlap chunks).
  std::optional<progress::ProgressStage> stage;
  const int64_t first = gy0 / kDemChunkRows, last = (int64_t(gy0) + rows - 1) / kDemChunkRows;
  if (showProgress) stage.emplace("read DEM", uint64_t(last - first + 1));
  std::vector<uint8_t> mask(im.maskBand ? n : 0);
  for (int64_t k = first; k <= last; ++k) {
    const int64_t c0 = k * kDemChunkRows, c1 = std::min<int64_t>(c0 + kDemChunkRows, h);
    if (im.chunk != k) {
      im.chunk = -1;
      const size_t cn = size_t(c1 - c0) * w;
      im.chunkHeights.resize(cn);
      GdalErrorCapture cap;
      CPLErr err = im.band->RasterIO(GF_Read, 0, int(c0), int(w), int(c1 - c0), im.chunkHeights.data(), int(w),
                                     int(c1 - c0), GDT_Float32, 0, 0, nullptr);
      if (err != CE_None || !cap.failures().empty())
        fail(path, withGdal("cannot read the raster data (truncated or corrupt file?)", cap));
      if (im.maskBand) {
        im.chunkMask.resize(cn);
        cap.clear();
        if (im.band->GetMaskBand()->RasterIO(GF_Read, 0, int(c0), int(w), int(c1 - c0), im.chunkMask.data(), int(w),
                                             int(c1 - c0), GDT_Byte, 0, 0, nullptr) != CE_None ||
            !cap.failures().empty())
          fail(path, withGdal("cannot read the raster's mask band", cap));
      }
      im.chunk = k;
    }
    const int64_t r0 = std::max<int64_t>(c0, gy0), r1 = std::min<int64_t>(c1, int64_t(gy0) + rows);
    const size_t from = size_t(r0 - c0) * w, to = size_t(r0 - gy0) * w, count = size_t(r1 - r0) * w;
    std::copy_n(im.chunkHeights.data() + from, count, heights + to);
    if (im.maskBand) std::copy_n(im.chunkMask.data() + from, count, mask.data() + to);
    if (stage) progress::advance();
  }
  for (size_t i = 0; i < n; ++i) {
    const float v = heights[i];
    const bool isVoid = !std::isfinite(v) || (im.nodataInFloat && v == im.nodataF) ||
                        (im.nodataHuge && std::fabs(v) >= std::numeric_limits<float>::max()) ||
                        (!mask.empty() && mask[i] == 0);
    valid[i] = isVoid ? 0 : 1;
    if (!isVoid && (im.scale != 1.0 || im.offset != 0.0)) heights[i] = static_cast<float>(v * im.scale + im.offset);
    if (!isVoid && !std::isfinite(heights[i])) fail(path, "heights overflow after z-scale " + formatNumber(im.zScale));
  }
  if (im.flip && rows > 1) {
    for (uint32_t r = 0; r < rows / 2; ++r) {
      std::swap_ranges(heights + size_t{r} * w, heights + size_t{r + 1} * w, heights + size_t{rows - 1 - r} * w);
      std::swap_ranges(valid + size_t{r} * w, valid + size_t{r + 1} * w, valid + size_t{rows - 1 - r} * w);
    }
  }
}

DemRaster loadDem(const fs::path& path, const DemOptions& options) {
  const DemSource src(path, options);
  DemRaster dem = src.info();
  const int w = int(dem.width), h = int(dem.height);
  const size_t n = size_t{dem.width} * dem.height;
  const double need = double(n) * options.buildBytesPerSample;
  if (options.maxMemory > 0 && need > double(options.maxMemory)) {
    const auto size = [](double bytes) {
      char text[32];
      if (bytes >= double(1ull << 30))
        std::snprintf(text, sizeof text, "%.1f GiB", bytes / double(1ull << 30));
      else
        std::snprintf(text, sizeof text, "%.1f MiB", bytes / double(1ull << 20));
      return std::string(text);
    };
    fail(path, std::to_string(w) + " x " + std::to_string(h) + " samples need about " + size(need) +
                   " to build in memory, over the " + size(double(options.maxMemory)) + " cap; give a larger " +
                   optionRef("maxMemory") + " (this build holds the whole DEM in memory)");
  }
  std::vector<uint8_t> valid;
  try {
    dem.heights.resize(n);
    valid.resize(n);
  } catch (const std::bad_alloc&) {
    fail(path, "raster " + std::to_string(w) + " x " + std::to_string(h) + " is too large to load into memory");
  }
  src.readRows(0, dem.height, dem.heights.data(), valid.data(), true);
  std::vector<bool> voids(n, false);
  for (size_t i = 0; i < n; ++i) voids[i] = valid[i] == 0;
  valid = {};
  const uint64_t voidCount = static_cast<uint64_t>(std::count(voids.begin(), voids.end(), true));
  if (voidCount == n) fail(path, "every sample is nodata (" + std::to_string(n) + " samples)");

  // Fill voids, then the height range.
  dem.integerHeights = true;
  for (size_t i = 0; i < dem.heights.size() && dem.integerHeights; ++i)
    dem.integerHeights = voids[i] || dem.heights[i] == std::nearbyint(dem.heights[i]);
  dem.voidFillMethod = kVoidFillMethod;
  dem.voidsFilled = voidCount > 0 ? fillVoids(dem.heights, voids, dem.width, dem.height) : 0;
  const auto [mn, mx] = std::minmax_element(dem.heights.begin(), dem.heights.end());
  dem.minHeight = *mn;
  dem.maxHeight = *mx;
  return dem;
}

}  // namespace gimlod

// DEM loading through GDAL and void filling.
// Based on: pull-push scattered-data interpolation (Gortler, Grzeszczuk, Szeliski, Cohen,
// "The Lumigraph", SIGGRAPH 1996, section 3.4; Grossman and Dally, "Point Sample Rendering",
// EGWR 1998), applied to DEM voids; degree-to-metre series from the WGS84 ellipsoid (as in
// the USGS/NGA "length of a degree" formulas).
#include "atlas/terrain/dem.h"
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

[[noreturn]] void fail(const fs::path& file, const std::string& what) {
  throw InputError(file.string() + ": " + what);
}

DatasetPtr openRaster(const std::string& name) {
  constexpr unsigned kFlags = GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR;
  DatasetPtr ds(GDALDataset::FromHandle(GDALOpenEx(name.c_str(), kFlags, nullptr, nullptr, nullptr)));
  // note: GDAL's ESRI ASCII grid driver types the band Int32 when the first values look integral,
  // and then reads "nan" tokens as 0; reopen such grids as Float32 so NaN voids are seen.
  if (ds && ds->GetDriver() && EQUAL(ds->GetDriver()->GetDescription(), "AAIGrid") &&
      ds->GetRasterCount() > 0 && GDALDataTypeIsInteger(ds->GetRasterBand(1)->GetRasterDataType())) {
    const char* const openOptions[] = {"DATATYPE=Float32", nullptr};
    const char* const drivers[] = {"AAIGrid", nullptr};
    DatasetPtr f(GDALDataset::FromHandle(
        GDALOpenEx(name.c_str(), kFlags, drivers, openOptions, nullptr)));
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
  struct Sub { std::string name, desc; };
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
      const char* var = ds->GetRasterCount() > 0
                            ? ds->GetRasterBand(1)->GetMetadataItem("NETCDF_VARNAME")
                            : nullptr;
      if (var && want == var) return ds;
      fail(path, "has no subdataset '" + want + "'" +
                     (var ? std::string(" (its only variable is '") + var + "')" : ""));
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
  std::string why = subs.empty() ? "no raster bands" : "no 2D subdataset among " +
                                                           std::to_string(subs.size());
  fail(path, withGdal("not a raster GDAL can read (" + why + ")", cap));
}

// Metres per unit of a vertical unit string, or 0 if unknown.
double verticalUnitToMetres(std::string unit) {
  std::transform(unit.begin(), unit.end(), unit.begin(), [](unsigned char c) { return std::tolower(c); });
  if (unit.empty() || unit == "m" || unit == "metre" || unit == "metres" || unit == "meter" ||
      unit == "meters")
    return 1.0;
  if (unit == "ft" || unit == "foot" || unit == "feet" || unit == "international foot") return 0.3048;
  if (unit == "us-ft" || unit == "ftus" || unit == "us survey foot" || unit == "foot_us")
    return 1200.0 / 3937.0;
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


DemRaster loadDem(const fs::path& path, const DemOptions& options) {
  if (!std::isfinite(options.zScale) || options.zScale == 0.0)
    fail(path, "z-scale " + formatNumber(options.zScale) + " must be finite and non-zero");
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "no such file");
  if (fs::is_directory(path, ec)) fail(path, "is a directory, not a raster file");

  registerGdalOnce();
  if (options.gdalCacheBytes > 0) GDALSetCacheMax64(GIntBig(options.gdalCacheBytes));
  GdalErrorCapture cap;
  DemRaster dem;
  DatasetPtr ds = openDem(path, options, cap, dem.warnings);

  const int w = ds->GetRasterXSize(), h = ds->GetRasterYSize();
  if (w <= 0 || h <= 0) fail(path, "raster has zero size");
  if (ds->GetRasterCount() < 1) fail(path, "not a raster GDAL can read (no bands)");
  if (ds->GetRasterCount() > 1)
    dem.warnings.push_back(std::to_string(ds->GetRasterCount()) +
                           " bands; using band 1 as heights");
  dem.width = static_cast<uint32_t>(w);
  dem.height = static_cast<uint32_t>(h);
  const size_t n = size_t{dem.width} * dem.height;
  GDALRasterBand* band = ds->GetRasterBand(1);
  const double need = double(n) * options.buildBytesPerSample;
  if (options.maxMemory > 0 && need > double(options.maxMemory)) {
    const auto size = [](double bytes) {
      char text[32];
      if (bytes >= double(1ull << 30)) std::snprintf(text, sizeof text, "%.1f GiB", bytes / double(1ull << 30));
      else std::snprintf(text, sizeof text, "%.1f MiB", bytes / double(1ull << 20));
      return std::string(text);
    };
    fail(path, std::to_string(w) + " x " + std::to_string(h) + " samples need about " + size(need) +
                   " to build in memory, over the " + size(double(options.maxMemory)) + " cap; give a larger " +
                   optionRef("maxMemory") + " (this build holds the whole DEM in memory)");
  }

  // Read band 1 as float.
  try {
    dem.heights.resize(n);
  } catch (const std::bad_alloc&) {
    fail(path, "raster " + std::to_string(w) + " x " + std::to_string(h) +
                   " is too large to load into memory");
  }
  cap.clear();
  // GDAL reports how much it has read: the "read DEM" stage in thousandths.
  const progress::ProgressStage stage("read DEM", 1000);
  uint64_t thousandths = 0;
  GDALRasterIOExtraArg extra;
  INIT_RASTERIO_EXTRA_ARG(extra);
  extra.pfnProgress = [](double done, const char*, void* data) -> int {
    auto* last = static_cast<uint64_t*>(data);
    const uint64_t now = uint64_t(std::clamp(done, 0.0, 1.0) * 1000.0);
    if (now > *last) progress::advance(now - *last), *last = now;
    return TRUE;
  };
  extra.pProgressData = &thousandths;
  CPLErr err = band->RasterIO(GF_Read, 0, 0, w, h, dem.heights.data(), w, h, GDT_Float32, 0, 0, &extra);
  if (err != CE_None || !cap.failures().empty())
    fail(path, withGdal("cannot read the raster data (truncated or corrupt file?)", cap));

  // Void mask: declared nodata, NaN, inf, and an explicit mask band if the file has one.
  std::vector<bool> voids(n, false);
  int hasNodata = 0;
  const double nodata = band->GetNoDataValue(&hasNodata);
  const bool nodataInFloat = hasNodata && std::isfinite(nodata) &&
                             std::fabs(nodata) <= std::numeric_limits<float>::max();
  const float nodataF = nodataInFloat ? static_cast<float>(nodata) : 0.f;
  // note: a double raster's nodata beyond float range reads back as +-FLT_MAX or inf.
  const bool nodataHuge = hasNodata && std::isfinite(nodata) && !nodataInFloat;
  const int maskFlags = band->GetMaskFlags();
  std::vector<uint8_t> mask;
  if (!(maskFlags & GMF_ALL_VALID) && !(maskFlags & GMF_NODATA)) {
    mask.resize(n);
    cap.clear();
    if (band->GetMaskBand()->RasterIO(GF_Read, 0, 0, w, h, mask.data(), w, h, GDT_Byte, 0, 0,
                                      nullptr) != CE_None ||
        !cap.failures().empty())
      fail(path, withGdal("cannot read the raster's mask band", cap));
  }
  for (size_t i = 0; i < n; ++i) {
    const float v = dem.heights[i];
    voids[i] = !std::isfinite(v) || (nodataInFloat && v == nodataF) ||
               (nodataHuge && std::fabs(v) >= std::numeric_limits<float>::max()) ||
               (!mask.empty() && mask[i] == 0);
  }
  const uint64_t voidCount = static_cast<uint64_t>(std::count(voids.begin(), voids.end(), true));
  if (voidCount == n) fail(path, "every sample is nodata (" + std::to_string(n) + " samples)");

  // Height units: band scale/offset (packed data), vertical unit, user z-scale.
  int hasScale = 0, hasOffset = 0;
  const double bandScale = band->GetScale(&hasScale);
  const double bandOffset = band->GetOffset(&hasOffset);
  double unit = verticalUnitToMetres(band->GetUnitType() ? band->GetUnitType() : "");
  if (unit == 0.0) {
    dem.warnings.push_back(std::string("vertical unit '") + band->GetUnitType() +
                           "' not recognised; assumed metres");
    unit = 1.0;
  } else if (unit != 1.0) {
    dem.warnings.push_back(std::string("vertical unit '") + band->GetUnitType() +
                           "' converted to metres");
  }
  const double scale = (hasScale ? bandScale : 1.0) * unit * options.zScale;
  const double offset = (hasOffset ? bandOffset : 0.0) * unit * options.zScale;
  if (scale != 1.0 || offset != 0.0) {
    for (size_t i = 0; i < n; ++i)
      if (!voids[i]) dem.heights[i] = static_cast<float>(dem.heights[i] * scale + offset);
  }
  for (size_t i = 0; i < n; ++i)
    if (!voids[i] && !std::isfinite(dem.heights[i]))
      fail(path, "heights overflow after z-scale " + formatNumber(options.zScale));

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
  bool flip = true;
  if (!hasGt) {
    // note: without a geotransform the raster is treated as an image whose top row is north.
    dem.warnings.push_back("no geotransform: sample spacing set to 1 m, top row taken as north");
    dem.spacing = {1.0, 1.0};
  } else {
    const double sx = std::hypot(gt[1], gt[4]), sy = std::hypot(gt[2], gt[5]);
    if (!(sx > 0) || !(sy > 0) || !std::isfinite(sx) || !std::isfinite(sy))
      fail(path, "invalid geotransform (zero or non-finite pixel size)");
    if (gt[2] != 0.0 || gt[4] != 0.0)
      dem.warnings.push_back("rotated geotransform: rotation ignored");
    flip = gt[5] < 0;  // GDAL row 0 is north for the usual north-up rasters
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
          dem.warnings.push_back("spatial reference is neither geographic nor projected; "
                                 "horizontal units taken as its linear units");
      }
    } else {
      // No SRS: degrees if the pixel extent fits the globe and pixels are under a degree.
      const double x0 = std::min(gt[0], gt[0] + gt[1] * w), x1 = std::max(gt[0], gt[0] + gt[1] * w);
      const double y0 = std::min(gt[3], gt[3] + gt[5] * h), y1 = std::max(gt[3], gt[3] + gt[5] * h);
      geographic = sx < 1.0 && sy < 1.0 && x0 >= -180.0 - sx && x1 <= 360.0 + sx &&
                   y0 >= -90.0 - sy && y1 <= 90.0 + sy;
      if (geographic) {
        dem.warnings.push_back("no spatial reference; extent fits longitude/latitude, so units "
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

  // Flip so that row 0 is the south edge.
  if (flip && dem.height > 1) {
    for (uint32_t r = 0; r < dem.height / 2; ++r) {
      const uint32_t s = dem.height - 1 - r;
      std::swap_ranges(dem.heights.begin() + size_t{r} * dem.width,
                       dem.heights.begin() + size_t{r + 1} * dem.width,
                       dem.heights.begin() + size_t{s} * dem.width);
      for (uint32_t x = 0; x < dem.width; ++x) {
        std::vector<bool>::swap(voids[size_t{r} * dem.width + x], voids[size_t{s} * dem.width + x]);
      }
    }
  }

  // Fill voids, then the height range.
  dem.integerHeights = true;
  for (size_t i = 0; i < dem.heights.size() && dem.integerHeights; ++i)
    dem.integerHeights = voids[i] || dem.heights[i] == std::nearbyint(dem.heights[i]);
  dem.voidFillMethod = kVoidFillMethod;
  dem.voidsFilled = voidCount > 0 ? fillVoids(dem.heights, voids, dem.width, dem.height) : 0;
  const auto [mn, mx] = std::minmax_element(dem.heights.begin(), dem.heights.end());
  dem.minHeight = *mn;
  dem.maxHeight = *mx;
  for (const std::string& wmsg : cap.warnings()) dem.warnings.push_back(wmsg);
  return dem;
}

}  // namespace gimlod

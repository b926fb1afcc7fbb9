// Tests for DEM loading (GDAL), void filling, and bad-input handling.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <numeric>
#include <vector>

#include <gdal.h>
#include <gdal_utils.h>

#include "atlas/terrain/dem.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

fs::path terrain(const char* name) { return test::realData(std::string("terrain/") + name); }

// Raw band 1 of a raster, read independently of loadDem (GDAL row order: north first).
struct RawBand {
  int w = 0, h = 0;
  std::vector<double> v;
  bool hasNodata = false;
  double nodata = 0;
};

RawBand readRaw(const fs::path& path) {
  GDALAllRegister();
  RawBand r;
  GDALDatasetH ds = GDALOpen(path.c_str(), GA_ReadOnly);
  if (!ds) return r;
  GDALRasterBandH b = GDALGetRasterBand(ds, 1);
  r.w = GDALGetRasterXSize(ds);
  r.h = GDALGetRasterYSize(ds);
  r.v.resize(size_t(r.w) * r.h);
  int has = 0;
  r.nodata = GDALGetRasterNoDataValue(b, &has);
  r.hasNodata = has != 0;
  if (GDALRasterIO(b, GF_Read, 0, 0, r.w, r.h, r.v.data(), r.w, r.h, GDT_Float64, 0, 0) != CE_None) r.v.clear();
  GDALClose(ds);
  return r;
}

// Writes a single-band GeoTIFF (north-up, 1-degree-free projected-less geotransform).
void writeTiff(const fs::path& path, int w, int h, GDALDataType type, const std::vector<double>& v,
               const double* nodata, const std::array<double, 6>& geotransform = {500000, 10, 0, 5000000, 0, -10}) {
  GDALAllRegister();
  GDALDriverH drv = GDALGetDriverByName("GTiff");
  ASSERT_NE(drv, nullptr);
  GDALDatasetH ds = GDALCreate(drv, path.c_str(), w, h, 1, type, nullptr);
  ASSERT_NE(ds, nullptr);
  std::array<double, 6> gt = geotransform;
  GDALSetGeoTransform(ds, gt.data());
  GDALRasterBandH b = GDALGetRasterBand(ds, 1);
  if (nodata) GDALSetRasterNoDataValue(b, *nodata);
  std::vector<double> copy = v;
  ASSERT_EQ(GDALRasterIO(b, GF_Write, 0, 0, w, h, copy.data(), w, h, GDT_Float64, 0, 0), CE_None);
  GDALClose(ds);
}

void expectInputErrorNaming(const fs::path& file, const DemOptions& opt = {}) {
  try {
    loadDem(file, opt);
    FAIL() << "expected InputError for " << file;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(file.filename().string()), std::string::npos)
        << "message does not name the file: " << e.what();
  }
}

bool allFinite(const std::vector<float>& v) {
  return std::all_of(v.begin(), v.end(), [](float x) { return std::isfinite(x); });
}

// ---- real data ----------------------------------------------------------------------------

void checkSrtmTile(const char* name, uint64_t documentedVoids, double centreLat) {
  GIMLOD_NEED_SHARED_DATA(fs::exists(terrain(name)));
  const fs::path file = terrain(name);
  const RawBand raw = readRaw(file);
  ASSERT_FALSE(raw.v.empty());
  ASSERT_TRUE(raw.hasNodata);
  uint64_t nodataCount = 0;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (double x : raw.v) {
    if (x == raw.nodata) {
      ++nodataCount;
    } else {
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
  }
  EXPECT_EQ(nodataCount, documentedVoids);

  const auto t0 = std::chrono::steady_clock::now();
  const DemRaster dem = loadDem(file);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("[ timing   ] loadDem(%s): %.3f s\n", name, secs);
  ASSERT_EQ(dem.width, uint32_t(raw.w));
  ASSERT_EQ(dem.height, uint32_t(raw.h));
  EXPECT_EQ(dem.voidsFilled, nodataCount);
  EXPECT_FALSE(dem.voidFillMethod.empty());
  EXPECT_TRUE(allFinite(dem.heights));
  EXPECT_GE(dem.minHeight, lo);
  EXPECT_LE(dem.maxHeight, hi);
  EXPECT_EQ(dem.minHeight, *std::min_element(dem.heights.begin(), dem.heights.end()));
  EXPECT_EQ(dem.maxHeight, *std::max_element(dem.heights.begin(), dem.heights.end()));
  // Row 0 is south: loadDem row y equals raw (north-first) row h-1-y wherever valid.
  size_t compared = 0;
  for (int y = 0; y < raw.h; y += 97)
    for (int x = 0; x < raw.w; x += 89) {
      const double r = raw.v[size_t(raw.h - 1 - y) * raw.w + x];
      if (r == raw.nodata) continue;
      EXPECT_EQ(dem.heights[size_t(y) * dem.width + x], float(r));
      ++compared;
    }
  EXPECT_GT(compared, 100u);
  EXPECT_TRUE(dem.georef.geographic);
  EXPECT_NEAR(dem.georef.centreLatitudeDeg, centreLat, 1e-6);
  EXPECT_FALSE(dem.georef.wkt.empty());
  // 3 arc-seconds: ~92.6 m north-south everywhere, east-west shrinks with cos(latitude).
  EXPECT_GT(dem.spacing[0], 60.0);
  EXPECT_LT(dem.spacing[0], 95.0);
  EXPECT_GT(dem.spacing[1], 90.0);
  EXPECT_LT(dem.spacing[1], 95.0);
  const double expectX = metresPerDegreeLongitude(centreLat) / 1200.0;
  EXPECT_NEAR(dem.spacing[0], expectX, 1e-6 * expectX);
}

TEST(AtlasDem, RainierSrtmVoidsFilled) { checkSrtmTile("mt_rainier_90m.tif", 9033, 46.5); }
TEST(AtlasDem, FujiSrtmVoidsFilled) { checkSrtmTile("mt_fuji_90m.tif", 2437, 35.5); }

TEST(AtlasDem, SaintHelensUsgsDemProjected) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  const RawBand raw = readRaw(terrain("SainteHelens.dem"));
  ASSERT_TRUE(raw.hasNodata);  // USGS DEM: -32767 outside the quadrangle's rotated profiles
  const uint64_t nodataCount = uint64_t(std::count(raw.v.begin(), raw.v.end(), raw.nodata));
  const DemRaster dem = loadDem(terrain("SainteHelens.dem"));
  EXPECT_EQ(dem.voidsFilled, nodataCount);
  EXPECT_GT(nodataCount, 0u);
  EXPECT_EQ(dem.width, 327u);
  EXPECT_EQ(dem.height, 468u);
  EXPECT_FALSE(dem.georef.geographic);
  EXPECT_NE(dem.georef.wkt.find("UTM zone 10N"), std::string::npos);
  EXPECT_DOUBLE_EQ(dem.spacing[0], 30.0);
  EXPECT_DOUBLE_EQ(dem.spacing[1], 30.0);
  EXPECT_TRUE(allFinite(dem.heights));
  EXPECT_GE(dem.minHeight, 682.f);
  EXPECT_LE(dem.maxHeight, 2543.f);
  EXPECT_GT(dem.maxHeight - dem.minHeight, 1000.f);
}

// GDAL resamples a VRT window by window, and far down a tall raster a sample's last bits depend
// on the window asked for (ETOPO5 upsampled to 52,440 rows: rows 51,800.. read as part of rows
// 51,712..51,967 and of rows 51,800..52,439 differ by up to 0.02 m). DemSource asks GDAL for the
// same chunks whatever rows it is asked for, so every way of reading gives the same samples.
TEST(AtlasDem, RowsReadTheSameWhateverTheBandsAsked) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  test::TempDir tmp("gimlod-dem-rows");
  const fs::path vrt = tmp.path() / "tall.vrt";
  {
    GDALAllRegister();
    GDALDatasetH src = GDALOpen(terrain("etopo5.cdf").c_str(), GA_ReadOnly);
    ASSERT_NE(src, nullptr);
    const char* argv[] = {"-q", "-of", "VRT", "-outsize", "300", "52440", "-r", "bilinear", nullptr};
    GDALTranslateOptions* opts = GDALTranslateOptionsNew(const_cast<char**>(argv), nullptr);
    GDALDatasetH out = GDALTranslate(vrt.c_str(), src, opts, nullptr);
    GDALTranslateOptionsFree(opts);
    ASSERT_NE(out, nullptr);
    GDALClose(out);
    GDALClose(src);
  }
  const DemSource source(vrt);
  ASSERT_EQ(source.info().height, 52440u);
  const uint32_t w = source.info().width;
  // Our rows run south to north: GDAL's rows 51,712.. are our rows ..728.
  auto read = [&](uint32_t y0, uint32_t rows) {
    std::vector<float> h(size_t(w) * rows);
    std::vector<uint8_t> v(h.size());
    source.readRows(y0, rows, h.data(), v.data());
    return h;
  };
  const std::vector<float> whole = read(0, 1000);
  for (const auto& [y0, rows] :
       std::vector<std::pair<uint32_t, uint32_t>>{{0, 640}, {472, 256}, {100, 37}, {640, 360}}) {
    const std::vector<float> part = read(y0, rows);
    size_t differ = 0;
    for (size_t i = 0; i < part.size(); ++i) differ += std::memcmp(&part[i], &whole[size_t(y0) * w + i], 4) != 0;
    EXPECT_EQ(differ, 0u) << "rows " << y0 << " + " << rows;
  }
}

TEST(AtlasDem, Etopo5NetcdfGeographic) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  const auto t0 = std::chrono::steady_clock::now();
  const DemRaster dem = loadDem(terrain("etopo5.cdf"));
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("[ timing   ] loadDem(etopo5.cdf): %.3f s\n", secs);
  EXPECT_EQ(dem.width, 4320u);
  EXPECT_EQ(dem.height, 2161u);
  EXPECT_TRUE(dem.georef.geographic);  // no SRS in the file: inferred from the extent
  EXPECT_FALSE(dem.warnings.empty());
  EXPECT_NEAR(dem.georef.centreLatitudeDeg, 0.0, 1e-6);
  EXPECT_TRUE(allFinite(dem.heights));
  EXPECT_NEAR(dem.minHeight, -10376.f, 1.f);
  EXPECT_NEAR(dem.maxHeight, 7833.f, 1.f);
  // 5 arc-minutes at the equator: ~9.28 km east-west, ~9.21 km north-south.
  EXPECT_NEAR(dem.spacing[0], 9277.0, 20.0);
  EXPECT_NEAR(dem.spacing[1], 9213.0, 20.0);
  // Row 0 is south: the first row is Antarctica (high), the last the Arctic Ocean (deep).
  const double south = std::accumulate(dem.heights.begin(), dem.heights.begin() + 4320, 0.0);
  const double north = std::accumulate(dem.heights.end() - 4320, dem.heights.end(), 0.0);
  EXPECT_GT(south / 4320, 1000.0);
  EXPECT_LT(north / 4320, 0.0);
  // Choosing the variable explicitly works; a wrong one is reported.
  EXPECT_NO_THROW(loadDem(terrain("etopo5.cdf"), DemOptions{1.0, "ROSE"}));
  expectInputErrorNaming(terrain("etopo5.cdf"), DemOptions{1.0, "NOPE"});
}

TEST(AtlasDem, ZScaleMultipliesHeights) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  const DemRaster a = loadDem(terrain("SainteHelens.dem"));
  const DemRaster b = loadDem(terrain("SainteHelens.dem"), DemOptions{2.5, ""});
  ASSERT_EQ(a.heights.size(), b.heights.size());
  for (size_t i = 0; i < a.heights.size(); i += 101) EXPECT_FLOAT_EQ(b.heights[i], 2.5f * a.heights[i]);
}

// ---- fillVoids ----------------------------------------------------------------------------

TEST(AtlasFillVoids, HoleInRampFollowsRamp) {
  const uint32_t w = 64, h = 48;
  std::vector<float> ramp(w * h);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) ramp[y * w + x] = 3.0f * x + 1.5f * y + 100.f;
  std::vector<bool> mask(w * h, false);
  uint64_t holes = 0;
  for (uint32_t y = 15; y < 31; ++y)
    for (uint32_t x = 20; x < 40; ++x) {
      mask[y * w + x] = true;
      ++holes;
    }
  std::vector<float> v = ramp;
  for (size_t i = 0; i < v.size(); ++i)
    if (mask[i]) v[i] = -32768.f;
  EXPECT_EQ(fillVoids(v, mask, w, h), holes);
  const float lo = *std::min_element(ramp.begin(), ramp.end());
  const float hi = *std::max_element(ramp.begin(), ramp.end());
  double maxErr = 0;
  for (size_t i = 0; i < v.size(); ++i) {
    if (!mask[i]) {
      EXPECT_EQ(v[i], ramp[i]);  // valid samples untouched
      continue;
    }
    EXPECT_GE(v[i], lo);
    EXPECT_LE(v[i], hi);
    maxErr = std::max(maxErr, double(std::fabs(v[i] - ramp[i])));
  }
  // The hole spans 3*20 + 1.5*16 = 84 m of ramp; the fill stays within a few metres of it
  // (measured 3.3 m).
  EXPECT_LT(maxErr, 5.0) << "max deviation from the ramp";
  // No spikes: neighbouring filled samples differ by at most a few ramp steps.
  for (uint32_t y = 15; y < 31; ++y)
    for (uint32_t x = 20; x < 40; ++x) EXPECT_LT(std::fabs(v[y * w + x + 1] - v[y * w + x]), 3.0f * 3);
}

TEST(AtlasFillVoids, SingleValidSample) {
  const uint32_t w = 7, h = 5;
  std::vector<float> v(w * h, NAN);
  std::vector<bool> mask(w * h, true);
  v[3 * w + 6] = 42.f;
  mask[3 * w + 6] = false;
  EXPECT_EQ(fillVoids(v, mask, w, h), uint64_t(w * h - 1));
  for (float x : v) EXPECT_EQ(x, 42.f);
}

TEST(AtlasFillVoids, VoidsOnBordersAndCorners) {
  const uint32_t w = 33, h = 17;
  std::vector<float> v(w * h);
  std::vector<bool> mask(w * h, false);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) {
      v[y * w + x] = float(x + y);
      if (x < 3 || y == h - 1 || (x > 28 && y < 5)) mask[y * w + x] = true;
    }
  std::vector<float> orig = v;
  uint64_t n = std::count(mask.begin(), mask.end(), true);
  EXPECT_EQ(fillVoids(v, mask, w, h), n);
  float lo = 1e9f, hi = -1e9f;
  for (size_t i = 0; i < v.size(); ++i)
    if (!mask[i]) lo = std::min(lo, orig[i]), hi = std::max(hi, orig[i]);
  for (size_t i = 0; i < v.size(); ++i) {
    EXPECT_TRUE(std::isfinite(v[i]));
    EXPECT_GE(v[i], lo);
    EXPECT_LE(v[i], hi);
    // Border voids are extended, not extrapolated: within the ramp's rise over the 3-sample
    // strip plus the corner.
    if (mask[i]) {
      EXPECT_LT(std::fabs(v[i] - orig[i]), 6.f) << "sample " << i;
    }
  }
  // No spikes: along rows and columns neighbours differ by at most 2.5 x the ramp slope (1/sample).
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x + 1 < w; ++x) EXPECT_LE(std::fabs(v[y * w + x + 1] - v[y * w + x]), 2.5f);
  for (uint32_t y = 0; y + 1 < h; ++y)
    for (uint32_t x = 0; x < w; ++x) EXPECT_LE(std::fabs(v[(y + 1) * w + x] - v[y * w + x]), 2.5f);
}

TEST(AtlasFillVoids, DeterministicAndContracts) {
  const uint32_t w = 50, h = 31;
  std::vector<float> v(w * h);
  std::vector<bool> mask(w * h);
  for (size_t i = 0; i < v.size(); ++i) {
    v[i] = float((i * 7919) % 1000);
    mask[i] = (i * 31) % 7 < 3;
  }
  std::vector<float> a = v, b = v;
  fillVoids(a, mask, w, h);
  fillVoids(b, mask, w, h);
  EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(float)));
  std::vector<bool> none(w * h, false);
  std::vector<float> c = v;
  EXPECT_EQ(fillVoids(c, none, w, h), 0u);
  EXPECT_EQ(c, v);
  std::vector<bool> all(w * h, true);
  EXPECT_THROW(fillVoids(c, all, w, h), std::invalid_argument);
  EXPECT_THROW(fillVoids(c, none, w + 1, h), std::invalid_argument);
}

// ---- bad input ----------------------------------------------------------------------------

TEST(AtlasDemErrors, TruncatedGeoTiff) {
  test::TempDir tmp("gimlod-dem");
  const fs::path src = terrain("mt_rainier_90m.tif");
  const fs::path dst = tmp.path() / "truncated_rainier.tif";
  std::ifstream in(src, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  std::ofstream(dst, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size() * 3 / 10));
  expectInputErrorNaming(dst);
}

// A GeoTIFF whose directory is at the start (as GDAL's CreateCopy writes it) opens fine even when
// truncated or garbled: the failure then comes from RasterIO, and GDAL's message must end up in
// the InputError instead of on stderr.
TEST(AtlasDemErrors, DamagedTileDataFailsInRead) {
  test::TempDir tmp("gimlod-dem");
  const fs::path full = tmp.path() / "deflate.tif";
  GDALAllRegister();
  GDALDatasetH src = GDALOpen(terrain("mt_rainier_90m.tif").c_str(), GA_ReadOnly);
  ASSERT_NE(src, nullptr);
  const char* opts[] = {"TILED=YES", "COMPRESS=DEFLATE", nullptr};
  GDALDatasetH dst = GDALCreateCopy(GDALGetDriverByName("GTiff"), full.c_str(), src, FALSE, const_cast<char**>(opts),
                                    nullptr, nullptr);
  ASSERT_NE(dst, nullptr);
  GDALClose(dst);
  GDALClose(src);
  std::ifstream in(full, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  ASSERT_GT(bytes.size(), 100000u);

  const fs::path cut = tmp.path() / "cut_tiles.tif";
  std::ofstream(cut, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size() * 6 / 10));
  const fs::path garbled = tmp.path() / "garbled_tiles.tif";
  std::vector<char> g = bytes;
  for (size_t i = g.size() / 2; i < g.size() / 2 + 20000; ++i) g[i] = char(i * 131);
  std::ofstream(garbled, std::ios::binary).write(g.data(), std::streamsize(g.size()));

  for (const fs::path& f : {cut, garbled}) {
    testing::internal::CaptureStderr();
    try {
      loadDem(f);
      ADD_FAILURE() << "expected InputError for " << f;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(f.filename().string()), std::string::npos) << msg;
      EXPECT_NE(msg.find("cannot read the raster data"), std::string::npos) << msg;
      EXPECT_NE(msg.find("("), std::string::npos) << "GDAL's reason missing: " << msg;
    }
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  }
}

TEST(AtlasDemErrors, TextFileIsNotARaster) {
  test::TempDir tmp("gimlod-dem");
  const fs::path f = tmp.path() / "notes_not_raster.txt";
  std::ofstream(f) << "This is not a raster.\nJust some words, 1 2 3.\n";
  expectInputErrorNaming(f);
  expectInputErrorNaming(tmp.path() / "missing_file.tif");
}

TEST(AtlasDemErrors, AllNodataRaster) {
  test::TempDir tmp("gimlod-dem");
  const fs::path f = tmp.path() / "all_nodata.tif";
  const double nd = -9999;
  writeTiff(f, 8, 6, GDT_Int16, std::vector<double>(48, nd), &nd);
  try {
    loadDem(f);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("all_nodata.tif"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("every sample is nodata"), std::string::npos) << e.what();
  }
}

// Without an SRS, a raster whose extent fits the globe is taken as degrees. A global grid of
// pixels centred on the pole passes 90 degrees by half of one of its pixels, and keeps doing so
// when resampled finer (ETOPO5 at 5 arc minutes, upsampled by a VRT): its north-west corner, in
// pixels of 0.0034 degrees, is still geographic. A raster a degree past the pole is not.
TEST(AtlasDem, AFinelyResampledGlobalGridIsStillDegrees) {
  test::TempDir tmp("gimlod-dem");
  const int w = 12, h = 10;
  std::vector<double> v(w * h, 100.0);
  const double half = 0.5 * 5.0 / 60.0;  // half a pixel of 5 arc minutes
  writeTiff(tmp.path() / "corner.tif", w, h, GDT_Float32, v, nullptr, {-half, 0.0034, 0, 90.0 + half, 0, -0.0034});
  const DemRaster corner = loadDem(tmp.path() / "corner.tif");
  EXPECT_TRUE(corner.georef.geographic);
  EXPECT_NEAR(corner.spacing[1], 0.0034 * 111000.0, 0.0034 * 2000.0) << "metres per degree of latitude";
  writeTiff(tmp.path() / "past.tif", w, h, GDT_Float32, v, nullptr, {0.0, 0.0034, 0, 91.0, 0, -0.0034});
  const DemRaster past = loadDem(tmp.path() / "past.tif");
  EXPECT_FALSE(past.georef.geographic);
  EXPECT_DOUBLE_EQ(past.spacing[1], 0.0034);
}

TEST(AtlasDemErrors, NanAndNodataInFloatRasterAreFilled) {
  test::TempDir tmp("gimlod-dem");
  const fs::path f = tmp.path() / "float_nan.tif";
  const int w = 10, h = 8;
  std::vector<double> v(w * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) v[y * w + x] = 10.0 * x;
  v[3 * w + 4] = NAN;
  v[5 * w + 6] = INFINITY;
  v[0] = -1.0e30;  // declared nodata
  v[7 * w + 9] = NAN;
  const double nd = -1.0e30;
  writeTiff(f, w, h, GDT_Float32, v, &nd);
  const DemRaster dem = loadDem(f);
  EXPECT_EQ(dem.voidsFilled, 4u);
  EXPECT_TRUE(allFinite(dem.heights));
  EXPECT_FALSE(dem.georef.geographic);  // no SRS, extent far outside lon/lat
  EXPECT_DOUBLE_EQ(dem.spacing[0], 10.0);
  EXPECT_GE(dem.minHeight, 0.f);
  EXPECT_LE(dem.maxHeight, 90.f);
  // Raw row 3 (from the north) is row h-1-3 after the flip.
  EXPECT_NEAR(dem.heights[size_t(h - 1 - 3) * w + 4], 40.f, 10.f);
}

// ESRI ASCII grids with integral values are typed Int32 by GDAL, which reads "nan" as 0.
TEST(AtlasDemErrors, NanTokensInIntegerLookingAsciiGrid) {
  test::TempDir tmp("gimlod-dem");
  const fs::path f = tmp.path() / "nans.asc";
  std::string grid = "ncols 9\nnrows 7\nxllcorner 0\nyllcorner 0\ncellsize 30\n";
  for (int r = 0; r < 7; ++r) {
    for (int c = 0; c < 9; ++c) grid += (r == 4 && c >= 3 && c <= 5) ? "nan " : std::to_string(100 + r + c) + " ";
    grid += "\n";
  }
  std::ofstream(f) << grid;
  const DemRaster dem = loadDem(f);
  EXPECT_EQ(dem.voidsFilled, 3u);
  EXPECT_DOUBLE_EQ(dem.spacing[0], 30.0);
  EXPECT_GE(dem.minHeight, 100.f);
  // Grid row 4 from the top is row 7-1-4 = 2 from the south; its voids lie between 105 and 111.
  for (int c = 3; c <= 5; ++c) {
    EXPECT_GT(dem.heights[2 * 9 + c], 104.f);
    EXPECT_LT(dem.heights[2 * 9 + c], 112.f);
  }
}

TEST(AtlasDemErrors, BadZScale) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  const fs::path f = terrain("SainteHelens.dem");
  expectInputErrorNaming(f, DemOptions{std::nan(""), ""});
  expectInputErrorNaming(f, DemOptions{0.0, ""});
  expectInputErrorNaming(f, DemOptions{INFINITY, ""});
  expectInputErrorNaming(f, DemOptions{1e300, ""});  // heights overflow float
}

// The shipped imagery, three bands of bytes, is a colour image: refused as a DEM unless a band is
// named, and a band past the raster's is an error naming the file.
TEST(AtlasDemErrors, ColourImageNeedsABand) {
  const fs::path rgb = test::repoData() / "terrain/mt_rainier_imagery.tif";
  try {
    loadDem(rgb);
    FAIL() << "an RGB image read as heights";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("mt_rainier_imagery.tif"), std::string::npos) << what;
    EXPECT_NE(what.find("RGB"), std::string::npos) << what;
    EXPECT_NE(what.find("band"), std::string::npos) << what;
  }
  DemOptions green;
  green.band = 2;
  const DemRaster dem = loadDem(rgb, green);
  EXPECT_GT(dem.maxHeight, dem.minHeight);
  EXPECT_LE(dem.maxHeight, 255.f);
  DemOptions fourth;
  fourth.band = 4;
  expectInputErrorNaming(rgb, fourth);
}

// A raster without a georeference is taken as 1 m apart, with a warning naming the spacing option;
// the option gives the spacing in metres (and replaces a georeference's, with a warning).
TEST(AtlasDem, SpacingOfARasterWithoutGeoreference) {
  test::TempDir tmp("gimlod-dem-spacing");
  const fs::path f = tmp.path() / "plain.tif";
  GDALAllRegister();
  GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GTiff"), f.c_str(), 8, 6, 1, GDT_Int16, nullptr);
  ASSERT_NE(ds, nullptr);
  std::vector<int16_t> h(48);
  for (size_t i = 0; i < h.size(); ++i) h[i] = int16_t(i * 3);
  ASSERT_EQ(GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Write, 0, 0, 8, 6, h.data(), 8, 6, GDT_Int16, 0, 0), CE_None);
  GDALClose(ds);
  auto warned = [](const DemRaster& d, const char* what) {
    for (const std::string& w : d.warnings)
      if (w.find(what) != std::string::npos) return true;
    return false;
  };
  const DemRaster plain = loadDem(f);
  EXPECT_EQ(plain.spacing, (std::array<double, 2>{1.0, 1.0}));
  EXPECT_TRUE(warned(plain, "spacing taken as 1 m")) << ::testing::PrintToString(plain.warnings);
  DemOptions o;
  o.spacing = {30.0, 20.0};
  const DemRaster given = loadDem(f, o);
  EXPECT_EQ(given.spacing, (std::array<double, 2>{30.0, 20.0}));
  EXPECT_FALSE(warned(given, "1 m"));
  o.spacing = {-5.0, 20.0};
  expectInputErrorNaming(f, o);
  o.spacing = {5.0, std::nan("")};
  expectInputErrorNaming(f, o);
  // A georeferenced DEM's spacing replaced, and said so.
  o.spacing = {45.0, 45.0};
  const DemRaster rainier = loadDem(test::repoData() / "terrain/mt_rainier_90m.tif", o);
  EXPECT_EQ(rainier.spacing, (std::array<double, 2>{45.0, 45.0}));
  EXPECT_TRUE(warned(rainier, "in place of the georeference"));
}

TEST(AtlasDem, DegreeLengths) {
  EXPECT_NEAR(metresPerDegreeLatitude(0), 110574.0, 2.0);
  EXPECT_NEAR(metresPerDegreeLatitude(90), 111694.0, 2.0);
  EXPECT_NEAR(metresPerDegreeLongitude(0), 111319.0, 2.0);
  EXPECT_NEAR(metresPerDegreeLongitude(60), 55800.0, 30.0);
  EXPECT_GT(metresPerDegreeLongitude(90), 1000.0);  // clamped to 89 degrees, never zero
}

}  // namespace
}  // namespace gimlod

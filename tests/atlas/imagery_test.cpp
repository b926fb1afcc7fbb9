// Terrain imagery (atlas/terrain/imagery.h): reprojection onto the DEM's lattice puts colours at
// the right geographic points, the scale follows the imagery's resolution, a whole-Earth image
// wraps around the antimeridian, the pyramid keeps shared chart borders bit-identical, a window of
// the pyramid gives the whole pyramid's charts, the files written window by window are those of
// the whole raster, and bad imagery is named.
#include <gtest/gtest.h>

#include <fstream>
#include <random>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/imagery.h"
#include "atlas/terrain/terrain_atlas.h"
#include "tests/imagery_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

fs::path rainier() { return test::repoData() / "terrain" / "mt_rainier_90m.tif"; }

// The imagery sample at a geographic point of a geographic north-up DEM (nearest lattice sample).
PackedColour sampleAt(const ImageryRaster& im, const DemRaster& dem, double lon, double lat) {
  const auto& gt = dem.georef.geotransform;
  const double gx = (lon - (gt[0] + 0.5 * gt[1])) / gt[1];
  const double gyNorth = (lat - (gt[3] + 0.5 * gt[5])) / gt[5];  // rows from the north
  const double gy = (dem.height - 1) - gyNorth;
  const double s = double(1u << im.scaleLog2);
  const size_t x = size_t(std::lround(gx * s)), y = size_t(std::lround(gy * s));
  return im.rgba.at(y * im.width + x);
}

void expectColour(const PackedColour& got, const std::array<uint8_t, 3>& want, const std::string& what) {
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(int(got[size_t(c)]), int(want[size_t(c)]), 12) << what << " channel " << c;
  EXPECT_EQ(got[3], 255) << what;
}

class ImageryTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { dem_ = new DemRaster(loadDem(rainier())); }
  static void TearDownTestSuite() {
    delete dem_;
    dem_ = nullptr;
  }
  static DemRaster* dem_;
  test::TempDir dir_{"gimlod-imagery"};
};
DemRaster* ImageryTest::dem_ = nullptr;

TEST_F(ImageryTest, ReprojectedColoursLandOnTheirGeographicPoints) {
  const fs::path img = dir_.path() / "utm.tif";
  const double* e = test::kRainierUtm;
  test::writeUtmImagery(img, test::rainierPoints(), e[0], e[1], e[2], e[3], 200.0, 3000.0);
  ImageryOptions o;
  o.path = img;
  const ImageryRaster im = loadImagery(*dem_, rainier(), o);
  EXPECT_EQ(im.scaleLog2, 0u);  // 200 m pixels over a 64 x 93 m DEM: the DEM's own lattice
  EXPECT_EQ(im.width, dem_->width);
  EXPECT_EQ(im.height, dem_->height);
  for (const test::GeoPoint& p : test::rainierPoints())
    expectColour(sampleAt(im, *dem_, p.lon, p.lat), p.rgb,
                 "point " + std::to_string(p.lon) + "," + std::to_string(p.lat));
  // Grey between the squares; nothing at the tile's south-west corner, which the UTM rectangle
  // leaves out.
  expectColour(sampleAt(im, *dem_, -121.6, 46.5), {128, 128, 128}, "between");
  EXPECT_EQ(im.rgba[0][3], 0);
  EXPECT_GT(im.coverage, 0.85);
  EXPECT_LT(im.coverage, 0.99);
}

TEST_F(ImageryTest, ScaleFollowsTheImageryResolution) {
  const auto grey = [](int, int) { return std::array<uint8_t, 3>{90, 90, 90}; };
  // 20 km squares of the tile's middle in UTM at 40 m and at 10 m.
  const auto utm = [&](const char* name, double pixel) {
    const fs::path p = dir_.path() / name;
    const int n = int(20000.0 / pixel);
    test::writeTestRaster(p, n, n, grey, {600000.0, pixel, 0.0, 5170000.0, 0.0, -pixel}, 32610);
    return p;
  };
  ImageryOptions o;
  o.path = utm("40m.tif", 40.0);
  ImageryRaster im = loadImagery(*dem_, rainier(), o);
  EXPECT_EQ(im.scaleLog2, 1u);
  EXPECT_EQ(im.width, (dem_->width - 1) * 2 + 1);
  EXPECT_EQ(im.resampling, "bilinear");
  EXPECT_NEAR(im.coverage, 400.0e6 / (1200.0 * 1200.0 * 63.97 * 92.63), 0.01);
  o.scaleLog2 = 2;  // asked for
  EXPECT_EQ(loadImagery(*dem_, rainier(), o).scaleLog2, 2u);
  o.scaleLog2 = kAutoImageryScale;
  o.path = utm("10m.tif", 10.0);
  im = loadImagery(*dem_, rainier(), o);
  EXPECT_EQ(im.scaleLog2, kMaxImageryScaleLog2);  // finer than 4 per interval: averaged down to 4
  EXPECT_EQ(im.resampling, "average");
}

TEST_F(ImageryTest, AWholeEarthImageWrapsAroundTheAntimeridian) {
  // A DEM on 0..360 degrees of longitude (like ETOPO5) at 5 degrees, and an image without a
  // georeference whose western half (-180..0) is red and eastern half (0..180) blue.
  DemRaster dem;
  dem.width = 73;
  dem.height = 37;
  dem.heights.assign(size_t(dem.width) * dem.height, 0.f);
  dem.georef.geotransform = {-2.5, 5.0, 0.0, 92.5, 0.0, -5.0};
  dem.georef.geographic = true;
  const fs::path img = dir_.path() / "world.tif";
  test::writeTestRaster(
      img, 360, 180,
      [](int x, int) {
        return x < 180 ? std::array<uint8_t, 3>{220, 20, 20} : std::array<uint8_t, 3>{20, 20, 220};
      },
      {}, 0);
  ImageryOptions o;
  o.path = img;
  EXPECT_THROW(
      try { loadImagery(dem, "dem", o); } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("no georeference"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("imageryExtent"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(img.string()), std::string::npos) << e.what();
        throw;
      },
      InputError);
  o.extent = std::array<double, 4>{-180.0, -90.0, 180.0, 90.0};
  const ImageryRaster im = loadImagery(dem, "dem", o);
  EXPECT_GT(im.coverage, 0.99);  // all but the samples on the poles, at the image's very edge
  const uint32_t s = 1u << im.scaleLog2;
  const auto at = [&](uint32_t gx, uint32_t gy) { return im.rgba[size_t(gy * s) * im.width + gx * s]; };
  expectColour(at(18, 18), {20, 20, 220}, "longitude 90");         // east of Greenwich
  expectColour(at(54, 18), {220, 20, 20}, "longitude 270 = -90");  // west of it, through the wrap
  expectColour(at(71, 30), {220, 20, 20}, "longitude 355 = -5");
}

TEST_F(ImageryTest, BadImageryIsNamed) {
  const auto expectError = [&](const ImageryOptions& o, const DemRaster& dem, const std::string& needle) {
    try {
      loadImagery(dem, "the-dem.tif", o);
      ADD_FAILURE() << "no error for " << needle;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  ImageryOptions o;
  o.path = dir_.path() / "missing.tif";
  expectError(o, *dem_, "no such file");
  o.path = dir_.path() / "garbage.tif";
  std::ofstream(o.path) << "not an image at all";
  expectError(o, *dem_, "not a raster GDAL can read");
  // Truncated: the first half of a valid GeoTIFF.
  const fs::path full = dir_.path() / "full.tif";
  test::writeTestRaster(
      full, 256, 256,
      [](int x, int y) {
        return std::array<uint8_t, 3>{uint8_t(x), uint8_t(y), 7};
      },
      {600000.0, 40.0, 0.0, 5170000.0, 0.0, -40.0}, 32610);
  o.path = dir_.path() / "truncated.tif";
  {
    std::ifstream in(full, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), {});
    std::ofstream(o.path, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size() / 2));
  }
  try {
    loadImagery(*dem_, rainier(), o);
    ADD_FAILURE() << "a truncated GeoTIFF was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(o.path.string()), std::string::npos) << e.what();
  }
  // 16-bit imagery.
  o.path = dir_.path() / "u16.tif";
  test::writeTestRaster(
      o.path, 16, 16,
      [](int, int) {
        return std::array<uint8_t, 3>{1, 2, 3};
      },
      {600000.0, 40.0, 0.0, 5170000.0, 0.0, -40.0}, 32610, 3, GDT_UInt16);
  expectError(o, *dem_, "8-bit");
  // Two colour bands.
  o.path = dir_.path() / "two.tif";
  test::writeTestRaster(
      o.path, 16, 16,
      [](int, int) {
        return std::array<uint8_t, 3>{1, 2, 3};
      },
      {600000.0, 40.0, 0.0, 5170000.0, 0.0, -40.0}, 32610, 2);
  expectError(o, *dem_, "grey, grey + alpha, RGB or RGBA");
  // Somewhere else on Earth (UTM zone 10N, but 2,000 km south).
  o.path = dir_.path() / "far.tif";
  test::writeTestRaster(
      o.path, 16, 16,
      [](int, int) {
        return std::array<uint8_t, 3>{1, 2, 3};
      },
      {600000.0, 40.0, 0.0, 3000000.0, 0.0, -40.0}, 32610);
  expectError(o, *dem_, "does not overlap");
  // A DEM without a georeference.
  DemRaster plain;
  plain.width = plain.height = 9;
  plain.heights.assign(81, 0.f);
  plain.georef.geotransform = {0, 1, 0, 0, 0, 1};
  o.path = full;
  expectError(o, plain, "the-dem.tif: has no georeference");
  // Absurd options.
  o.scaleLog2 = 3;
  expectError(o, *dem_, "imageryScale");
  o.scaleLog2 = kAutoImageryScale;
  o.extent = std::array<double, 4>{10.0, 0.0, -10.0, 5.0};
  expectError(o, *dem_, "imageryExtent");
}

TEST(ImageryPyramid, ChartsShareBitIdenticalBordersAtEveryLevel) {
  // Random colours on a 2 x 3 grid of 33-sample charts at 2 imagery samples per interval.
  ImageryRaster raster;
  raster.scaleLog2 = 1;
  raster.width = 2 * 32 * 2 - 7;  // narrower than the chart grid: the rest is edge-clamped
  raster.height = 3 * 32 * 2 + 1;
  std::mt19937 rng(7);
  raster.rgba.resize(size_t(raster.width) * raster.height);
  for (PackedColour& c : raster.rgba) c = {uint8_t(rng()), uint8_t(rng()), uint8_t(rng()), 255};
  const uint32_t levels = 6;
  const ImageryPyramid pyramid(raster, 2, 3, 33, levels);
  std::vector<ChartPyramid> charts;
  for (int32_t y = 0; y < 3; ++y)
    for (int32_t x = 0; x < 2; ++x) charts.push_back(pyramid.chart(x, y));
  // Level 0 is the raster itself (clamped beyond it).
  EXPECT_EQ(charts[0].colours[0][0], raster.rgba[0]);
  EXPECT_EQ(charts[1].colours[0][64], raster.rgba[raster.width - 1]);  // clamped column
  uint64_t compared = 0;
  for (uint32_t k = 0; k < levels; ++k) {
    const uint32_t n = (64u >> k) + 1;
    for (int32_t y = 0; y < 3; ++y)
      for (int32_t x = 0; x < 2; ++x) {
        const auto& here = charts[size_t(y * 2 + x)].colours[k];
        ASSERT_EQ(here.size(), size_t(n) * n);
        if (x + 1 < 2) {
          const auto& right = charts[size_t(y * 2 + x + 1)].colours[k];
          for (uint32_t v = 0; v < n; ++v, ++compared) EXPECT_EQ(here[v * n + n - 1], right[v * n]) << k;
        }
        if (y + 1 < 3) {
          const auto& top = charts[size_t((y + 1) * 2 + x)].colours[k];
          for (uint32_t u = 0; u < n; ++u, ++compared) EXPECT_EQ(here[(n - 1) * n + u], top[u]) << k;
        }
      }
  }
  EXPECT_GT(compared, 300u);
  // A coarser sample is the rounded [1 2 1]^2 / 16 filter of the finer level round it.
  const auto& f = charts[0].colours[0];
  const auto& c = charts[0].colours[1];
  uint32_t sum = 0;
  for (int j = -1; j <= 1; ++j)
    for (int i = -1; i <= 1; ++i) sum += uint32_t((i ? 1 : 2) * (j ? 1 : 2)) * f[size_t((10 + j) * 65 + 10 + i)][0];
  EXPECT_EQ(c[5 * 33 + 5][0], uint8_t((sum + 8) >> 4));
}

// Random colours on a 5 x 4 grid of 17-sample charts at 2 imagery samples per interval, the raster
// narrower and shorter than the grid (the rest edge-clamped).
ImageryRaster randomRaster(uint32_t chartsX, uint32_t chartsY, uint32_t intervals) {
  ImageryRaster raster;
  raster.scaleLog2 = 1;
  raster.width = chartsX * intervals - 5;
  raster.height = chartsY * intervals - 3;
  std::mt19937 rng(11);
  raster.rgba.resize(size_t(raster.width) * raster.height);
  for (PackedColour& c : raster.rgba) c = {uint8_t(rng()), uint8_t(rng()), uint8_t(rng()), uint8_t(rng())};
  return raster;
}

// The charts of a window whose margin is `margin` level-0 samples round the chart (gridX, gridY),
// against the whole pyramid's: the number of differing samples over every level.
uint64_t windowDifferences(const ImageryRaster& raster, const ImageryPyramid& whole, uint32_t chartsX, uint32_t chartsY,
                           uint32_t chartSize, uint32_t levels, int32_t gridX, int32_t gridY, uint32_t margin) {
  const uint32_t ci = (chartSize - 1) << raster.scaleLog2;
  const uint32_t gridW = chartsX * ci + 1, gridH = chartsY * ci + 1;
  const uint32_t x0 = std::max<int64_t>(int64_t(gridX) * ci - margin, 0);
  const uint32_t y0 = std::max<int64_t>(int64_t(gridY) * ci - margin, 0);
  const uint32_t x1 = std::min(gridW, uint32_t(gridX + 1) * ci + margin + 1);
  const uint32_t y1 = std::min(gridH, uint32_t(gridY + 1) * ci + margin + 1);
  std::vector<PackedColour> base(size_t(x1 - x0) * (y1 - y0));
  for (uint32_t y = y0; y < y1; ++y)
    for (uint32_t x = x0; x < x1; ++x)
      base[size_t(y - y0) * (x1 - x0) + (x - x0)] =
          raster.rgba[size_t(std::min(y, raster.height - 1)) * raster.width + std::min(x, raster.width - 1)];
  const ImageryPyramid window(std::move(base), {x0, y0, x1 - x0, y1 - y0},
                              {chartsX, chartsY, chartSize, raster.scaleLog2}, levels);
  const ChartPyramid a = whole.chart(gridX, gridY), b = window.chart(gridX, gridY);
  uint64_t differ = 0;
  for (uint32_t k = 0; k < levels; ++k)
    for (size_t i = 0; i < a.colours[k].size(); ++i) differ += a.colours[k][i] != b.colours[k][i];
  return differ;
}

// A window with a margin of 2^(levels - 1) level-0 samples round a chart (each coarser level's
// filter reads one sample past it; a window starts on a multiple of it) gives that chart's pyramid
// bit for bit; a window of the chart alone does not (so the comparison sees the margin).
TEST(ImageryPyramid, AWindowWithItsMarginGivesTheWholePyramidsCharts) {
  const uint32_t chartsX = 5, chartsY = 4, chartSize = 17, levels = 5;
  const ImageryRaster raster = randomRaster(chartsX, chartsY, 32);
  const ImageryPyramid whole(raster, chartsX, chartsY, chartSize, levels);
  const uint32_t margin = 1u << (levels - 1);
  uint64_t shortDifferences = 0;
  for (int32_t y = 0; y < int32_t(chartsY); ++y)
    for (int32_t x = 0; x < int32_t(chartsX); ++x) {
      EXPECT_EQ(windowDifferences(raster, whole, chartsX, chartsY, chartSize, levels, x, y, margin), 0u)
          << x << "," << y;
      shortDifferences += windowDifferences(raster, whole, chartsX, chartsY, chartSize, levels, x, y, 0);
    }
  EXPECT_GT(shortDifferences, 0u) << "a window without a margin gave every chart exactly";
  // A window that does not hold the chart is refused.
  const ImageryPyramid corner(std::vector<PackedColour>(size_t(49) * 49), {0, 0, 49, 49},
                              {chartsX, chartsY, chartSize, raster.scaleLog2}, levels);
  EXPECT_THROW(corner.chart(2, 0), std::invalid_argument);
}

// The shipped tile's imagery (on the DEM's own lattice, 1201^2) written window by window, in
// windows of 8 x 8 charts and less, is the whole raster's, file for file; the coverage is the same.
TEST_F(ImageryTest, WindowByWindowWritesTheWholeRastersFiles) {
  TerrainAtlasOptions atlas;
  atlas.chartSize = 129;
  atlas.blockIntervals = 64;
  AtlasManifest a;
  fs::create_directories(dir_.path() / "whole");
  fs::create_directories(dir_.path() / "windows");
  writeTerrainCharts(*dem_, atlas, dir_.path() / "whole", a);
  AtlasManifest b = a;
  ImageryOptions o;
  o.path = test::repoData() / "terrain" / "mt_rainier_imagery.tif";
  o.scaleLog2 = 0;
  const ImageryRaster raster = loadImagery(*dem_, rainier(), o);
  writeImageryCharts(raster, "imagery", dir_.path() / "whole", a);
  ImagerySource source(*dem_, rainier(), o);
  ImageryWindowStats ws;
  // 8 x 8 charts of 128 intervals and their margins in 3/4 of 24 MiB: (8 * 128 + 2 * 128 + 1)^2
  // x 10 bytes; the rest keeps one reprojected tile.
  writeImageryChartsWindowed(source, "imagery", dir_.path() / "windows", b, {24u << 20}, &ws);
  std::printf("  %zu charts, %u x %u imagery samples: %llu windows of at most %llu samples\n", a.charts.size(),
              raster.width, raster.height, (unsigned long long)ws.windows, (unsigned long long)ws.windowSamples);
  EXPECT_EQ(ws.windows, 4u);
  EXPECT_LT(ws.windowSamples, uint64_t(raster.width) * raster.height);
  EXPECT_EQ(b.imagery.coverage, raster.coverage);
  EXPECT_EQ(b.imagery.coverage, a.imagery.coverage);
  EXPECT_EQ(b.imagery.scaleLog2, a.imagery.scaleLog2);
  ASSERT_EQ(a.charts.size(), b.charts.size());
  for (size_t i = 0; i < a.charts.size(); ++i) {
    ASSERT_EQ(a.charts[i].imageryFile, b.charts[i].imageryFile);
    EXPECT_EQ(test::fileBytes(dir_.path() / "whole" / a.charts[i].imageryFile),
              test::fileBytes(dir_.path() / "windows" / b.charts[i].imageryFile))
        << a.charts[i].imageryFile;
  }
}

// Charts built in tiles take their imagery tile by tile (here 257-sample charts in tiles of 64
// intervals, blocks of 16, imagery at twice the DEM's lattice: 4 x 4 tiles of 128 imagery
// intervals a chart, the levels from 3 up from the grid's level 3): every level of every chart
// decodes to the whole raster's pyramid, bit for bit, so shared borders stay identical; the
// coverage is the whole raster's.
TEST_F(ImageryTest, TiledChartsTakeTheWholePyramidsColours) {
  TerrainAtlasOptions atlas;
  atlas.chartSize = 257;
  atlas.blockIntervals = 16;
  AtlasManifest a;
  fs::create_directories(dir_.path() / "tiles");
  writeTerrainCharts(*dem_, atlas, dir_.path() / "tiles", a);
  ImageryOptions o;
  o.path = test::repoData() / "terrain" / "mt_rainier_imagery.tif";
  o.scaleLog2 = 1;
  const ImageryRaster raster = loadImagery(*dem_, rainier(), o);
  ImagerySource source(*dem_, rainier(), o);
  ImageryWindowStats ws;
  // A quarter of 256 MiB keeps every reprojected tile of the 2401^2 lattice.
  writeImageryChartsWindowed(source, "imagery", dir_.path() / "tiles", a, {256u << 20, 64}, &ws);
  EXPECT_EQ(ws.windows, uint64_t(a.chartsX) * a.chartsY * 16);
  EXPECT_EQ(a.imagery.coverage, raster.coverage);
  const ImageryPyramid whole(raster, a.chartsX, a.chartsY, a.chartSize, a.pyramidLevels());
  for (const ChartInfo& c : a.charts) {
    const ChartFileReader file(dir_.path() / "tiles" / c.imageryFile);
    ASSERT_EQ(file.chartSize(), 513u);
    ASSERT_EQ(file.levels(), a.pyramidLevels());
    const ChartPyramid want = whole.chart(c.gridX, c.gridY);
    for (uint32_t k = 0; k < file.levels(); ++k)
      ASSERT_TRUE(file.readLevelColours(k) == want.colours[k]) << c.imageryFile << " level " << k;
  }
}

}  // namespace
}  // namespace gimlod

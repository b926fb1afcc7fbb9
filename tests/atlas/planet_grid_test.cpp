// A longitude/latitude DEM made ready for the sphere (atlas/terrain/planet_grid.h).
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <numeric>
#include <tuple>

#include <gdal.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>
#include <nlohmann/json.hpp>

#include "atlas/terrain/planet_grid.h"
#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "atlas/terrain/imagery.h"
#include "atlas/mesh/mesh_atlas.h"
#include "core/atlas_format.h"
#include "core/planet.h"
#include "core/stage_meter.h"
#include "pipeline/build.h"
#include "pipeline/sharded_build.h"
#include "pipeline/terrain_build.h"
#include "tests/imagery_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

// A geographic DEM of w x h samples of `step` degrees from (west, north) (GDAL's corner), heights
// from f(column, row from the south).
template <typename F>
DemRaster geographicDem(uint32_t w, uint32_t h, double west, double north, double step, F f) {
  DemRaster d;
  d.width = w;
  d.height = h;
  d.georef.geographic = true;
  d.georef.geotransform = {west, step, 0.0, north, 0.0, -step};
  d.integerHeights = true;
  d.heights.resize(size_t(w) * h);
  d.minHeight = 1e30f;
  d.maxHeight = -1e30f;
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) {
      const float v = f(x, y);
      d.heights[size_t(y) * w + x] = v;
      d.minHeight = std::min(d.minHeight, v);
      d.maxHeight = std::max(d.maxHeight, v);
    }
  return d;
}

float at(const DemRaster& d, uint32_t x, uint32_t y) { return d.heights[size_t(y) * d.width + x]; }

// The planet lattice of an in-memory DEM, row by row as DemSource lays it.
PlanetInfo preparePlanetGrid(DemRaster& d, const std::filesystem::path& input, double radius, uint32_t m) {
  PlanetGrid g = planPlanetGrid({d.georef, d.width, d.height, d.integerHeights}, input, radius, m);
  const std::vector<uint8_t> valid(d.heights.size(), 1);
  g.southMean = poleRowMean(g, &d.heights[size_t(g.southMeanRow) * d.width], valid.data(), input);
  g.northMean = poleRowMean(g, &d.heights[size_t(g.northMeanRow) * d.width], valid.data(), input);
  std::vector<float> out(size_t(g.width()) * g.height());
  std::vector<uint8_t> outValid(out.size());
  for (uint32_t y = 0; y < g.height(); ++y) {
    const int64_t s = g.sourceRow(y);
    planetGridRow(g, y, s < 0 ? nullptr : &d.heights[size_t(s) * d.width], s < 0 ? nullptr : valid.data(),
                  &out[size_t(y) * g.width()], &outValid[size_t(y) * g.width()]);
  }
  d.heights.swap(out);
  d.width = g.width();
  d.height = g.height();
  d.spacing = planetGridSpacing(g);
  return g.info;
}

TEST(PlanetGrid, CellCentredGlobeWrapsOnChartBordersAndGainsPoleRows) {
  // 40 x 20 cells of 9 degrees: 40 columns a turn, made 48 (3 charts of 16), plus the wrap column.
  DemRaster d = geographicDem(40, 20, -180.0, 90.0, 9.0, [](uint32_t x, uint32_t y) { return float(x * 10 + y); });
  const DemRaster before = d;
  const PlanetInfo p = preparePlanetGrid(d, "globe.tif", kEarthRadius, 16);
  EXPECT_EQ(p.wrapColumns, 48u);
  EXPECT_DOUBLE_EQ(p.dlonDeg, 7.5);
  EXPECT_DOUBLE_EQ(p.lon0Deg, -175.5);
  EXPECT_EQ(d.width, 49u);
  EXPECT_EQ(d.height, 22u);
  EXPECT_DOUBLE_EQ(p.lat0Deg, -94.5);  // the added row, clamped onto the pole
  for (uint32_t y = 0; y < d.height; ++y) EXPECT_EQ(at(d, 48, y), at(d, 0, y)) << y;
  // The pole rows: uniform, at the mean of the source row next to them.
  double south = 0, north = 0;
  for (uint32_t x = 0; x < 40; ++x) {
    south += at(before, x, 0);
    north += at(before, x, 19);
  }
  for (uint32_t x = 0; x < 49; ++x) {
    EXPECT_EQ(at(d, x, 0), std::nearbyint(south / 40.0));
    EXPECT_EQ(at(d, x, 21), std::nearbyint(north / 40.0));
  }
  // Resampled linearly round the circle: column 0 kept, a column between two source ones between
  // their heights, whole metres kept.
  for (uint32_t y = 0; y < 20; ++y) {
    EXPECT_EQ(at(d, 0, y + 1), at(before, 0, y));
    const float mid = at(d, 5, y + 1);  // 5 * 40 / 48 = 4.17 source columns
    EXPECT_GE(mid, std::min(at(before, 4, y), at(before, 5, y)));
    EXPECT_LE(mid, std::max(at(before, 4, y), at(before, 5, y)));
    EXPECT_EQ(mid, std::nearbyint(mid));
    // The last source column wraps onto column 0: (47 * 40 / 48 = 39.17) between 39 and 0.
    const float last = at(d, 47, y + 1);
    EXPECT_GE(last, std::min(at(before, 39, y), at(before, 0, y)));
    EXPECT_LE(last, std::max(at(before, 39, y), at(before, 0, y)));
  }
  EXPECT_NEAR(d.spacing[0], kEarthRadius * 7.5 * M_PI / 180.0, 1e-6);
}

TEST(PlanetGrid, GridRegisteredGlobeKeepsItsSamples) {
  // 41 x 21 samples of 9 degrees on the meridians and parallels: the last column repeats the
  // first, the first and last rows lie on the poles.
  DemRaster d =
      geographicDem(41, 21, -184.5, 94.5, 9.0, [](uint32_t x, uint32_t y) { return float((x % 40) + 100 * y); });
  const DemRaster before = d;
  const PlanetInfo p = preparePlanetGrid(d, "grid.tif", 1000.0, 8);
  EXPECT_EQ(p.wrapColumns, 40u);
  EXPECT_EQ(d.width, 41u);
  EXPECT_EQ(d.height, 21u);
  EXPECT_DOUBLE_EQ(p.lat0Deg, -90.0);
  EXPECT_DOUBLE_EQ(p.radius, 1000.0);
  for (uint32_t y = 1; y < 20; ++y)
    for (uint32_t x = 0; x < 41; ++x) EXPECT_EQ(at(d, x, y), at(before, x % 40, y));
  for (uint32_t x = 0; x < 41; ++x) {
    EXPECT_EQ(at(d, x, 0), at(d, 0, 0));
    EXPECT_EQ(at(d, x, 20), at(d, 0, 20));
  }
}

TEST(PlanetGrid, RowsPastThePolesMeetThere) {
  // A globe resampled finer whose rows pass the poles by a third of a degree (as an upsampled
  // ETOPO5 does): the rows on or past each pole are uniform, at the mean of the one nearest it.
  const double step = 0.25;
  DemRaster d = geographicDem(1440, 724, -180.0, 90.0 + 0.375 + 0.125, step,
                              [](uint32_t x, uint32_t y) { return float((x * 7 + y * 3) % 1000); });
  const DemRaster before = d;
  const PlanetInfo p = preparePlanetGrid(d, "fine.tif", kEarthRadius, 64);
  EXPECT_EQ(p.wrapColumns, 1472u);
  EXPECT_EQ(d.height, 724u);
  const PlanetFrame f(p, d.width, d.height);
  ASSERT_GE(f.southPoleRow(), 1);    // rows 0 and 1 lie on or past the south pole
  ASSERT_LE(f.northPoleRow(), 722);  // rows 722 and 723 on or past the north pole
  for (int64_t y = 0; y <= f.southPoleRow(); ++y)
    for (uint32_t x = 0; x < d.width; ++x) EXPECT_EQ(at(d, x, uint32_t(y)), at(d, 0, 0));
  for (int64_t y = f.northPoleRow(); y < 724; ++y)
    for (uint32_t x = 0; x < d.width; ++x) EXPECT_EQ(at(d, x, uint32_t(y)), at(d, 0, 723));
  double mean = 0.0;
  for (uint32_t x = 0; x < 1440; ++x) mean += at(before, x, uint32_t(f.southPoleRow()));
  EXPECT_EQ(at(d, 0, 0), std::nearbyint(mean / 1440.0));
  // The next row is the DEM's own, resampled.
  EXPECT_EQ(at(d, 0, uint32_t(f.southPoleRow() + 1)), at(before, 0, uint32_t(f.southPoleRow() + 1)));
  // Past the slack: refused.
  DemRaster far = geographicDem(1440, 727, -180.0, 91.0, step, [](uint32_t, uint32_t) { return 0.0f; });
  EXPECT_THROW(preparePlanetGrid(far, "far.tif", kEarthRadius, 64), InputError);
}

TEST(PlanetGrid, ARegionalDemIsLeftAsItIs) {
  DemRaster d = geographicDem(100, 80, 10.0, 50.0, 0.01, [](uint32_t x, uint32_t y) { return float(x + y); });
  const DemRaster before = d;
  const PlanetInfo p = preparePlanetGrid(d, "alps.tif", kEarthRadius, 64);
  EXPECT_EQ(p.wrapColumns, 0u);
  EXPECT_EQ(d.width, 100u);
  EXPECT_EQ(d.height, 80u);
  EXPECT_EQ(d.heights, before.heights);
  EXPECT_DOUBLE_EQ(p.lon0Deg, 10.005);
  EXPECT_NEAR(p.lat0Deg, 49.205, 1e-9);
}

// A DEM whose extent misses 360 degrees by more than half its pixel (ETOPO5's NetCDF spans 360.0033
// degrees; resampled to 207,872 columns that is 3.8 pixels) is regional, and says why; its
// extent given exactly, it wraps. The regional DEM above says nothing.
TEST(PlanetGrid, ANearlyGlobalDemThatDoesNotWrapSaysSo) {
  Georeference near;
  near.geographic = true;
  near.geotransform = {-0.0416671, 360.0033 / 207872, 0.0, 90.04, 0.0, -0.0017};
  const PlanetGrid g = planPlanetGrid({near, 207872, 1000, true}, "big.vrt", kEarthRadius, 16384);
  EXPECT_EQ(g.info.wrapColumns, 0u);
  EXPECT_NE(g.warning.find("360.0033 degrees"), std::string::npos) << g.warning;
  EXPECT_NE(g.warning.find("-a_ullr"), std::string::npos) << g.warning;
  Georeference exact = near;
  exact.geotransform[1] = 360.0 / 207872;
  const PlanetGrid w = planPlanetGrid({exact, 207872, 1000, true}, "big.vrt", kEarthRadius, 16384);
  EXPECT_EQ(w.info.wrapColumns, 212992u);
  EXPECT_TRUE(w.warning.empty()) << w.warning;
  DemRaster alps = geographicDem(100, 80, 10.0, 50.0, 0.01, [](uint32_t, uint32_t) { return 0.0f; });
  EXPECT_TRUE(planPlanetGrid({alps.georef, 100, 80, true}, "alps.tif", kEarthRadius, 64).warning.empty());
}

TEST(PlanetGrid, AProjectedDemIsRefusedByName) {
  DemRaster d = geographicDem(10, 10, 500000.0, 5200000.0, 30.0, [](uint32_t, uint32_t) { return 0.0f; });
  d.georef.geographic = false;
  try {
    preparePlanetGrid(d, "utm.tif", kEarthRadius, 8);
    FAIL() << "a projected DEM was taken";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("utm.tif"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("longitude and latitude"), std::string::npos);
  }
}

// The window-by-window build reads the same planet lattice: its atlas is byte-identical to the
// in-memory build's (but the build statistics).
// The shipped 30' Earth as a planet atlas at `output`, in charts of chartSize.
TerrainBuildOptions shippedGlobe(const std::filesystem::path& output, uint32_t chartSize) {
  TerrainBuildOptions o;
  o.input = test::repoData() / "terrain/etopo_30min.tif";
  o.output = output;
  o.planet = true;
  o.chartSize = chartSize;
  return o;
}

TEST(PlanetGrid, TheWindowedBuildGivesTheSameAtlas) {
  test::TempDir dir("planet_windowed");
  TerrainBuildOptions o = shippedGlobe(dir.path() / "memory.atlas", 129);
  buildAtlas(o);
  o.output = dir.path() / "windowed.atlas";
  o.outOfCore = true;
  o.maxMemory = uint64_t(1) << 30;
  buildAtlas(o);
  uint32_t files = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir.path() / "memory.atlas")) {
    if (!e.is_regular_file() || e.path().filename() == "stats.json") continue;
    const auto rel = std::filesystem::relative(e.path(), dir.path() / "memory.atlas");
    EXPECT_EQ(test::fileBytes(e.path()), test::fileBytes(dir.path() / "windowed.atlas" / rel)) << rel;
    ++files;
  }
  EXPECT_GT(files, 10u);
  const std::string stats = test::fileBytes(dir.path() / "windowed.atlas/stats.json");
  EXPECT_NE(stats.find("windowed"), std::string::npos);
}

// The normals of a chart's samples on the antimeridian are central differences across it, as
// everywhere else: the first chart column's west border and the last one's east border (the same
// samples) hold the same normals, bit for bit, stored or derived from compressed heights, at every
// level; and they match the difference of the heights either side.
TEST(PlanetGrid, NormalsAreCentralDifferencesAcrossTheAntimeridian) {
  test::TempDir dir("planet_normals");
  for (const bool compress : {true, false}) {
    TerrainBuildOptions o = shippedGlobe(dir.path() / (compress ? "compressed.atlas" : "raw.atlas"), 65);
    o.compress = compress;
    buildAtlas(o);
    const AtlasManifest m = readManifest(o.output);
    ASSERT_EQ(uint64_t(m.chartsX) * (m.chartSize - 1), m.planet.wrapColumns);
    uint64_t samples = 0, sloped = 0;
    for (uint32_t gy = 0; gy < m.chartsY; ++gy) {
      const ChartFileReader west(o.output / m.charts[size_t(gy) * m.chartsX].file);
      const ChartFileReader east(o.output / m.charts[size_t(gy) * m.chartsX + m.chartsX - 1].file);
      for (uint32_t k = 0; k < west.levels(); ++k) {
        const uint32_t s = ((m.chartSize - 1) >> k) + 1;
        const auto wn = west.readLevelNormals(k), en = east.readLevelNormals(k);
        const auto wh = west.readLevelHeights(k), eh = east.readLevelHeights(k);
        for (uint32_t v = 0; v < s; ++v) {
          const PackedNormal a = wn[size_t(v) * s], b = en[size_t(v) * s + s - 1];
          ASSERT_EQ(a, b) << (compress ? "compressed" : "raw") << " row " << gy << " level " << k << " sample " << v;
          // The east slope from the samples a level step either side of the antimeridian: the normal's
          // east component is -dx / sqrt(dx^2 + dy^2 + 1), so within the north slope's share of
          // -dx / sqrt(dx^2 + 1), which the other tests check.
          const double dx = (double(wh[size_t(v) * s + 1]) - double(eh[size_t(v) * s + s - 2])) /
                            (2.0 * double(1u << k) * m.spacing[0]);
          const double nx = -dx / std::sqrt(dx * dx + 1.0);
          const double stored = (double(a[0]) - 128.0) / 127.5;
          EXPECT_LE(std::abs(stored - nx), 0.02 + std::abs(nx) * 0.5)
              << "row " << gy << " level " << k << " sample " << v << ": east slope " << dx;
          if (std::abs(dx) > 0.01) {
            ++sloped;
            EXPECT_EQ(std::signbit(stored), std::signbit(nx)) << "row " << gy << " level " << k << " sample " << v;
          }
          ++samples;
        }
      }
    }
    EXPECT_GT(sloped, samples / 20) << "too few sloped samples on the antimeridian to tell";
  }
}

// The shipped Earth resampled to w x h samples (a VRT) at `path`.
void upsampledEarth(const std::filesystem::path& path, uint32_t w, uint32_t h) {
  GDALAllRegister();
  const std::string ws = std::to_string(w), hs = std::to_string(h);
  const char* args[] = {"-of", "VRT", "-outsize", ws.c_str(), hs.c_str(), "-r", "bilinear", nullptr};
  GDALTranslateOptions* to = GDALTranslateOptionsNew(const_cast<char**>(args), nullptr);
  GDALDatasetH src = GDALOpen((test::repoData() / "terrain/etopo_30min.tif").c_str(), GA_ReadOnly);
  ASSERT_NE(src, nullptr);
  GDALDatasetH vrt = GDALTranslate(path.c_str(), src, to, nullptr);
  ASSERT_NE(vrt, nullptr);
  GDALClose(vrt);
  GDALClose(src);
  GDALTranslateOptionsFree(to);
}

// A planet's chart size is the plan's unless that adds over 1/16 of the DEM's columns round the
// turn: 9,000 columns make 9,216 in the plan's charts of 1,025 (kept); 8,400 would make 9,216
// there (9.7% more), 8,704 in charts of 513 (3.6%).
TEST(PlanetGrid, ChartsAreHalvedWhereThePlansWouldAddColumns) {
  test::TempDir dir("planet_chart_size");
  for (const auto& [w, planned, chosen, turn] : {std::tuple{9000u, 1025u, 1025u, 9216u}, {8400u, 1025u, 513u, 8704u}}) {
    SCOPED_TRACE(w);
    const std::filesystem::path vrt = dir.path() / ("earth" + std::to_string(w) + ".vrt");
    upsampledEarth(vrt, w, w / 2);
    TerrainBuildOptions o;
    o.input = vrt;
    TerrainPlan flat;
    plannedTerrainBuild(o, &flat);
    EXPECT_EQ(flat.chartSize, planned);
    o.planet = true;
    const TerrainBuildOptions p = plannedTerrainBuild(o);
    EXPECT_EQ(p.chartSize, chosen);
    o.chartSize = p.chartSize;
    EXPECT_EQ(DemSource(vrt, terrainDemOptions(o)).info().planet.wrapColumns, turn);
  }
}

// A window-by-window build whose memory cap builds charts of 513 in tiles reads the tiles' margins
// and the coarse lattice across the antimeridian: every level's heights and normals are the
// in-memory build's; and so are those of a build in three shards, whose charts at the antimeridian
// gather the lattice past it that their own windows do not hold.
TEST(PlanetGrid, ChartsBuiltInTilesReadAcrossTheAntimeridian) {
  test::TempDir dir("planet_tiles");
  // The shipped Earth at twice its resolution (a VRT): 4 chart columns a turn, so that the charts
  // at the antimeridian read lattice no window of theirs holds.
  upsampledEarth(dir.path() / "earth2.vrt", 1537, 723);
  TerrainBuildOptions o;
  o.input = dir.path() / "earth2.vrt";
  o.planet = true;
  o.chartSize = 513;
  o.output = dir.path() / "memory.atlas";
  buildAtlas(o);
  // Each step's cap is what it holds now and 40 MiB: about 25 MiB of windows (the GDAL cache and a
  // fifth kept out), between the 16 MiB floor and the 36 MiB that would hold a chart of 513 and its
  // neighbours' margins whole. Each step measures its own, as a process of its own would: memory
  // the steps before left resident would otherwise narrow the later steps' windows. Freed memory is
  // handed back first, so that what the process holds does not fall after the cap is set.
  const auto cap = [] {
    releaseFreedMemory();
    return residentBytes() + (uint64_t{40} << 20);
  };
  o.output = dir.path() / "tiled.atlas";
  o.outOfCore = true;
  o.maxMemory = cap();
  const nlohmann::json stats = buildAtlas(o);
  ASSERT_LT(stats.at("windowed").at("band_rows").get<uint64_t>(), 3u * 512u + 1u)
      << "the cap did not have the charts built in tiles";
  TerrainBuildOptions sharded = o;
  sharded.output = dir.path() / "sharded.atlas";
  sharded.outOfCore = false;
  sharded.maxMemory = cap();
  prepareShards(sharded);
  for (uint32_t i = 0; i < 3; ++i) {
    sharded.maxMemory = cap();
    buildShard(sharded, {i, 3});
  }
  mergeShards(sharded.output);
  const AtlasManifest m = readManifest(o.output);
  ASSERT_GE(m.chartsX, 4u);
  ASSERT_EQ(uint64_t(m.chartsX) * 512u, m.planet.wrapColumns);
  for (const ChartInfo& c : m.charts)
    for (const std::filesystem::path& built : {o.output, sharded.output}) {
      const ChartFileReader a(dir.path() / "memory.atlas" / c.file), b(built / c.file);
      for (uint32_t k = 0; k < a.levels(); ++k) {
        EXPECT_EQ(a.readLevelHeights(k), b.readLevelHeights(k)) << c.file << " level " << k;
        const auto an = a.readLevelNormals(k), bn = b.readLevelNormals(k);
        ASSERT_EQ(an.size(), bn.size());
        size_t differ = 0;
        for (size_t i = 0; i < an.size(); ++i) differ += an[i] != bn[i];
        EXPECT_EQ(differ, 0u) << built.filename() << " " << c.file << " level " << k;
      }
    }
}

// A global image whose colours change across the antimeridian (red ramps up eastwards from 0 at
// 180 W to 255 at 180 E; green waves; blue ramps with latitude).
void writeGlobeImagery(const std::filesystem::path& path) {
  test::writeTestRaster(
      path, 720, 360,
      [](int x, int y) {
        return std::array<uint8_t, 3>{uint8_t(x * 255 / 719), uint8_t(128 + 100 * std::sin(0.026 * x + 0.05 * y)),
                                      uint8_t(y * 255 / 359)};
      },
      {-180.0, 0.5, 0.0, 90.0, 0.0, -0.5}, 4326);
}

// The colours of chart files `west` and `east` at level k, on the west one's first column and the
// east one's last: the same place on the planet.
size_t seamDifferences(const std::filesystem::path& west, const std::filesystem::path& east, uint32_t k) {
  const ChartFileReader w(west), e(east);
  const std::vector<PackedColour> a = w.readLevelColours(k), b = e.readLevelColours(k);
  const size_t side = size_t(std::lround(std::sqrt(double(a.size()))));
  size_t differ = 0;
  for (size_t v = 0; v < side; ++v) differ += a[v * side] != b[v * side + side - 1];
  return differ;
}

// The seam's differences in every level of every chart row of the atlas in `dir` (manifest m), and
// the levels checked.
std::pair<size_t, uint32_t> seamDifferences(const std::filesystem::path& dir, const AtlasManifest& m) {
  size_t differ = 0;
  uint32_t levels = 0;
  for (uint32_t gy = 0; gy < m.chartsY; ++gy) {
    const ChartInfo& west = m.charts[size_t(gy) * m.chartsX];
    const ChartInfo& east = m.charts[size_t(gy) * m.chartsX + m.chartsX - 1];
    for (uint32_t k = 0; k < m.pyramidLevels(); ++k, ++levels)
      differ += seamDifferences(dir / west.imageryFile, dir / east.imageryFile, k);
  }
  return {differ, levels};
}

// The shipped globe (`input`) read as a planet lattice for charts of `intervals`.
DemRaster globeLattice(const std::filesystem::path& input, uint32_t intervals) {
  DemOptions d;
  d.planetRadius = kEarthRadius;
  d.planetChartIntervals = intervals;
  return loadDem(input, d);
}

// The globe's imagery (writeGlobeImagery) written into `dir`, and the options that drape it.
ImageryOptions globeImageryOptions(const std::filesystem::path& dir) {
  writeGlobeImagery(dir / "globe.tif");
  ImageryOptions io;
  io.path = dir / "globe.tif";
  return io;
}

// A planet's imagery meets itself at the antimeridian: the first column of charts' west borders and
// the last column's east borders hold the same colours at every level, where the colours change
// across it, written whole, window by window and in tiles; and the windows' and tiles' colours are
// the whole raster's.
TEST(PlanetGrid, ImageryMeetsItselfAtTheAntimeridianAtEveryLevel) {
  test::TempDir dir("planet_imagery");
  const std::filesystem::path input = test::repoData() / "terrain/etopo_30min.tif";
  const DemRaster dem = globeLattice(input, 128);
  const ImageryOptions io = globeImageryOptions(dir.path());
  ImagerySource source(dem, input, io);
  TerrainAtlasOptions atlas;
  atlas.chartSize = 129;
  atlas.blockIntervals = 16;
  for (const char* way : {"whole", "windows", "tiles"}) {
    SCOPED_TRACE(way);
    const std::filesystem::path out = dir.path() / way;
    std::filesystem::create_directories(out);
    AtlasManifest m;
    writeTerrainCharts(dem, atlas, out, m);
    ASSERT_EQ(uint64_t(m.chartsX) * (m.chartSize - 1), m.planet.wrapColumns);
    ImageryWindowStats ws;
    if (way == std::string("whole"))
      writeImageryCharts(loadImagery(dem, input, io), "globe", out, m);
    else if (way == std::string("windows"))
      writeImageryChartsWindowed(source, "globe", out, m, {uint64_t{2} << 20}, &ws);
    else
      writeImageryChartsWindowed(source, "globe", out, m, {uint64_t{64} << 20, 32}, &ws);
    if (way == std::string("windows")) {
      EXPECT_GT(ws.windows, 1u) << "the seam is not across windows";
    }
    if (way == std::string("tiles")) {
      EXPECT_GT(ws.windows, m.charts.size()) << "the charts were not built in tiles";
    }
    const auto [differ, levels] = seamDifferences(out, m);
    EXPECT_EQ(differ, 0u);
    EXPECT_EQ(levels, m.chartsY * m.pyramidLevels());
    for (const ChartInfo& c : m.charts) {
      const ChartFileReader got(out / c.imageryFile), want(dir.path() / "whole" / c.imageryFile);
      ASSERT_EQ(got.levels(), want.levels());
      for (uint32_t k = 0; k < got.levels(); ++k)
        EXPECT_TRUE(got.readLevelColours(k) == want.readLevelColours(k)) << c.imageryFile << " level " << k;
    }
  }
}

// Imagery written in parts of the charts and finished from their coarse levels, as the shards and
// the merge of a build write it, is the whole's, file for file, and the parts' covered samples add
// up to the whole's coverage: parts of whole rows, of rows cut anywhere, and the east column alone
// (whose east borders come from tiles of the first column that the part does not hold), for charts
// in one tile each and in tiles of 32 intervals.
TEST(PlanetGrid, ImageryWrittenInPartsAndFinishedIsTheWholesFileForFile) {
  test::TempDir dir("planet_imagery_parts");
  const std::filesystem::path input = test::repoData() / "terrain/etopo_30min.tif";
  const DemRaster dem = globeLattice(input, 64);
  const ImageryOptions io = globeImageryOptions(dir.path());
  ImagerySource source(dem, input, io);
  TerrainAtlasOptions atlas;
  atlas.chartSize = 65;
  atlas.blockIntervals = 16;
  AtlasManifest whole;
  std::filesystem::create_directories(dir.path() / "geometry");
  writeTerrainCharts(dem, atlas, dir.path() / "geometry", whole);
  const AtlasManifest charts = whole;
  const uint32_t n = uint32_t(whole.charts.size());
  std::vector<uint32_t> east, rest;
  for (uint32_t c = 0; c < n; ++c) (uint32_t(whole.charts[c].gridX) + 1 == whole.chartsX ? east : rest).push_back(c);
  auto run = [](uint32_t from, uint32_t to) {
    std::vector<uint32_t> r(to - from);
    std::iota(r.begin(), r.end(), from);
    return r;
  };
  const uint32_t row = whole.chartsX;
  const std::vector<std::vector<std::vector<uint32_t>>> splits = {
      {run(0, 2 * row), run(2 * row, n)},                 // whole rows
      {run(0, n / 3), run(n / 3, n - 5), run(n - 5, n)},  // rows cut anywhere
      {east, rest}};
  for (const uint32_t maxTile : {kMaxChartTile, 32u}) {
    // One process's files: charts in tiles of maxTile intervals (in one tile each, the whole
    // raster's files).
    const std::filesystem::path one = dir.path() / ("whole" + std::to_string(maxTile));
    whole = charts;
    if (maxTile == kMaxChartTile)
      writeImageryCharts(loadImagery(dem, input, io), "globe", one, whole);
    else
      writeImageryChartsWindowed(source, "globe", one, whole, {uint64_t{64} << 20, maxTile});
    for (size_t s = 0; s < splits.size(); ++s) {
      SCOPED_TRACE(testing::Message() << "tiles of " << maxTile << ", split " << s);
      const std::filesystem::path out = dir.path() / ("parts" + std::to_string(maxTile) + "-" + std::to_string(s));
      uint64_t covered = 0;
      uint32_t coarseLevel = 0;
      std::vector<PackedColour> coarse;  // every chart's coarse level, in the manifest's order
      std::vector<std::filesystem::path> partials(n);
      for (size_t k = 0; k < splits[s].size(); ++k) {
        const std::vector<uint32_t>& part = splits[s][k];
        const std::filesystem::path partDir = out / ("part" + std::to_string(k));
        AtlasManifest m = charts;
        const ImageryPart written =
            writeImageryChartsPart(source, "globe", partDir, m, {uint64_t{1} << 20, maxTile}, part);
        coarseLevel = written.coarseLevel;
        const size_t side = ((size_t(m.imagery.chartSize(m.chartSize)) - 1) >> coarseLevel) + 1, per = side * side;
        ASSERT_EQ(written.coarse.size(), part.size() * per);
        coarse.resize(n * per);
        covered += written.stats.coveredSamples;
        for (size_t i = 0; i < part.size(); ++i) {
          std::copy_n(written.coarse.begin() + std::ptrdiff_t(i * per), per,
                      coarse.begin() + std::ptrdiff_t(part[i] * per));
          partials[part[i]] = partDir / m.charts[part[i]].imageryFile;
        }
      }
      EXPECT_EQ(double(covered) / (double(source.width()) * double(source.height())), whole.imagery.coverage);
      AtlasManifest m = charts;
      m.imagery = whole.imagery;
      finishImageryCharts(out / "finished", m, partials, std::move(coarse), coarseLevel);
      for (const ChartInfo& c : whole.charts)
        EXPECT_TRUE(test::fileBytes(out / "finished" / c.imageryFile) == test::fileBytes(one / c.imageryFile))
            << c.imageryFile;
    }
  }
}

// A WGS84 planet's samples lie where PROJ puts their longitude, latitude and height (EPSG:4979 to
// the geocentric EPSG:4978), within a millimetre: the shipped globe built with the ellipsoid, the
// samples of a level of every fifth chart.
TEST(PlanetGrid, AWgs84PlanetsSamplesLieWhereProjPutsThem) {
  test::TempDir dir("planet_wgs84");
  TerrainBuildOptions o = shippedGlobe(dir.path() / "wgs84.atlas", 129);
  o.planetRadius = kEllipsoids[0].radius;
  o.planetFlattening = kEllipsoids[0].flattening;
  buildAtlas(o);
  const AtlasManifest m = readManifest(o.output);
  ASSERT_EQ(m.planet.flattening, kEllipsoids[0].flattening);
  OGRSpatialReference geodetic, geocentric;
  ASSERT_EQ(geodetic.importFromEPSG(4979), OGRERR_NONE);
  ASSERT_EQ(geocentric.importFromEPSG(4978), OGRERR_NONE);
  geodetic.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  std::unique_ptr<OGRCoordinateTransformation> toCentre(OGRCreateCoordinateTransformation(&geodetic, &geocentric));
  ASSERT_NE(toCentre, nullptr);
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  const uint32_t level = 2, M = m.chartSize - 1, n = M >> level;
  double worst = 0.0, offSphere = 0.0;
  uint64_t checked = 0;
  for (size_t c = 0; c < m.charts.size(); c += 5) {
    const std::vector<float> h = ChartFileReader(o.output / m.charts[c].file).readHeightsWindow(level, 0, 0, n);
    for (uint32_t v = 0; v <= n; ++v)
      for (uint32_t u = 0; u <= n; ++u) {
        const int64_t gx = m.charts[c].gridX * int64_t(M) + (int64_t(u) << level);
        const int64_t gy = m.charts[c].gridY * int64_t(M) + (int64_t(v) << level);
        double x = frame.longitude(gx) * 180.0 / std::numbers::pi, y = frame.latitude(gy) * 180.0 / std::numbers::pi;
        double z = h[size_t(v) * (n + 1) + u];
        ASSERT_TRUE(toCentre->Transform(1, &x, &y, &z));
        const glm::dvec3 proj(x, y, z), ours = frame.position(gx, gy, h[size_t(v) * (n + 1) + u]);
        worst = std::max(worst, glm::length(ours - proj));
        offSphere = std::max(offSphere, std::fabs(glm::length(proj) - m.planet.radius - z));
        ++checked;
      }
  }
  EXPECT_GT(checked, 2000u);
  EXPECT_LT(worst, 1e-3);
  EXPECT_GT(offSphere, 1.0e4) << "the ellipsoid is no sphere";
}

// The shipped global DEM as a planet atlas: the whole surface, every pyramid level, is closed.
TEST(PlanetGrid, TheShippedGlobeExportsAsAClosedSurfaceAtEveryLevel) {
  test::TempDir dir("planet_export");
  const TerrainBuildOptions o = shippedGlobe(dir.path() / "earth.atlas", 257);
  buildAtlas(o);
  for (uint32_t level = 0; level <= 8; level += 2) {
    const AtlasSurface s = readAtlasSurface(o.output, level);
    EXPECT_EQ(s.boundaryEdges, 0u) << "level " << level;
    // A closed surface of genus 0: V - E + F = 2.
    const int64_t faces = int64_t(s.triangles.size()), edges = faces * 3 / 2;
    EXPECT_EQ(int64_t(s.positions.size()) - edges + faces, 2) << "level " << level;
  }
}

}  // namespace
}  // namespace gimlod

// The terrain chart plan (pipeline/terrain_build.h planTerrain): tens of trees from 1M to 21.6G
// samples, whatever the DEM's shape, with the smallest chart that keeps them there; the depth that
// leaves the finest nodes 32 intervals wide; sizes and depths given are kept; a DEM under 2 x 2
// samples is refused. No DEM is read: the plan depends on the size alone.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include <gdal.h>

#include "atlas/terrain/terrain_atlas.h"
#include "pipeline/build.h"
#include "pipeline/terrain_build.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

uint64_t chartsOf(uint64_t w, uint64_t h, uint32_t chartSize) {
  const uint64_t m = chartSize - 1;
  return std::max<uint64_t>(1, (w - 2 + m) / m) * std::max<uint64_t>(1, (h - 2 + m) / m);
}

TEST(TerrainPlan, TensOfTreesFromOneMillionToTwentyBillionSamples) {
  TerrainBuildOptions o;
  o.maxMemory = uint64_t{16} << 30;  // room for every hierarchy here (the next test lowers it)
  for (const double samples : {1e6, 5.8e6, 1e8, 1.84e8, 2.68e8, 1e9, 5.5e9, 2.16e10}) {
    for (const double aspect : {1.0, 2.0, 0.5, 4.0}) {
      const uint64_t w = uint64_t(std::sqrt(samples * aspect)), h = uint64_t(samples / double(w));
      const TerrainPlan p = planTerrain("dem.tif", w, h, o);
      SCOPED_TRACE(::testing::Message() << w << " x " << h);
      EXPECT_TRUE(p.autoChartSize);
      EXPECT_EQ(uint64_t(p.chartsX) * p.chartsY, chartsOf(w, h, p.chartSize));
      EXPECT_LE(uint64_t(p.chartsX) * p.chartsY, kTargetTerrainCharts);
      // The smallest chart from 513 that does it.
      if (p.chartSize > 513) {
        EXPECT_GT(chartsOf(w, h, (p.chartSize + 1) / 2), kTargetTerrainCharts);
      }
      EXPECT_GE(p.chartSize, 513u);
      EXPECT_LE(p.chartSize, kMaxTerrainChartSize);
      // Finest nodes 32 intervals wide (at least the 5 levels of a 513-sample chart).
      const uint32_t L = uint32_t(std::log2(p.chartSize - 1));
      EXPECT_EQ(p.depth, std::max(5u, L - 4));
      EXPECT_EQ((p.chartSize - 1) >> (p.depth - 1), p.depth == 5 ? (p.chartSize - 1) / 16 : 32u);
      if (aspect == 2.0)
        std::printf("terrain plan: %.3g samples (%llu x %llu): %u x %u charts of %u, depth %u\n", samples,
                    (unsigned long long)w, (unsigned long long)h, p.chartsX, p.chartsY, p.chartSize, p.depth);
    }
  }
  // Puget Sound (16385^2): 8 x 8 charts of 2049 (the paper: 4 trees). North America's 5.5G
  // (172800 x 32000 here) and the Earth's 21.6G (207360 x 103680) in tens.
  const TerrainPlan puget = planTerrain("dem.tif", 16385, 16385, o);
  EXPECT_EQ(puget.chartSize, 2049u);
  EXPECT_EQ(puget.chartsX * puget.chartsY, 64u);
  const TerrainPlan america = planTerrain("dem.tif", 172800, 32000, o),
                    earth = planTerrain("dem.tif", 207360, 103680, o);
  EXPECT_EQ(america.chartSize, 16385u);
  EXPECT_EQ(america.chartsX * america.chartsY, 11u * 2u);
  EXPECT_EQ(earth.chartSize, 32769u);
  EXPECT_EQ(earth.chartsX * earth.chartsY, 7u * 4u);
  // The shipped tile and ETOPO5 keep their 513-sample charts.
  EXPECT_EQ(planTerrain("dem.tif", 1201, 1201, o).chartSize, 513u);
  EXPECT_EQ(planTerrain("dem.tif", 4320, 2160, o).chartSize, 513u);
}

// Imagery is draped on tiled charts as on whole ones: it changes neither the plan nor what
// validates.
TEST(TerrainPlan, ImageryTakesTheHeightsPlan) {
  TerrainBuildOptions o;
  const TerrainPlan bare = planTerrain("dem.tif", 104000, 52000, o);
  o.imagery = "imagery.tif";
  const TerrainPlan p = planTerrain("dem.tif", 104000, 52000, o);
  EXPECT_EQ(p.chartSize, bare.chartSize);
  EXPECT_EQ(p.chartSize, 16385u);
  EXPECT_EQ(p.depth, bare.depth);
  o.chartSize = 4097;
  EXPECT_NO_THROW(validateTerrainBuildOptions(o));
  o.chartSize = 4096;
  EXPECT_THROW(validateTerrainBuildOptions(o), InputError);
}

// The build holds the hierarchy whole: the automatic depth drops a level while it would take over
// a quarter of the memory cap (the Earth's 21.6G samples: 28 trees of 11 levels take 1.76 GB).
TEST(TerrainPlan, TheHierarchyTakesAtMostAQuarterOfTheMemoryCap) {
  TerrainBuildOptions o;
  o.maxMemory = uint64_t{2} << 30;
  const TerrainPlan earth = planTerrain("dem.tif", 207872, 103936, o);
  EXPECT_EQ(earth.chartSize, 32769u);
  EXPECT_EQ(earth.depth, 10u);
  const uint64_t charts = uint64_t(earth.chartsX) * earth.chartsY;
  EXPECT_LE(terrainHierarchyBytes(charts, earth.depth, 5), o.maxMemory / 4);
  EXPECT_GT(terrainHierarchyBytes(charts, earth.depth + 1, 5), o.maxMemory / 4);
  std::printf("terrain plan: 21.6G samples under a 2 GiB cap: depth %u, hierarchy %.0f MB (depth %u: %.0f MB)\n",
              earth.depth, double(terrainHierarchyBytes(charts, earth.depth, 5)) / 1e6, earth.depth + 1,
              double(terrainHierarchyBytes(charts, earth.depth + 1, 5)) / 1e6);
  o.maxMemory = uint64_t{8} << 30;
  EXPECT_EQ(planTerrain("dem.tif", 207872, 103936, o).depth, 11u);
  // Never below kDefaultDepth, and a depth given is kept.
  o.maxMemory = uint64_t{64} << 20;
  EXPECT_EQ(planTerrain("dem.tif", 207872, 103936, o).depth, 7u);
  o.maxMemory = uint64_t{1} << 20;
  EXPECT_EQ(planTerrain("dem.tif", 207872, 103936, o).depth, 5u);
  o.depth = 11;
  EXPECT_EQ(planTerrain("dem.tif", 207872, 103936, o).depth, 11u);
}

TEST(TerrainPlan, GivenSizeAndDepthAreKept) {
  TerrainBuildOptions o;
  o.chartSize = 257;
  o.depth = 3;
  const TerrainPlan p = planTerrain("dem.tif", 19201, 9601, o);
  EXPECT_FALSE(p.autoChartSize);
  EXPECT_FALSE(p.autoDepth);
  EXPECT_EQ(p.chartSize, 257u);
  EXPECT_EQ(p.depth, 3u);
  EXPECT_EQ(uint64_t(p.chartsX) * p.chartsY, 75u * 38u);
  o.depth = kAutoDepth;
  o.chartSize = 16385;
  EXPECT_EQ(planTerrain("dem.tif", 19201, 9601, o).depth, 10u);
  o.chartSize = 129;
  EXPECT_EQ(planTerrain("dem.tif", 19201, 9601, o).depth, 5u);
}

// A DEM of one sample, or one row, has no cell to draw: an error naming it, in the plan and in the
// build (which would otherwise write an atlas of no node).
TEST(TerrainPlan, ADemUnderTwoByTwoIsRefused) {
  TerrainBuildOptions o;
  EXPECT_THROW(planTerrain("dem.tif", 1, 1, o), InputError);
  EXPECT_THROW(planTerrain("dem.tif", 1000, 1, o), InputError);
  test::TempDir tmp("gimlod-tiny-dem");
  const fs::path f = tmp.path() / "one.tif";
  GDALAllRegister();
  GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GTiff"), f.c_str(), 1, 1, 1, GDT_Float32, nullptr);
  ASSERT_NE(ds, nullptr);
  double gt[6] = {500000, 10, 0, 5000000, 0, -10};
  GDALSetGeoTransform(ds, gt);
  float v = 12.5f;
  ASSERT_EQ(GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Write, 0, 0, 1, 1, &v, 1, 1, GDT_Float32, 0, 0), CE_None);
  GDALClose(ds);
  o.input = f;
  o.output = tmp.path() / "atlas";
  try {
    buildTerrainAtlas(o);
    FAIL() << "a 1 x 1 DEM built an atlas";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("one.tif"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("1 x 1"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output));
}

}  // namespace
}  // namespace gimlod

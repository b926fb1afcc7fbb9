// Tests for the height-field atlas: option validation, chart grid, pyramids, normals, and
// bit-identical seams between neighbouring charts written to disk.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "atlas/terrain/terrain_atlas.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

DemRaster planeDem(uint32_t w, uint32_t h, double a, double b, std::array<double, 2> spacing) {
  DemRaster d;
  d.width = w;
  d.height = h;
  d.spacing = spacing;
  d.heights.resize(size_t(w) * h);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) d.heights[size_t(y) * w + x] = float(a * x * spacing[0] + b * y * spacing[1]);
  d.minHeight = *std::min_element(d.heights.begin(), d.heights.end());
  d.maxHeight = *std::max_element(d.heights.begin(), d.heights.end());
  return d;
}

void expectOptionError(uint32_t cs, uint32_t bi, const std::string& what) {
  try {
    validateTerrainAtlasOptions({cs, bi, {}});
    FAIL() << "expected InputError for " << cs << "/" << bi;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(AtlasTerrain, OptionValidation) {
  EXPECT_NO_THROW(validateTerrainAtlasOptions({513, 64, {}}));
  EXPECT_NO_THROW(validateTerrainAtlasOptions({9, 8, {}}));
  EXPECT_NO_THROW(validateTerrainAtlasOptions({8193, 1024, {}}));
  EXPECT_NO_THROW(validateTerrainAtlasOptions({kMaxTerrainChartSize, 64, {}}));
  expectOptionError(500, 64, "chartSize 500 is not 2^m+1");
  expectOptionError(5, 4, "chartSize 5");
  expectOptionError(65537, 64, "chartSize 65537");
  expectOptionError(513, 48, "blockIntervals 48");
  expectOptionError(513, 2, "blockIntervals 2");
  expectOptionError(513, 2048, "blockIntervals 2048");
  expectOptionError(17, 32, "exceeds");
  EXPECT_EQ(chartFileName(7), "charts/chart_0007.bin");
  EXPECT_EQ(chartFileName(12345), "charts/chart_12345.bin");
}

TEST(AtlasTerrain, ExtractChartEdgeClamps) {
  DemRaster d = planeDem(20, 11, 1.0, 0.0, {1.0, 1.0});
  for (size_t i = 0; i < d.heights.size(); ++i) d.heights[i] = float(i);
  const auto c = extractChart(d, 2, 1, 9);  // covers x 16..24, y 8..16: mostly outside
  for (uint32_t v = 0; v < 9; ++v)
    for (uint32_t u = 0; u < 9; ++u) {
      const uint32_t gx = std::min(16 + u, 19u), gy = std::min(8 + v, 10u);
      EXPECT_EQ(c[v * 9 + u], d.heights[gy * 20 + gx]);
    }
}

TEST(AtlasTerrain, PyramidSubsamplesAndPlaneNormals) {
  // Plane z = 0.3 x - 0.2 y (metres), anisotropic spacing.
  const DemRaster d = planeDem(70, 40, 0.3, -0.2, {30.0, 20.0});
  const ChartPyramid p = buildChartPyramid(d, 0, 0, 33);
  ASSERT_EQ(p.heights.size(), 6u);
  const auto level0 = extractChart(d, 0, 0, 33);
  EXPECT_EQ(p.heights[0], level0);
  const float len = std::sqrt(0.3f * 0.3f + 0.2f * 0.2f + 1.f);
  for (uint32_t k = 0; k < 6; ++k) {
    const uint32_t s = (32 >> k) + 1;
    ASSERT_EQ(p.heights[k].size(), size_t(s) * s);
    for (uint32_t v = 0; v < s; ++v)
      for (uint32_t u = 0; u < s; ++u) {
        EXPECT_EQ(p.heights[k][v * s + u], level0[(v << k) * 33 + (u << k)]);
        const auto n = unpackNormal(p.normals[k][v * s + u]);
        EXPECT_NEAR(n[0], -0.3f / len, 0.01f);
        EXPECT_NEAR(n[1], 0.2f / len, 0.01f);
        EXPECT_NEAR(n[2], 1.f / len, 0.01f);
      }
  }
}

TEST(AtlasTerrain, SmallDemGridAndManifest) {
  test::TempDir tmp("gimlod-terrain");
  const DemRaster d = planeDem(40, 17, 0.1, 0.1, {10.0, 10.0});  // 39 x 16 intervals
  AtlasManifest m;
  const TerrainAtlasStats st = writeTerrainCharts(d, {17, 8, {}}, tmp.path(), m);
  EXPECT_EQ(m.chartsX, 3u);  // ceil(39 / 16)
  EXPECT_EQ(m.chartsY, 1u);
  EXPECT_EQ(st.charts, 3u);
  EXPECT_EQ(st.samples, 40u * 17u);
  EXPECT_EQ(st.storedSamples, 3u * (289 + 81 + 25 + 9 + 4));
  EXPECT_EQ(m.samplesX, 40u);
  EXPECT_EQ(m.chartSize, 17u);
  EXPECT_EQ(m.blockIntervals, 8u);
  EXPECT_LE(m.maxNodeResLog2, 3u);
  uint64_t onDisk = 0;
  for (const ChartInfo& c : m.charts) onDisk += fs::file_size(tmp.path() / c.file);
  EXPECT_EQ(st.bytesOnDisk, onDisk);
  EXPECT_EQ(m.charts[0].neighbours[kEdgeRight].chart, 1);
  EXPECT_EQ(m.charts[0].neighbours[kEdgeRight].edge, kEdgeLeft);
  EXPECT_EQ(m.charts[1].neighbours[kEdgeLeft].chart, 0);
  EXPECT_EQ(m.charts[1].neighbours[kEdgeLeft].edge, kEdgeRight);
  EXPECT_EQ(m.charts[2].neighbours[kEdgeRight].chart, -1);
  EXPECT_EQ(m.charts[1].neighbours[kEdgeTop].chart, -1);
  EXPECT_EQ(m.charts[1].neighbours[kEdgeBottom].chart, -1);
  m.source = "plane";
  writeManifest(tmp.path(), m);
  const AtlasManifest r = readManifest(tmp.path());  // validates neighbour symmetry
  EXPECT_EQ(r.charts.size(), 3u);
  EXPECT_THROW(writeTerrainCharts(d, {500, 64, {}}, tmp.path(), m), InputError);
}

// Shared side of two charts at one level: column u = s-1 of `a` vs u = 0 of `b` (horizontal
// neighbours), or row v = s-1 of `a` vs v = 0 of `b` (vertical).
template <typename T>
void expectSharedSideIdentical(const std::vector<T>& a, const std::vector<T>& b, uint32_t s, bool horizontal,
                               const char* what, uint32_t level) {
  for (uint32_t i = 0; i < s; ++i) {
    const size_t ia = horizontal ? size_t(i) * s + (s - 1) : size_t(s - 1) * s + i;
    const size_t ib = horizontal ? size_t(i) * s : i;
    ASSERT_EQ(0, std::memcmp(&a[ia], &b[ib], sizeof(T))) << what << " differ at level " << level << " index " << i;
  }
}

TEST(AtlasTerrain, RainierSeamsBitIdentical) {
  const DemRaster dem = loadDem(test::realData("terrain/mt_rainier_90m.tif"));
  test::TempDir tmp("gimlod-terrain");
  AtlasManifest m;
  const TerrainAtlasStats st = writeTerrainCharts(dem, {129, 32, {}}, tmp.path(), m);
  std::printf("[ timing   ] writeTerrainCharts(rainier, 129/32): %u charts, %.3f s, %.1f MB\n", st.charts, st.seconds,
              st.bytesOnDisk / 1e6);
  EXPECT_EQ(m.chartsX, 10u);  // ceil(1200 / 128)
  EXPECT_EQ(m.chartsY, 10u);
  EXPECT_EQ(m.voidsFilled, 9033u);
  writeManifest(tmp.path(), m);
  const AtlasManifest r = readManifest(tmp.path());

  // A chart in the middle, its right neighbour and its top neighbour; plus the last column
  // (partly outside the DEM, edge-clamped).
  const std::pair<uint32_t, uint32_t> pairs[] = {
      {4 * 10 + 4, 4 * 10 + 5}, {4 * 10 + 4, 5 * 10 + 4}, {9 * 10 + 8, 9 * 10 + 9}, {8 * 10 + 9, 9 * 10 + 9}};
  for (auto [ia, ib] : pairs) {
    const ChartInfo& ca = r.charts[ia];
    const bool horizontal = ca.neighbours[kEdgeRight].chart == int32_t(ib);
    ASSERT_TRUE(horizontal || ca.neighbours[kEdgeTop].chart == int32_t(ib));
    ChartFileReader fa(tmp.path() / ca.file), fb(tmp.path() / r.charts[ib].file);
    ASSERT_EQ(fa.levels(), 8u);
    for (uint32_t k = 0; k < fa.levels(); ++k) {
      const uint32_t s = (128 >> k) + 1;
      expectSharedSideIdentical(fa.readLevelHeights(k), fb.readLevelHeights(k), s, horizontal, "heights", k);
      expectSharedSideIdentical(fa.readLevelNormals(k), fb.readLevelNormals(k), s, horizontal, "normals", k);
    }
    // The files hold exactly what buildChartPyramid computes.
    const ChartPyramid p = buildChartPyramid(dem, ca.gridX, ca.gridY, 129);
    for (uint32_t k = 0; k < fa.levels(); ++k) {
      EXPECT_EQ(fa.readLevelHeights(k), p.heights[k]);
      EXPECT_EQ(fa.readLevelNormals(k), p.normals[k]);
    }
  }
}

}  // namespace
}  // namespace gimlod

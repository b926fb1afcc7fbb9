// Charts built in tiles (atlas/terrain/terrain_atlas.h ChartTiling): on the shipped SRTM tile
// upsampled, a tiled chart holds the samples and normals of the same chart built whole, at every
// level; the files do not depend on the order the tiles finish in; the build window by window
// writes the same files as the tiled build in memory; and the hierarchy read in tiles gives the
// nodes of the hierarchy read whole.
#include <gtest/gtest.h>

#include <cmath>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "atlas/terrain/terrain_windowed.h"
#include "core/block_codec.h"
#include "hierarchy/hierarchy.h"
#include "tests/test_util.h"
#include "tests/upsampled_tile.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// The tile twice upsampled (2401^2 samples, voids filled), as a compressed build quantizes it.
struct Fixture {
  test::TempDir tmp{"gimlod-tiles"};
  fs::path tile;
  DemRaster dem;
  Fixture() {
    tile = test::upsampledTile(tmp.path(), "200%");
    dem = loadDem(tile);
    for (float& h : dem.heights)
      if (h != std::nearbyint(h)) h = quantizeToStep(h, 1.0);
  }
  TerrainAtlasOptions options(uint32_t chartSize, bool compressed) const {
    TerrainAtlasOptions o;
    o.chartSize = chartSize;
    o.blockIntervals = 64;
    o.coding.compressed = compressed;
    o.coding.heightPrecision = 1.0;
    return o;
  }
  // The charts of `o`, built whole (tile 0) or in tiles of `tile` intervals, into dir.
  AtlasManifest build(const fs::path& dir, const TerrainAtlasOptions& o, uint32_t tileIntervals,
                      int concurrency = 2) const {
    fs::create_directories(dir / "charts");
    AtlasManifest m;
    if (tileIntervals == 0) {
      writeTerrainCharts(dem, o, dir, m);
    } else {
      fillTerrainManifest(dem, o, m);
      writeTiledCharts(dem, dir, m, o, chartTiling(o.chartSize, o.blockIntervals, tileIntervals), concurrency);
    }
    return m;
  }
};

void expectSameLevels(const fs::path& a, const fs::path& b) {
  const ChartFileReader ra(a), rb(b);
  ASSERT_EQ(ra.levels(), rb.levels());
  for (uint32_t k = 0; k < ra.levels(); ++k) {
    ASSERT_EQ(ra.readLevelHeights(k), rb.readLevelHeights(k)) << a << " level " << k;
    ASSERT_EQ(ra.readLevelNormals(k), rb.readLevelNormals(k)) << a << " level " << k;
  }
}

TEST(ChartTiling, TilesHoldTheLevelsWhoseBlocksFitThem) {
  const ChartTiling whole = chartTiling(513, 64, 2048);
  EXPECT_FALSE(whole.tiled());
  EXPECT_EQ(whole.coarseLevel, 10u);
  const ChartTiling t = chartTiling(16385, 64, 2048);
  EXPECT_TRUE(t.tiled());
  EXPECT_EQ(t.tilesPerSide, 8u);
  EXPECT_EQ(t.coarseLevel, 6u);  // level 5's blocks are 64 * 32 = 2048 level-0 intervals wide
  EXPECT_EQ(t.margin(), 32u);
  EXPECT_THROW(chartTiling(1025, 64, 64), std::invalid_argument);
}

TEST(ChartTiling, TiledChartsHoldTheWholeChartsSamples) {
  const Fixture f;
  for (const bool compressed : {true, false}) {
    const TerrainAtlasOptions o = f.options(1025, compressed);
    const fs::path whole = f.tmp.path() / (compressed ? "whole-c" : "whole"),
                   tiled = f.tmp.path() / (compressed ? "tiled-c" : "tiled");
    const AtlasManifest a = f.build(whole, o, 0);
    const AtlasManifest b = f.build(tiled, o, 256);
    ASSERT_EQ(a.charts.size(), 9u);
    ASSERT_EQ(b.charts.size(), a.charts.size());
    for (size_t i = 0; i < a.charts.size(); ++i) {
      expectSameLevels(whole / a.charts[i].file, tiled / b.charts[i].file);
      EXPECT_NE(test::fileBytes(whole / a.charts[i].file), test::fileBytes(tiled / b.charts[i].file));
    }
  }
}

TEST(ChartTiling, FilesDoNotDependOnTheOrderOfTheWork) {
  const Fixture f;
  const TerrainAtlasOptions o = f.options(1025, true);
  const AtlasManifest a = f.build(f.tmp.path() / "one", o, 256, 1);
  const AtlasManifest b = f.build(f.tmp.path() / "three", o, 256, 3);
  for (size_t i = 0; i < a.charts.size(); ++i)
    EXPECT_EQ(test::fileBytes(f.tmp.path() / "one" / a.charts[i].file),
              test::fileBytes(f.tmp.path() / "three" / b.charts[i].file))
        << a.charts[i].file;
}

// In 16 MiB the window of a 1025-sample chart and its neighbours' margins (3073^2 heights) does
// not fit: the charts are built in tiles of 512, whose coarse levels come from the DEM's lattice.
TEST(ChartTiling, WindowedTilesAreTheInMemoryTiles) {
  const Fixture f;
  const TerrainAtlasOptions o = f.options(1025, true);
  const AtlasManifest a = f.build(f.tmp.path() / "memory", o, 512);
  const DemSource source(f.tile);
  WindowedTerrainOptions wo;
  wo.atlas = o;
  wo.heightPrecision = 1.0;
  wo.memoryBytes = uint64_t{16} << 20;
  AtlasManifest b;
  fs::create_directories(f.tmp.path() / "windows");
  const WindowedTerrainResult r = writeTerrainChartsWindowed(source, f.tmp.path() / "windows", wo, b);
  EXPECT_LT(r.bandRows, 1025u);
  ASSERT_EQ(a.charts.size(), b.charts.size());
  for (size_t i = 0; i < a.charts.size(); ++i)
    EXPECT_EQ(test::fileBytes(f.tmp.path() / "memory" / a.charts[i].file),
              test::fileBytes(f.tmp.path() / "windows" / b.charts[i].file))
        << a.charts[i].file;
}

// The hierarchy of 1025-sample charts read in tiles of 128 (level 0 a tile at a time, and level 7
// for the coarse cells) against the same read whole: the same flags and bounds; the same errors,
// up to the rounding of a tile's border samples (which both tiles measure), for every node over the
// DEM's samples alone; and no larger ones for the nodes over the grid's padding, whose tiles past
// the DEM are not read.
TEST(ChartTiling, HierarchyReadInTilesIsTheWholeOne) {
  const Fixture f;
  const TerrainAtlasOptions o = f.options(1025, true);
  const fs::path dir = f.tmp.path() / "atlas";
  AtlasManifest m = f.build(dir, o, 0);
  m.depth = 6;
  m.maxNodeResLog2 = 6;
  m.minNodeResLog2 = 2;
  const ChartWindowSource source = [&](uint32_t c, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n) {
    return ChartFileReader(dir / m.charts[c].file).readHeightsWindow(level, u0, v0, n);
  };
  const Hierarchy whole = buildTerrainHierarchy(m, source, nullptr, 1024);
  const Hierarchy tiled = buildTerrainHierarchy(m, source, nullptr, 128);
  ASSERT_EQ(whole.chartCount(), tiled.chartCount());
  const HierarchyParams& p = whole.params;
  size_t inside = 0, padding = 0;
  for (uint32_t c = 0; c < whole.chartCount(); ++c) {
    const auto& a = whole.charts[c];
    const auto& b = tiled.charts[c];
    EXPECT_EQ(a.flags, b.flags) << "chart " << c;
    for (uint32_t l = 0; l < p.depth; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) {
          const uint32_t n = nodeIndex(l, x, y), size = 1024u >> l;
          if (a.flags[n] & kNodeEmpty) continue;
          EXPECT_EQ(a.bounds[n], b.bounds[n]) << "chart " << c << " node " << n;
          const bool overData = int64_t(m.charts[c].gridX) * 1024 + (x + 1) * size <= int64_t(m.samplesX) - 1 &&
                                int64_t(m.charts[c].gridY) * 1024 + (y + 1) * size <= int64_t(m.samplesY) - 1;
          for (uint32_t r = 0; r < p.resCount(); ++r) {
            const float ea = a.errors[size_t(n) * p.resCount() + r], eb = b.errors[size_t(n) * p.resCount() + r];
            if (std::isnan(ea)) {
              ASSERT_TRUE(std::isnan(eb)) << "chart " << c << " node " << n;
              continue;
            }
            if (overData) {
              ASSERT_NEAR(ea, eb, 1e-4f * std::max(1.0f, ea)) << "chart " << c << " node " << n;
              ++inside;
            } else {
              ASSERT_LE(eb, ea + 1e-4f * std::max(1.0f, ea)) << "chart " << c << " node " << n;
              ++padding;
            }
          }
        }
  }
  EXPECT_GT(inside, 4u * 1365u);  // the 4 charts wholly over data, every node at one resolution at least
  EXPECT_GT(padding, 0u);
}

}  // namespace
}  // namespace gimlod

// The terrain build window by window (atlas/terrain/terrain_windowed.h): on the shipped SRTM tile
// twice upsampled it writes byte for byte the chart files the in-memory build writes, compressed
// or not, with windows far smaller than the DEM. (The build under --max-memory through the
// command line: tests/cli/terrain_memory_cap_cli_test.cpp.)
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>

#include <gdal_priv.h>
#include <gdal_utils.h>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "atlas/terrain/terrain_windowed.h"
#include "core/block_codec.h"
#include "tests/test_util.h"
#include "tests/upsampled_tile.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using test::upsampledTile;

// The tile twice upsampled (2401^2 samples, voids and all): in 16 MiB the charts go in groups of
// 3 chart columns, and the void fill in windows of about 500^2.
void expectSameCharts(bool compressed) {
  test::TempDir tmp("gimlod-windowed");
  const fs::path tile = upsampledTile(tmp.path(), "200%");
  TerrainAtlasOptions atlas;
  atlas.chartSize = 257;
  atlas.blockIntervals = 64;
  atlas.coding.compressed = compressed;
  // In memory, as the build does it: filled, then quantized for a compressed atlas.
  DemRaster dem = loadDem(tile);
  // Whole metres, and voids filled with fractions: the scratch holds tiles of both kinds.
  ASSERT_GT(dem.voidsFilled, 0u);
  ASSERT_TRUE(dem.integerHeights);
  if (compressed) {
    atlas.coding.heightPrecision = 1.0;
    for (float& h : dem.heights)
      if (h != std::nearbyint(h)) h = quantizeToStep(h, 1.0);
    dem.minHeight = *std::min_element(dem.heights.begin(), dem.heights.end());
    dem.maxHeight = *std::max_element(dem.heights.begin(), dem.heights.end());
  }
  AtlasManifest a, b;
  fs::create_directories(tmp.path() / "memory");
  fs::create_directories(tmp.path() / "windows");
  writeTerrainCharts(dem, atlas, tmp.path() / "memory", a);
  const DemSource source(tile);
  WindowedTerrainOptions wo;
  wo.atlas = atlas;
  wo.memoryBytes = uint64_t{16} << 20;
  const WindowedTerrainResult r = writeTerrainChartsWindowed(source, tmp.path() / "windows", wo, b);
  EXPECT_EQ(r.heightPrecision, compressed ? 1.0 : 0.0);
  EXPECT_LT(r.bandColumns, dem.width);
  EXPECT_GT(r.scratchBytes, 0u);
  EXPECT_LT(r.scratchBytes, uint64_t(dem.width) * dem.height * 2);  // under 2 of the 5 raw bytes
  EXPECT_EQ(r.dem.voidsFilled, dem.voidsFilled);
  EXPECT_EQ(r.dem.minHeight, dem.minHeight);
  EXPECT_EQ(r.dem.maxHeight, dem.maxHeight);
  EXPECT_EQ(r.dem.integerHeights, dem.integerHeights);
  EXPECT_LT(r.bandRows, dem.height);
  ASSERT_EQ(a.charts.size(), b.charts.size());
  for (size_t i = 0; i < a.charts.size(); ++i)
    EXPECT_EQ(test::fileBytes(tmp.path() / "memory" / a.charts[i].file),
              test::fileBytes(tmp.path() / "windows" / b.charts[i].file))
        << a.charts[i].file;
  EXPECT_EQ(a.heightRange, b.heightRange);
  EXPECT_EQ(a.compression.present, b.compression.present);
  EXPECT_EQ(a.compression.heightPrecision, b.compression.heightPrecision);
  // The scratch raster is gone.
  for (const auto& e : fs::directory_iterator(tmp.path() / "windows"))
    EXPECT_EQ(e.path().filename().string().find("scratch"), std::string::npos) << e.path();
}

TEST(WindowedTerrain, ChartFilesAreThoseOfTheInMemoryBuild) { expectSameCharts(true); }
TEST(WindowedTerrain, UncompressedChartFilesAreThoseOfTheInMemoryBuild) { expectSameCharts(false); }

}  // namespace
}  // namespace gimlod

// Chart files opened on demand (runtime/page_reader.h): an atlas with more charts than files kept
// open reads every chart, never holds more than the limit open, and a reader still in use stays
// valid after it is closed for another.
#include <gtest/gtest.h>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "runtime/page_reader.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

TEST(ChartFileSet, MoreChartsThanOpenFiles) {
  test::TempDir tmp("gimlod-fileset");
  const DemRaster dem = loadDem(test::repoData() / "terrain/mt_rainier_90m.tif");
  AtlasManifest m;
  TerrainAtlasOptions o;
  o.chartSize = 129;
  o.blockIntervals = 32;
  writeTerrainCharts(dem, o, tmp.path(), m);
  ASSERT_GT(m.charts.size(), 50u);
  ChartFileSet set(4);
  for (const ChartInfo& c : m.charts) set.add(tmp.path() / c.file);
  const auto held = set.get(0);
  for (int pass = 0; pass < 2; ++pass)
    for (uint32_t i = 0; i < set.size(); ++i) {
      const auto r = set.get(i);
      EXPECT_EQ(r->readLevelHeights(0), ChartFileReader(tmp.path() / m.charts[i].file).readLevelHeights(0)) << i;
      EXPECT_LE(set.openFiles(), 4u);
    }
  // Closed for the others long ago, and still readable through the reader held.
  EXPECT_EQ(held->readLevelHeights(2), ChartFileReader(tmp.path() / m.charts[0].file).readLevelHeights(2));
}

}  // namespace
}  // namespace gimlod

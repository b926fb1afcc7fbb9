// Builds across processes (pipeline/sharded_build.h), in process: the split, the byte identity of
// the merged atlas with a one-process build whatever the number of shards, and the merge's
// refusals of missing, damaged and foreign shards.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <numeric>
#include <random>

#include "core/atlas_format.h"
#include "core/stage_meter.h"
#include "pipeline/build.h"
#include "pipeline/sharded_build.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// The least largest run of `work` cut into `n` contiguous runs, by trying every cut (small inputs).
double bestLargestRun(const std::vector<double>& work, uint32_t n, size_t from = 0) {
  double rest = 0.0;
  for (size_t i = from; i < work.size(); ++i) rest += work[i];
  if (n == 1 || from == work.size()) return rest;
  double best = rest, run = 0.0;
  for (size_t end = from; end < work.size(); ++end) {
    run += work[end];
    best = std::min(best, std::max(run, bestLargestRun(work, n - 1, end + 1)));
  }
  return best;
}

TEST(ShardSplit, ContiguousRunsCoverEveryChartOnceWithTheLeastLargestRun) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    const size_t charts = 1 + rng() % 12;
    const uint32_t n = 1 + rng() % 6;
    std::vector<double> work(charts);
    for (double& w : work) w = 1.0 + double(rng() % 100);
    std::vector<uint32_t> all;
    double largest = 0.0;
    uint32_t empty = 0;
    for (uint32_t i = 0; i < n; ++i) {
      const std::vector<uint32_t> mine = shardCharts(work, {i, n});
      ASSERT_EQ(mine, shardCharts(work, {i, n}));  // deterministic
      for (size_t k = 1; k < mine.size(); ++k) ASSERT_EQ(mine[k], mine[k - 1] + 1) << "not contiguous";
      if (!mine.empty()) {
        ASSERT_TRUE(all.empty() || mine.front() == all.back() + 1) << "runs out of order";
      }
      all.insert(all.end(), mine.begin(), mine.end());
      double sum = 0.0;
      for (uint32_t c : mine) sum += work[c];
      largest = std::max(largest, sum);
      empty += mine.empty();
    }
    std::vector<uint32_t> expected(charts);
    std::iota(expected.begin(), expected.end(), 0u);
    ASSERT_EQ(all, expected) << "trial " << trial;
    EXPECT_LE(largest, bestLargestRun(work, n) * (1.0 + 1e-9)) << "trial " << trial;
    EXPECT_EQ(empty, charts >= n ? 0u : n - uint32_t(charts)) << "trial " << trial;
  }
}

TEST(ShardSplit, ShardIdsAreParsedOrRefusedByName) {
  EXPECT_EQ(parseShardId("2/5").index, 2u);
  EXPECT_EQ(parseShardId("2/5").count, 5u);
  for (const char* bad : {"5/5", "1", "/3", "a/3", "1/0", "-1/3", "1/3x", "0/99999999"}) {
    try {
      parseShardId(bad);
      ADD_FAILURE() << bad << " was taken";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
}

TerrainBuildOptions tileOptions(const fs::path& output) {
  TerrainBuildOptions o;
  o.input = test::repoData() / "terrain/mt_rainier_90m.tif";
  o.output = output;
  o.chartSize = 129;  // 100 charts
  return o;
}

// prepare, every shard of n, merge.
ShardMergeStats buildSharded(const TerrainBuildOptions& o, uint32_t n) {
  prepareShards(o);
  for (uint32_t i = 0; i < n; ++i) buildShard(o, {i, n});
  return mergeShards(o.output);
}

TEST(ShardedBuild, TheShippedTileIsByteIdenticalForOneTwoThreeAndEightShards) {
  test::TempDir dir("gimlod-sharded");
  TerrainBuildOptions one = tileOptions(dir.path() / "one.atlas");
  buildTerrainAtlas(one);
  for (uint32_t n : {1u, 2u, 3u, 8u}) {
    SCOPED_TRACE(n);
    const TerrainBuildOptions o = tileOptions(dir.path() / (std::to_string(n) + "-shards.atlas"));
    const ShardMergeStats st = buildSharded(o, n);
    ASSERT_EQ(st.shards.size(), n);
    test::expectSameFiles(one.output, o.output, "stats.json");
    EXPECT_FALSE(fs::exists(shardArea(o.output))) << "the shard area stays after the merge";
    EXPECT_GE(st.balance, 1.0);
    EXPECT_EQ(readManifest(o.output).charts.size(), 100u);
  }
}

TEST(ShardedBuild, APlanetAndChartsBuiltInTilesAreByteIdentical) {
  test::TempDir dir("gimlod-sharded-planet");
  TerrainBuildOptions earth;
  earth.input = test::repoData() / "terrain/etopo_30min.tif";
  earth.planet = true;
  earth.chartSize = 65;
  earth.output = dir.path() / "one.atlas";
  buildTerrainAtlas(earth);
  earth.output = dir.path() / "sharded.atlas";
  buildSharded(earth, 3);
  test::expectSameFiles(dir.path() / "one.atlas", earth.output, "stats.json");
  // Charts of 513 in a memory cap that has them built in tiles (whose block order the files follow),
  // with the lattice of their coarse levels gathered across shards, against one process in the
  // same cap; a shard in another cap keeps the plan's tiles.
  // Each step's cap is the same headroom over what the process holds when it starts (that grows
  // and shrinks between steps), so the one process and the prepare choose the same tiles; freed
  // memory is handed back first, so that what the process holds does not fall after the cap is set.
  TerrainBuildOptions tiled = tileOptions(dir.path() / "tiled-one.atlas");
  const auto headroom = [&] {
    releaseFreedMemory();
    tiled.maxMemory = residentBytes() + (uint64_t{48} << 20);
  };
  tiled.chartSize = 513;
  tiled.outOfCore = true;
  headroom();
  const TerrainBuildStats oneProcess = buildTerrainAtlas(tiled);
  ASSERT_TRUE(oneProcess.write.windowed.has_value());
  EXPECT_LT(oneProcess.write.windowed->bandRows, 3u * 512u + 1u) << "the cap did not have the charts built in tiles";
  tiled.output = dir.path() / "tiled.atlas";
  tiled.outOfCore = false;
  headroom();
  prepareShards(tiled);
  const nlohmann::json plan = nlohmann::json::parse(std::ifstream(shardArea(tiled.output) / "plan.json"));
  EXPECT_LT(plan.at("chart_tile").get<uint32_t>(), 512u) << "the plan does not build the charts in tiles";
  headroom();
  buildShard(tiled, {0, 2});
  TerrainBuildOptions roomy = tiled;
  roomy.maxMemory = 0;
  buildShard(roomy, {1, 2});
  mergeShards(tiled.output);
  test::expectSameFiles(dir.path() / "tiled-one.atlas", tiled.output, "stats.json");
}

// The shipped tile with its imagery: each shard drapes its own charts up to their coarse level, the
// merge the levels above from every chart's coarse level, and the coverage from the lattice samples
// the shards' charts own; the atlas is one process's, file for file. A shard given other imagery
// options is refused.
TEST(ShardedBuild, ADrapedTileIsByteIdenticalForThreeAndEightShards) {
  test::TempDir dir("gimlod-sharded-imagery");
  const fs::path imagery = test::repoData() / "terrain/mt_rainier_imagery.tif";
  TerrainBuildOptions one = tileOptions(dir.path() / "one.atlas");
  one.imagery = imagery;
  one.imageryScaleLog2 = 0;  // on the DEM's lattice: 1201^2 samples
  buildTerrainAtlas(one);
  const AtlasManifest m = readManifest(one.output);
  ASSERT_TRUE(m.imagery.present);
  ASSERT_GT(m.imagery.coverage, 0.0);
  for (uint32_t n : {3u, 8u}) {
    SCOPED_TRACE(n);
    TerrainBuildOptions o = one;
    o.output = dir.path() / (std::to_string(n) + "-shards.atlas");
    const ShardMergeStats st = buildSharded(o, n);
    test::expectSameFiles(one.output, o.output, "stats.json");
    const nlohmann::json& im = st.stats.at("imagery");
    EXPECT_EQ(im.at("coverage").get<double>(), m.imagery.coverage);
    EXPECT_GT(im.at("bytes_on_disk").get<uint64_t>(), 0u);
  }
  // Other imagery than the plan's.
  TerrainBuildOptions o = one;
  o.output = dir.path() / "foreign.atlas";
  prepareShards(o);
  TerrainBuildOptions other = o;
  other.imageryScaleLog2 = 1;
  try {
    buildShard(other, {0, 2});
    ADD_FAILURE() << "a shard ran with another imagery scale";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("options.imagery_scale"), std::string::npos) << e.what();
  }
}

TEST(ShardedBuild, AMissingShardIsNamedAndRunAgainAloneGivesTheSameAtlas) {
  test::TempDir dir("gimlod-sharded-missing");
  TerrainBuildOptions one = tileOptions(dir.path() / "one.atlas");
  buildTerrainAtlas(one);
  const TerrainBuildOptions o = tileOptions(dir.path() / "sharded.atlas");
  prepareShards(o);
  buildShard(o, {0, 3});
  buildShard(o, {2, 3});
  // A shard killed while it ran leaves only its staging folder, of a process that is gone.
  fs::create_directories(shardArea(o.output) / ".shard-1-of-3.partial-999999999-1/charts");
  try {
    mergeShards(o.output, 3);
    ADD_FAILURE() << "merged without shard 1";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shard 1 of 3 is missing"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("shard 0 of 3"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output)) << "a refused merge wrote the atlas";
  buildShard(o, {1, 3});
  mergeShards(o.output);
  test::expectSameFiles(one.output, o.output, "stats.json");
}

TEST(ShardedBuild, ShardsOfAnotherInputOrOtherOptionsOrDamagedAreRefused) {
  test::TempDir dir("gimlod-sharded-foreign");
  const TerrainBuildOptions o = tileOptions(dir.path() / "a.atlas");
  prepareShards(o);
  // A shard given other options than the plan's refuses to run, naming them.
  TerrainBuildOptions scaled = o;
  scaled.zScale = 2.0;
  try {
    buildShard(scaled, {1, 3});
    ADD_FAILURE() << "a shard ran with another z-scale";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("options.z_scale"), std::string::npos) << e.what();
  }
  // A shard of another plan (another input's) put in its place is refused by the merge.
  TerrainBuildOptions other = tileOptions(dir.path() / "b.atlas");
  other.input = test::repoData() / "terrain/etopo_30min.tif";
  prepareShards(other);
  buildShard(other, {1, 3});
  buildShard(o, {0, 3});
  buildShard(o, {2, 3});
  fs::rename(shardArea(other.output) / "shard-1-of-3", shardArea(o.output) / "shard-1-of-3");
  try {
    mergeShards(o.output);
    ADD_FAILURE() << "merged a shard of another input";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shard 1 of 3 was built from another plan"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("input.path"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output));
  // A damaged chart file of a shard is named.
  fs::remove_all(shardArea(o.output) / "shard-1-of-3");
  buildShard(o, {1, 3});
  const fs::path chart = shardArea(o.output) / "shard-2-of-3" / readManifest(shardArea(o.output)).charts.back().file;
  {
    std::fstream f(chart, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(100);
    const char c = char(f.get() ^ 0xff);
    f.seekp(100);
    f.put(c);
  }
  try {
    mergeShards(o.output);
    ADD_FAILURE() << "merged a damaged shard";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shard 2 of 3 is damaged: " + chart.string()), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output));
  // Shards of two counts: the merge asks which.
  buildShard(o, {0, 2});
  try {
    mergeShards(o.output);
    ADD_FAILURE() << "merged with shards of two counts";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("2 different counts (2, 3)"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace gimlod

// `gimlod bench` end to end on the shipped DEM: the CSVs have every column and one row per frame
// per configuration, budgets hold, and bad options fail with a clear error. On the shipped scan:
// node budgets below the visible chart roots are reported.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

using test::Csv;
using test::readCsv;

class BenchCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("gimlod-bench");
    std::string output;
    const int rc = test::runCommand(test::appPath().string() + " build '" +
                                        (test::repoData() / "terrain/mt_rainier_90m.tif").string() + "' -o '" +
                                        atlas().string() + "'",
                                    &output);
    ASSERT_EQ(rc, 0) << output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path atlas() { return dir_->path() / "rainier.atlas"; }
  // Runs `gimlod bench ATLAS -o OUT ARGS`; returns the exit code and keeps the output.
  int bench(const fs::path& out, const std::string& args) {
    return test::runCommand(
        test::appPath().string() + " bench '" + atlas().string() + "' -o '" + out.string() + "' " + args, &output_);
  }

  static test::TempDir* dir_;
  std::string output_;
};
test::TempDir* BenchCliTest::dir_ = nullptr;

TEST_F(BenchCliTest, ErrorModeWritesEveryFrameOfEveryConfiguration) {
  const fs::path out = dir_->path() / "error";
  ASSERT_EQ(bench(out, "--orbit 4 --distance 0.5 --elevation 25 --nodes 60,300 --tolerance 1"), 0) << output_;
  EXPECT_NE(output_.find("adapt_us = "), std::string::npos) << output_;
  const Csv csv = readCsv(out / "bench.csv");
  for (const char* c : {"mode", "algorithm", "max_nodes", "max_triangles", "tolerance_px", "frame", "adapt_us", "nodes",
                        "triangles", "max_error_px", "mean_error_px", "splits", "merges", "refines", "coarsens",
                        "budget_bound", "constraint_splits"})
    EXPECT_NE(std::find(csv.header.begin(), csv.header.end(), c), csv.header.end()) << c;
  // 4 frames x 2 node budgets x 3 algorithms.
  ASSERT_EQ(csv.rows.size(), 24u);
  std::map<std::string, int> perAlgo;
  double adaptUs = 0.0;
  for (size_t i = 0; i < csv.rows.size(); ++i) {
    ASSERT_EQ(csv.rows[i].size(), csv.header.size()) << "row " << i;
    EXPECT_EQ(csv.rows[i][csv.col("mode")], "error");
    ++perAlgo[csv.rows[i][csv.col("algorithm")]];
    const double nodes = csv.num(i, "nodes"), maxNodes = csv.num(i, "max_nodes");
    // The stitching constraint may split past the budget; each such split adds at most 3 nodes.
    EXPECT_LE(nodes, maxNodes + 3 * csv.num(i, "constraint_splits")) << "row " << i;
    EXPECT_GT(nodes, 0) << "row " << i;
    EXPECT_TRUE(std::isfinite(csv.num(i, "adapt_us"))) << "row " << i;
    adaptUs += csv.num(i, "adapt_us");
    EXPECT_GE(csv.num(i, "max_error_px"), csv.num(i, "mean_error_px"));
    EXPECT_EQ(csv.num(i, "triangles") > 0, true);
  }
  EXPECT_GT(adaptUs, 0.0) << "the adapters' time was measured";
  EXPECT_EQ(perAlgo["ours"], 8);
  EXPECT_EQ(perAlgo["fixed"], 8);
  EXPECT_EQ(perAlgo["greedy"], 8);
  const Csv sum = readCsv(out / "summary.csv");
  EXPECT_EQ(sum.rows.size(), 6u);
  for (const char* c :
       {"adapt_us_mean", "nodes_mean", "triangles_mean", "max_error_px_p50", "max_error_px_p95", "max_error_px_max"})
    EXPECT_NE(std::find(sum.header.begin(), sum.header.end(), c), sum.header.end()) << c;
  EXPECT_TRUE(fs::exists(out / "cost_model.json"));
}

TEST_F(BenchCliTest, ShippedBenchPathRuns) {
  const fs::path out = dir_->path() / "path";
  ASSERT_EQ(bench(out, "--path '" + (test::repoData() / "../scenes/rainier_bench.json").string() +
                           "' --nodes 200 --algorithms ours"),
            0)
      << output_;
  EXPECT_EQ(readCsv(out / "bench.csv").rows.size(), 120u);
}

TEST_F(BenchCliTest, BudgetModeKeepsTheTriangleBudget) {
  const fs::path out = dir_->path() / "budget";
  const int rc = bench(out, "--mode budget --orbit 4 --distance 0.5 --nodes 60,300 --triangles 50000,200000");
  ASSERT_EQ(rc, 0) << output_;
  const Csv csv = readCsv(out / "bench.csv");
  ASSERT_EQ(csv.rows.size(), 4u * 4u * 3u);
  for (size_t i = 0; i < csv.rows.size(); ++i) {
    EXPECT_EQ(csv.rows[i][csv.col("mode")], "budget");
    EXPECT_LE(csv.num(i, "triangles"), csv.num(i, "max_triangles")) << "row " << i;
    EXPECT_LE(csv.num(i, "nodes"), csv.num(i, "max_nodes") + 3 * csv.num(i, "constraint_splits")) << "row " << i;
  }
}

// The frame-time controller on the cost model: it brings the modelled frame time to the target,
// and when the triangle rate halves it comes back to the target with about half the triangles.
TEST_F(BenchCliTest, FrameTimeControllerHoldsTheTargetThroughALoadStep) {
  const fs::path out = dir_->path() / "controller";
  // 20 ms at 10M triangles/s: about 200k triangles, far above the adaptation's own time.
  const int rc = bench(out,
                       "--mode budget --orbit 6 --distance 0.5 --nodes 500 --triangles 100000 --algorithms ours "
                       "--frame-ms 20 --tri-rate 1e7 --control-frames 160 --load-step 0.5");
  ASSERT_EQ(rc, 0) << output_;
  EXPECT_NE(output_.find("frame-time controller"), std::string::npos) << output_;
  const Csv csv = readCsv(out / "controller.csv");
  ASSERT_EQ(csv.rows.size(), 160u);
  const auto meanOver = [&](const std::string& col, size_t from, size_t to) {
    double sum = 0.0;
    for (size_t i = from; i < to; ++i) sum += csv.num(i, col);
    return sum / double(to - from);
  };
  EXPECT_NEAR(meanOver("frame_ms", 60, 80), 20.0, 2.0);    // settled before the step
  EXPECT_NEAR(meanOver("frame_ms", 140, 160), 20.0, 2.0);  // and again after it
  const double before = meanOver("triangles", 60, 80), after = meanOver("triangles", 140, 160);
  EXPECT_NEAR(after / before, 0.5, 0.1);
  EXPECT_LT(csv.num(0, "triangles"), before);  // it started below and grew
  const nlohmann::json cm = nlohmann::json::parse(std::ifstream(out / "cost_model.json"));
  EXPECT_GE(cm["controller"]["settling_frames_after_step"].get<int>(), 0);
  EXPECT_GT(cm["controller"]["peak_ms_after_step"].get<double>(), 20.0 * 1.3);  // the step did hit it
}

TEST_F(BenchCliTest, BadOptionsFailClearly) {
  const fs::path out = dir_->path() / "bad";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--orbit 2 --nodes ''", "--nodes"},
      {"--orbit 2 --nodes 100,0", "> 0"},
      {"--orbit 2 --nodes 100,,200", "empty"},
      {"--orbit 2 --nodes 100,abc", "not a positive integer"},
      {"--orbit 2 --mode fast", "--mode"},
      {"--orbit 2 --algorithms ours,roam", "unknown algorithm 'roam'"},
      {"--orbit 2 --tolerance 0", "--tolerance"},
      {"--orbit 2 --triangles 1000", "budget only"},
      {"--orbit 2 --size 12", "--size"},
      {"--orbit 2 --repeat 0", "--repeat"},
      {"--orbit 2 --frame-ms 16", "--tri-rate"},
      {"--orbit 2 --load-step 0", "--load-step"},
      {"--nodes 100", "one of --orbit N, --descent N and --path"},
      {"--orbit 2 --path nope.json", "one of --orbit N"},
      {"--orbit 2 --descent 5", "one of --orbit N"},
      {"--mode budget --orbit 2 --triangles 0", "> 0"},
  };
  for (const auto& [args, expect] : cases) {
    EXPECT_NE(bench(out, args), 0) << args;
    EXPECT_NE(output_.find(expect), std::string::npos) << args << "\n" << output_;
  }
  EXPECT_NE(test::runCommand(test::appPath().string() + " bench '" + (dir_->path() / "missing.atlas").string() +
                                 "' -o '" + out.string() + "' --orbit 2",
                             &output_),
            0);
  EXPECT_NE(output_.find("missing.atlas"), std::string::npos) << output_;
}

// Occurrences of `what` in `text`.
size_t countOf(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + what.size())) ++n;
  return n;
}

// A scan atlas has hundreds of charts, each a quadtree root, so a small node budget cannot hold:
// every row says so (root_floor, budget_below_roots), such frames draw exactly the visible roots,
// the others keep the budget, and the bench warns once.
TEST(BenchCliRootFloor, BudgetsBelowTheVisibleRootsAreReported) {
  test::TempDir dir("gimlod-bench-roots");
  const fs::path atlas = dir.path() / "bunny.atlas";
  std::string output;
  ASSERT_EQ(test::runCommand(test::appPath().string() + " build '" + test::realData("meshes/bun_zipper.ply").string() +
                                 "' -o '" + atlas.string() + "' --charts 24 --chart-size 17 --no-fidelity",
                             &output),
            0)
      << output;
  const uint32_t charts = uint32_t(nlohmann::json::parse(std::ifstream(atlas / "atlas.json"))["charts"].size());
  ASSERT_GT(charts, 20u);
  // From 3 bounding-box diagonals away every chart is in view: the floor is the chart count.
  const uint32_t low = charts / 8, justBelow = charts - 1, high = charts * 5;
  for (const std::string mode : {"budget", "error"}) {
    SCOPED_TRACE(mode);
    const fs::path out = dir.path() / mode;
    ASSERT_EQ(test::runCommand(test::appPath().string() + " bench '" + atlas.string() + "' -o '" + out.string() +
                                   "' --orbit 3 --distance 3 --max-roots 0 --mode " + mode +
                                   fmt::format(" --nodes {},{},{}", low, justBelow, high) +
                                   (mode == "budget" ? " --triangles 200000" : " --tolerance 0.5"),
                               &output),
              0)
        << output;
    const Csv csv = readCsv(out / "bench.csv");
    ASSERT_EQ(csv.rows.size(), 3u * 3u * 3u);
    std::map<std::string, int> perAlgo;
    for (size_t i = 0; i < csv.rows.size(); ++i) {
      ASSERT_EQ(csv.rows[i].size(), csv.header.size()) << "row " << i;
      ++perAlgo[csv.rows[i][csv.col("algorithm")]];
      const double maxNodes = csv.num(i, "max_nodes"), nodes = csv.num(i, "nodes");
      EXPECT_EQ(csv.num(i, "root_floor"), charts) << "row " << i;
      const bool below = maxNodes < charts;
      EXPECT_EQ(csv.num(i, "budget_below_roots"), below ? 1 : 0) << "row " << i;
      if (below) {
        EXPECT_EQ(nodes, charts) << "row " << i << ": the visible roots, unsplit";
        if (mode == "budget") {
          EXPECT_EQ(csv.num(i, "budget_bound"), 1) << "row " << i << ": at the node budget";
        }
      } else {
        EXPECT_LE(nodes, maxNodes) << "row " << i;
      }
    }
    EXPECT_EQ(perAlgo["ours"], 9);
    EXPECT_EQ(perAlgo["fixed"], 9);
    EXPECT_EQ(perAlgo["greedy"], 9);
    const Csv sum = readCsv(out / "summary.csv");
    ASSERT_EQ(sum.rows.size(), 9u);
    for (size_t i = 0; i < sum.rows.size(); ++i) {
      EXPECT_EQ(sum.num(i, "root_floor_max"), charts);
      EXPECT_EQ(sum.num(i, "budget_below_roots_frac"), sum.num(i, "max_nodes") < charts ? 1.0 : 0.0);
    }
    // One warning, for the first budget below the roots, naming it and the floor.
    EXPECT_EQ(countOf(output, "visible chart roots"), 1u) << output;
    EXPECT_NE(output.find(fmt::format("node budget {} is below the {} visible chart roots", low, charts)),
              std::string::npos)
        << output;
  }
  // A budget above the roots: no warning.
  ASSERT_EQ(test::runCommand(test::appPath().string() + " bench '" + atlas.string() + "' -o '" +
                                 (dir.path() / "above").string() + "' --orbit 2 --distance 3 --max-roots 0 " +
                                 fmt::format("--nodes {}", high),
                             &output),
            0)
      << output;
  EXPECT_EQ(countOf(output, "visible chart roots"), 0u) << output;
  EXPECT_EQ(readCsv(dir.path() / "above" / "bench.csv").num(0, "budget_below_roots"), 0);
  // The charts' roots in groups (the default): every algorithm holds budgets far below the chart
  // count, and no frame is below the floor.
  for (const std::string mode : {"budget", "error"}) {
    SCOPED_TRACE("grouped, " + mode);
    const fs::path out = dir.path() / ("grouped-" + mode);
    ASSERT_EQ(test::runCommand(test::appPath().string() + " bench '" + atlas.string() + "' -o '" + out.string() +
                                   "' --orbit 3 --distance 3 --mode " + mode + fmt::format(" --nodes {},{}", low, 16) +
                                   (mode == "budget" ? " --triangles 200000" : " --tolerance 0.5"),
                               &output),
              0)
        << output;
    EXPECT_EQ(countOf(output, "visible"), 0u) << output;
    const Csv csv = readCsv(out / "bench.csv");
    ASSERT_EQ(csv.rows.size(), 2u * 3u * 3u);
    for (size_t i = 0; i < csv.rows.size(); ++i) {
      EXPECT_LE(csv.num(i, "nodes"), csv.num(i, "max_nodes")) << "row " << i;
      EXPECT_LE(csv.num(i, "root_floor"), low) << "row " << i;
      EXPECT_EQ(csv.num(i, "budget_below_roots"), 0) << "row " << i;
    }
  }
}

}  // namespace
}  // namespace gimlod

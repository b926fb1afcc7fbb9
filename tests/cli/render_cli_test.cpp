// End to end through the command-line tool: build the shipped DEM, render an orbit and the
// shipped fly-by headless, and check the frames and per-frame statistics.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

std::vector<std::vector<std::string>> readCsv(const fs::path& p) {
  std::ifstream f(p);
  std::vector<std::vector<std::string>> rows;
  std::string line;
  while (std::getline(f, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    rows.push_back(cells);
  }
  return rows;
}

// Builds the shipped DEM at the defaults into DIR/rainier.atlas; gtest-fails on error.
fs::path buildShippedDem(const test::TempDir& dir, std::string* out) {
  const fs::path atlas = dir.path() / "rainier.atlas";
  EXPECT_EQ(
      test::runCommand(test::appPath().string() + " build '" +
                           (test::repoData() / "terrain/mt_rainier_90m.tif").string() + "' -o '" + atlas.string() + "'",
                       out),
      0)
      << *out;
  return atlas;
}

TEST(RenderCli, BuildAndRenderShippedDem) {
  test::TempDir dir("gimlod-render");
  const std::string app = test::appPath().string();
  std::string out;
  const fs::path atlas = buildShippedDem(dir, &out);
  ASSERT_FALSE(::testing::Test::HasFailure());
  const auto stats = nlohmann::json::parse(std::ifstream(atlas / "stats.json"));
  EXPECT_EQ(stats["charts"].get<int>(), 9);
  EXPECT_EQ(stats["voids_filled"].get<int>(), 9033);
  EXPECT_GT(stats["hierarchy_samples_per_second"].get<double>(), 0.0);
  EXPECT_GT(stats["bytes_on_disk"].get<double>(), 1e6);
  EXPECT_TRUE(fs::exists(atlas / "hierarchy.bin"));

  // Rebuilding over an existing atlas replaces it and leaves nothing staged behind.
  ASSERT_EQ(test::runCommand(app + " build '" + (test::repoData() / "terrain/mt_rainier_90m.tif").string() + "' -o '" +
                                 atlas.string() + "' --chart-size 257 --depth 4",
                             &out),
            0)
      << out;
  EXPECT_EQ(nlohmann::json::parse(std::ifstream(atlas / "stats.json"))["charts"].get<int>(), 25);
  for (const auto& e : fs::directory_iterator(dir.path()))
    EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();

  const double tolerance = 1.5;
  for (const std::string& camera :
       {std::string("--orbit 3"),
        "--path '" + (test::repoData().parent_path() / "scenes/rainier_flyby.json").string() + "'"}) {
    const fs::path frames = dir.path() / "frames";
    fs::remove_all(frames);
    ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + frames.string() + "' " + camera +
                                   " --size 96x64 --tolerance 1.5 --background 20,30,40",
                               &out),
              0)
        << out;
    const auto rows = readCsv(frames / "stats.csv");
    ASSERT_GE(rows.size(), 4u);
    size_t timed = 0;
    const auto& head = rows[0];
    auto col = [&](const std::string& name) {
      return size_t(std::find(head.begin(), head.end(), name) - head.begin());
    };
    for (const char* name : {"frame", "nodes", "triangles", "max_screen_error_px", "adapt_ms", "draw_ms", "gpu_ms"})
      ASSERT_LT(col(name), head.size()) << name;
    for (size_t r = 1; r < rows.size(); ++r) {
      char name[32];
      std::snprintf(name, sizeof(name), "frame_%04zu.png", r - 1);
      EXPECT_TRUE(fs::exists(frames / name)) << name;
      EXPECT_GT(std::stoul(rows[r][col("nodes")]), 0u);
      EXPECT_GT(std::stoull(rows[r][col("triangles")]), 0u);
      EXPECT_EQ(rows[r][col("pages_missing")], "0");
      if (rows[r][col("node_budget_bound")] == "0") {
        EXPECT_LE(std::stod(rows[r][col("max_screen_error_px")]), tolerance) << camera << " frame " << r - 1;
      }
      EXPECT_GT(std::stoull(rows[r][col("attribute_texels")]), 0u);
      // The GPU timer measured the draw: more than nothing, and not more than the wall time round it
      // (a driver's impossible value, llvmpipe's first, is written as nan).
      const double gpu = std::stod(rows[r][col("gpu_ms")]);
      if (!std::isnan(gpu)) {
        EXPECT_GT(gpu, 0.0);
        EXPECT_LE(gpu, std::stod(rows[r][col("draw_ms")]) + 0.001);
        ++timed;
      }
    }
    EXPECT_GE(timed, rows.size() - 2) << "GPU timer unknown on more than one frame";
  }

  // Triangle-budget mode (quad queue), multisampled: every frame within the budgets.
  const fs::path budget = dir.path() / "budget";
  ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + budget.string() +
                                 "' --orbit 3 --size 96x64 --triangles 30000 --max-nodes 60 --texel-ratio 2 --msaa 4",
                             &out),
            0)
      << out;
  const auto rows = readCsv(budget / "stats.csv");
  ASSERT_EQ(rows.size(), 4u);
  const auto& head = rows[0];
  auto col = [&](const std::string& name) { return size_t(std::find(head.begin(), head.end(), name) - head.begin()); };
  for (size_t r = 1; r < rows.size(); ++r) {
    EXPECT_LE(std::stoull(rows[r][col("triangles")]), 30000u);
    EXPECT_GT(std::stoull(rows[r][col("triangles")]), 10000u);
    EXPECT_LE(std::stoul(rows[r][col("nodes")]), 60u);
  }
  // Bad options name themselves.
  for (const char* bad : {"--texel-ratio -1", "--texel-ratio nan", "--triangles 1000 --top-down", "--geomorph -1",
                          "--msaa 0", "--msaa 64"}) {
    EXPECT_NE(test::runCommand(app + " render '" + atlas.string() + "' -o '" + (dir.path() / "bad").string() +
                                   "' --orbit 1 --size 32x32 " + bad,
                               &out),
              0)
        << bad;
    EXPECT_NE(out.find(std::string(bad).substr(0, std::string(bad).find(' '))), std::string::npos) << out;
  }
}

// The shipped DEM flown along the shipped fly-by with the loader under small byte budgets, a
// simulated slow disk and geomorphs: every frame complete, every cache within its budget. An orbit
// under a GPU cache below the roots' pages draws roots from their stand-ins, complete. Bad
// streaming options name themselves.
TEST(RenderCli, StreamingKeepsItsByteBudgets) {
  test::TempDir dir("gimlod-stream");
  const std::string app = test::appPath().string();
  std::string out;
  const fs::path atlas = buildShippedDem(dir, &out);
  ASSERT_FALSE(::testing::Test::HasFailure());
  const fs::path frames = dir.path() / "frames";
  const std::string path = (test::repoData().parent_path() / "scenes/rainier_flyby.json").string();
  ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + frames.string() + "' --path '" + path +
                                 "' --size 96x64 --gpu-cache 2M --ram-cache 1M --upload-budget 256K --io-latency 2,1 "
                                 "--loader-threads 2 --prefetch 0.5 --geomorph 0.5",
                             &out),
            0)
      << out;
  const auto rows = readCsv(frames / "stats.csv");
  ASSERT_GE(rows.size(), 4u);
  const auto& head = rows[0];
  auto col = [&](const std::string& name) { return size_t(std::find(head.begin(), head.end(), name) - head.begin()); };
  for (const char* name : {"resident_gpu_bytes", "gpu_budget_bytes", "resident_ram_bytes", "ram_budget_bytes",
                           "upload_bytes", "loads_issued", "loads_done", "loads_cancelled", "loads_failed",
                           "prefetch_requests", "pages_needed", "pages_resident", "incomplete"})
    ASSERT_LT(col(name), head.size()) << name;
  uint64_t issued = 0, done = 0;
  for (size_t r = 1; r < rows.size(); ++r) {
    const auto& row = rows[r];
    ASSERT_EQ(row.size(), head.size()) << "frame " << r - 1;
    EXPECT_LE(std::stoull(row[col("resident_gpu_bytes")]), std::stoull(row[col("gpu_budget_bytes")]));
    EXPECT_LE(std::stoull(row[col("gpu_budget_bytes")]), 2u << 20);
    EXPECT_LE(std::stoull(row[col("resident_ram_bytes")]), 1u << 20);
    EXPECT_EQ(std::stoull(row[col("ram_budget_bytes")]), 1u << 20);
    EXPECT_LE(std::stoull(row[col("pages_resident")]), std::stoull(row[col("pages_needed")]));
    EXPECT_EQ(row[col("incomplete")], "0") << "frame " << r - 1;
    EXPECT_EQ(row[col("pages_missing")], "0") << "frame " << r - 1;
    EXPECT_EQ(row[col("loads_failed")], "0") << "frame " << r - 1;
    issued += std::stoull(row[col("loads_issued")]);
    done += std::stoull(row[col("loads_done")]);
  }
  EXPECT_GT(issued, 0u);
  EXPECT_GT(done, 0u);
  // A GPU cache below the roots' pages: the roots are drawn from stand-ins, with the loader and
  // without, and every frame stays complete within the cache.
  // The orbit sees every chart, more roots than the pool's room for nodes.
  for (const std::string loader : {"", " --loader-threads 2 --io-latency 2,1"}) {
    const fs::path small = dir.path() / "small";
    ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + small.string() +
                                   "' --orbit 8 --size 96x64 --gpu-cache 400K" + loader,
                               &out),
              0)
        << out;
    EXPECT_NE(out.find("stand-in"), std::string::npos) << out;
    EXPECT_NE(out.find("the GPU page pool's room of"), std::string::npos) << out;
    const auto sr = readCsv(small / "stats.csv");
    ASSERT_GE(sr.size(), 4u);
    auto scol = [&](const std::string& name) {
      return size_t(std::find(sr[0].begin(), sr[0].end(), name) - sr[0].begin());
    };
    ASSERT_LT(scol("roots_on_stand_ins"), sr[0].size());
    uint64_t onStandIns = 0;
    for (size_t r = 1; r < sr.size(); ++r) {
      EXPECT_LE(std::stoull(sr[r][scol("resident_gpu_bytes")]), 400u << 10) << loader << " frame " << r - 1;
      EXPECT_EQ(sr[r][scol("incomplete")], "0") << loader << " frame " << r - 1;
      EXPECT_EQ(sr[r][scol("pages_missing")], "0") << loader << " frame " << r - 1;
      onStandIns += std::stoull(sr[r][scol("roots_on_stand_ins")]);
    }
    EXPECT_GT(onStandIns, 0u) << loader;
  }
  // Bad streaming options name themselves or what they cannot hold.
  for (const auto& [bad, named] :
       std::vector<std::pair<std::string, std::string>>{{"--gpu-cache 10K", "stand-ins"},
                                                        {"--ram-cache 2K", "loader's RAM"},
                                                        {"--ram-cache lots", "--ram-cache"},
                                                        {"--io-latency fast", "--io-latency"},
                                                        {"--io-latency 5,-1", "--io-latency"},
                                                        {"--prefetch -1", "--prefetch"},
                                                        {"--loader-threads 0", "--loader-threads"},
                                                        {"--io-depth 0", "--io-depth"}}) {
    EXPECT_NE(test::runCommand(app + " render '" + atlas.string() + "' -o '" + (dir.path() / "bad").string() +
                                   "' --orbit 1 --size 32x32 " + bad,
                               &out),
              0)
        << bad;
    EXPECT_NE(out.find(named), std::string::npos) << bad << ": " << out;
  }
}

// The shipped scan through the tool, as the demo runs it (smaller): build, then render the shipped
// orbit path; every frame drawn, no page missing, within tolerance unless the node budget bound.
TEST(RenderCli, BuildAndRenderShippedScan) {
  test::TempDir dir("gimlod-render-scan");
  const std::string app = test::appPath().string();
  const fs::path atlas = dir.path() / "bunny.atlas";
  std::string out;
  ASSERT_EQ(test::runCommand(app + " build '" + (test::repoData() / "meshes/bun_zipper.ply").string() + "' -o '" +
                                 atlas.string() + "' --charts 24 --chart-size 17",
                             &out),
            0)
      << out;
  const fs::path frames = dir.path() / "frames";
  ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + frames.string() + "' --path '" +
                                 (test::repoData().parent_path() / "scenes/bunny_orbit.json").string() +
                                 "' --size 48x36 --tolerance 2",
                             &out),
            0)
      << out;
  const auto rows = readCsv(frames / "stats.csv");
  ASSERT_EQ(rows.size(), 49u);
  const auto& head = rows[0];
  auto col = [&](const std::string& name) { return size_t(std::find(head.begin(), head.end(), name) - head.begin()); };
  for (size_t r = 1; r < rows.size(); ++r) {
    EXPECT_GT(std::stoull(rows[r][col("triangles")]), 0u);
    EXPECT_EQ(rows[r][col("pages_missing")], "0");
    if (rows[r][col("node_budget_bound")] == "0") {
      EXPECT_LE(std::stod(rows[r][col("max_screen_error_px")]), 2.0);
    }
  }
  EXPECT_TRUE(fs::exists(frames / "frame_0047.png"));
}

// A node budget below the scan's visible chart roots: every frame draws the roots, says so in
// stats.csv (root_floor, budget_below_roots), and the tool warns once, in both adaptation modes.
TEST(RenderCli, NodeBudgetBelowTheVisibleRootsIsReported) {
  test::TempDir dir("gimlod-render-roots");
  const std::string app = test::appPath().string();
  const fs::path atlas = dir.path() / "bunny.atlas";
  std::string out;
  ASSERT_EQ(test::runCommand(app + " build '" + (test::repoData() / "meshes/bun_zipper.ply").string() + "' -o '" +
                                 atlas.string() + "' --charts 24 --chart-size 17 --no-fidelity",
                             &out),
            0)
      << out;
  const size_t charts = nlohmann::json::parse(std::ifstream(atlas / "atlas.json"))["charts"].size();
  ASSERT_GT(charts, 16u);
  for (const std::string mode : {"", " --triangles 200000"}) {
    SCOPED_TRACE(mode);
    const fs::path frames = dir.path() / (mode.empty() ? "error" : "budget");
    // From 3 bounding-box diagonals away every chart is in view.
    ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + frames.string() +
                                   "' --orbit 3 --distance 3 --size 32x24 --max-nodes 16 --max-roots 0" + mode,
                               &out),
              0)
        << out;
    const std::string warning = "visible chart roots";
    size_t warnings = 0;
    for (size_t at = out.find(warning); at != std::string::npos; at = out.find(warning, at + 1)) ++warnings;
    EXPECT_EQ(warnings, 1u) << out;
    EXPECT_NE(out.find("--max-nodes 16 is below the " + std::to_string(charts) + " visible chart roots"),
              std::string::npos)
        << out;
    const auto rows = readCsv(frames / "stats.csv");
    ASSERT_EQ(rows.size(), 4u);
    const auto& head = rows[0];
    auto col = [&](const std::string& name) {
      return size_t(std::find(head.begin(), head.end(), name) - head.begin());
    };
    ASSERT_LT(col("root_floor"), head.size());
    ASSERT_LT(col("budget_below_roots"), head.size());
    for (size_t r = 1; r < rows.size(); ++r) {
      EXPECT_EQ(rows[r][col("root_floor")], std::to_string(charts));
      EXPECT_EQ(rows[r][col("budget_below_roots")], "1");
      EXPECT_EQ(rows[r][col("nodes")], std::to_string(charts));
    }
    // With the charts' roots in groups (the default), the same budget holds: closed groups are a
    // node each, and no frame is below the floor.
    const fs::path grouped = dir.path() / (mode.empty() ? "error-grouped" : "budget-grouped");
    ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + grouped.string() +
                                   "' --orbit 3 --distance 3 --size 32x24 --max-nodes 16" + mode,
                               &out),
              0)
        << out;
    EXPECT_EQ(out.find("visible"), std::string::npos) << out;
    const auto g = readCsv(grouped / "stats.csv");
    ASSERT_EQ(g.size(), 4u);
    const auto& gh = g[0];
    auto gcol = [&](const std::string& name) {
      const size_t c = size_t(std::find(gh.begin(), gh.end(), name) - gh.begin());
      EXPECT_LT(c, gh.size()) << name;
      return c;
    };
    for (size_t r = 1; r < g.size(); ++r) {
      EXPECT_LE(std::stoul(g[r][gcol("nodes")]), 16u);
      EXPECT_LE(std::stoul(g[r][gcol("root_floor")]), 16u);
      EXPECT_EQ(g[r][gcol("budget_below_roots")], "0");
      EXPECT_GT(std::stoul(g[r][gcol("closed_groups")]), 0u);
      EXPECT_GT(std::stoul(g[r][gcol("grouped_roots")]), std::stoul(g[r][gcol("closed_groups")]));
    }
  }
}

}  // namespace
}  // namespace gimlod

// `gimlod export --level 2` on every shared scan's default atlas (the one the pipeline's scan
// tests check, tests/scan_atlases.h): the PLY it writes reads back welded, with the scan's own open
// boundary loops and Euler characteristic, and no non-manifold edge.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "tests/mesh_topology.h"
#include "tests/scan_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

class ScanExportCli : public ::testing::TestWithParam<std::string> {};

TEST_P(ScanExportCli, LevelTwoReadsBackWithTheScansTopology) {
  const std::string name = GetParam();
  GIMLOD_NEED_SHARED_DATA(test::haveSharedScan(name));
  const test::BuiltScanAtlas* built = nullptr;
  ASSERT_NO_THROW(built = &test::scanAtlas(name, true)) << "gimlod build " << test::sharedScanPath(name);
  const test::Topology in = test::inputTopology(test::sharedScanPath(name));
  const fs::path ply = built->dir.parent_path() / (name + "_level2.ply");
  std::string out;
  ASSERT_EQ(
      test::runCommand(
          test::appPath().string() + " export " + built->dir.string() + " -o " + ply.string() + " --level 2", &out),
      0)
      << out;
  const test::Topology cli = test::inputTopology(ply);
  EXPECT_EQ(cli.boundaryLoops, in.boundaryLoops);
  EXPECT_EQ(cli.euler(), in.euler());
  EXPECT_EQ(cli.nonManifoldEdges, 0u);
  fs::remove(ply);
}

INSTANTIATE_TEST_SUITE_P(SharedScans, ScanExportCli, ::testing::ValuesIn(test::sharedScanNames()),
                         [](const ::testing::TestParamInfo<std::string>& i) { return i.param; });

}  // namespace
}  // namespace gimlod

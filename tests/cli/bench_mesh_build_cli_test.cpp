// bench_mesh_build end to end on the shipped scan: a meshoptimizer chain and a gimlod build of the
// same mesh, each its own process, reported stage by stage and side by side; bad options fail.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

#ifdef GIMLOD_BENCH_MESH_BUILD
// The summary row of `name`: its cells, trimmed.
std::vector<std::string> summaryRow(const std::string& output, const std::string& name) {
  std::istringstream in(output);
  std::vector<std::string> last;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("| " + name + " |", 0) != 0) continue;
    std::vector<std::string> cells;
    std::istringstream row(line.substr(1));
    for (std::string cell; std::getline(row, cell, '|');) {
      cell.erase(0, cell.find_first_not_of(' '));
      cell.erase(cell.find_last_not_of(' ') + 1);
      cells.push_back(cell);
    }
    last = cells;
  }
  return last;
}

TEST(BenchMeshBuild, ComparesWithTheBaselineOnTheShippedScan) {
  test::TempDir dir("gimlod-bench-mesh");
  std::string output;
  ASSERT_EQ(test::runCommand(std::string(GIMLOD_BENCH_MESH_BUILD) + " --work " + test::quoted(dir.path() / "work") +
                                 " --build-args '--chart-size 17 --charts 8 --quads kites --repair-rounds 0' " +
                                 test::quoted(test::realData("meshes/bun_zipper.ply")),
                             &output),
            0)
      << output;
  // The stage table, then the summary row with every column filled.
  EXPECT_NE(output.find("| resample |"), std::string::npos) << output;
  EXPECT_NE(output.find("| fidelity |"), std::string::npos) << output;
  const std::vector<std::string> row = summaryRow(output, "bun_zipper");
  ASSERT_EQ(row.size(), 16u) << output;
  EXPECT_EQ(row[1], "69451");  // the scan's triangles
  for (size_t c : {2u, 3u, 4u, 5u, 6u, 7u, 8u, 9u, 10u, 12u, 13u, 14u, 15u})
    EXPECT_GT(std::stod(row[c]), 0.0) << "column " << c;
  // The roots: the top groups above the charts (at most 16), never more than the charts.
  EXPECT_LE(std::stod(row[7]), std::min(std::stod(row[6]), 16.0));
  EXPECT_LT(std::stod(row[10]), 5.0);  // Hausdorff, in % of the diagonal
  // The baseline's codecs store the whole chain in well under 64 bytes per input triangle.
  EXPECT_LT(std::stod(row[14]), 64.0);
  // Nothing of the atlases is left in the work folder.
  for (const auto& e : fs::directory_iterator(dir.path() / "work"))
    EXPECT_NE(e.path().extension(), ".atlas") << e.path();
}

TEST(BenchMeshBuild, BadOptionsFailClearly) {
  std::string output;
  EXPECT_EQ(test::runCommand(std::string(GIMLOD_BENCH_MESH_BUILD) + " --cube-res 10", &output), 1);
  EXPECT_NE(output.find("--cube-res needs --dem"), std::string::npos) << output;
  EXPECT_EQ(test::runCommand(std::string(GIMLOD_BENCH_MESH_BUILD) + " /no/such/mesh.ply", &output), 1);
  EXPECT_NE(output.find("/no/such/mesh.ply"), std::string::npos) << output;
}
#endif

}  // namespace
}  // namespace gimlod

// `gimlod render --export-cut`: the cut as drawn, captured from the real vertex shader and welded,
// is watertight on the shipped scan and DEM (boundary edges only along the input's own holes and
// rims) and cracks without the stitching tables (the negative control); the PLY reads back with
// the counts the tool printed. With geomorphs too.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <regex>

#include "atlas/mesh/mesh_io.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

struct Exported {
  uint64_t vertices = 0, triangles = 0, boundary = 0, open = 0, elsewhere = 0;
};

Exported exportCut(const fs::path& atlas, const fs::path& ply, const std::string& view, bool stitch) {
  std::string out;
  const int rc = test::runCommand(test::appPath().string() + " render '" + atlas.string() + "' -o '" +
                                      (ply.parent_path() / "frames").string() + "' " + view + " --export-cut 0:'" +
                                      ply.string() + "'" + (stitch ? "" : " --no-stitch") + " 2>&1",
                                  &out);
  EXPECT_EQ(rc, 0) << out;
  std::smatch m;
  const std::regex line(
      R"((\d+) vertices, (\d+) triangles; (\d+) boundary edges, (\d+) on open chart borders, (\d+) elsewhere)");
  EXPECT_TRUE(std::regex_search(out, m, line)) << out;
  if (m.empty()) return {};
  return {std::stoull(m[1]), std::stoull(m[2]), std::stoull(m[3]), std::stoull(m[4]), std::stoull(m[5])};
}

// The PLY read back: the printed counts, and its own boundary edges counted here.
void expectFileMatches(const fs::path& ply, const Exported& e) {
  MeshReadOptions o;
  o.removeDuplicates = false;
  const IndexedMesh mesh = readMesh(ply, o);
  EXPECT_EQ(mesh.positions.size(), e.vertices);
  EXPECT_EQ(mesh.triangles.size(), e.triangles);
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ++uses[std::minmax(t[k], t[(k + 1) % 3])];
  uint64_t boundary = 0;
  for (const auto& [edge, n] : uses) boundary += n == 1;
  EXPECT_EQ(boundary, e.boundary);
}

TEST(ExportCut, ShippedScanIsWatertightButForItsHolesAndCracksWithoutStitching) {
  test::TempDir dir("gimlod-export-cut-scan");
  const std::string app = test::appPath().string();
  const fs::path atlas = dir.path() / "bunny.atlas";
  std::string out;
  ASSERT_EQ(test::runCommand(app + " build '" + (test::repoData() / "meshes/bun_zipper.ply").string() + "' -o '" +
                                 atlas.string() +
                                 "' --charts 24 --chart-size 33 --depth 3 --node-res 8 --min-node-res 2 "
                                 "--no-fidelity",
                             &out),
            0)
      << out;
  const std::string view = "--orbit 1 --size 160x120 --tolerance 0.3 --max-nodes 4000";
  const Exported s = exportCut(atlas, dir.path() / "cut.ply", view, true);
  EXPECT_GT(s.triangles, 0u);
  EXPECT_EQ(s.elsewhere, 0u) << "cracks in the stitched cut";
  EXPECT_GT(s.open, 0u) << "the bunny's holes";
  expectFileMatches(dir.path() / "cut.ply", s);
  const Exported n = exportCut(atlas, dir.path() / "cut_unstitched.ply", view, false);
  EXPECT_GT(n.elsewhere, 0u) << "without stitching, nodes of different resolutions must crack";
  expectFileMatches(dir.path() / "cut_unstitched.ply", n);
}

TEST(ExportCut, ShippedDemViewIsWatertightButForItsRimAndCracksWithoutStitching) {
  test::TempDir dir("gimlod-export-cut-dem");
  const std::string app = test::appPath().string();
  const fs::path atlas = dir.path() / "rainier.atlas";
  std::string out;
  ASSERT_EQ(test::runCommand(app + " build '" + (test::repoData() / "terrain/mt_rainier_90m.tif").string() + "' -o '" +
                                 atlas.string() + "' --chart-size 129 --depth 3 --node-res 32 --min-node-res 4",
                             &out),
            0)
      << out;
  const std::string view = "--orbit 1 --distance 1.6 --elevation 60 --size 160x120 --tolerance 0.3";
  const Exported s = exportCut(atlas, dir.path() / "cut.ply", view, true);
  EXPECT_EQ(s.elsewhere, 0u) << "cracks in the stitched cut";
  EXPECT_GT(s.open, 0u) << "the DEM's rim";
  expectFileMatches(dir.path() / "cut.ply", s);
  const Exported n = exportCut(atlas, dir.path() / "cut_unstitched.ply", view, false);
  EXPECT_GT(n.elsewhere, 0u);
  // With geomorphs the inner vertices move and the cut stays as watertight: the same welded mesh,
  // other positions.
  const auto bytes = [](const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(f)), {});
  };
  for (const char* range : {"0.5", "2"}) {
    const fs::path ply = dir.path() / (std::string("cut_geomorph_") + range + ".ply");
    const Exported g = exportCut(atlas, ply, view + " --geomorph " + range, true);
    EXPECT_EQ(g.elsewhere, 0u) << "cracks with --geomorph " << range;
    EXPECT_EQ(g.vertices, s.vertices) << range;
    EXPECT_EQ(g.triangles, s.triangles) << range;
    EXPECT_NE(bytes(ply), bytes(dir.path() / "cut.ply")) << "--geomorph " << range << " moved nothing";
  }
}

TEST(ExportCut, BadSpecsAreErrorsNamingTheOption) {
  test::TempDir dir("gimlod-export-cut-bad");
  const std::string app = test::appPath().string();
  const fs::path atlas = dir.path() / "rainier.atlas";
  ASSERT_EQ(test::runCommand(app + " build '" + (test::repoData() / "terrain/mt_rainier_90m.tif").string() + "' -o '" +
                             atlas.string() + "' --chart-size 129 --depth 2 --node-res 32"),
            0);
  for (const std::string spec : {"cut.ply", ":cut.ply", "x:cut.ply", "3:cut.ply", "0:"}) {
    std::string out;
    EXPECT_EQ(test::runCommand(app + " render '" + atlas.string() + "' -o '" + (dir.path() / "f").string() +
                                   "' --orbit 2 --size 32x24 --export-cut '" + spec + "' 2>&1",
                               &out),
              2)
        << spec;
    EXPECT_NE(out.find("--export-cut"), std::string::npos) << out;
  }
}

}  // namespace
}  // namespace gimlod

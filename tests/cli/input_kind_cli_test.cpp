// The build's command line on inputs whose name does not say their kind (pipeline/input_kind.h
// decides by content): a mesh named .dat builds, and an empty or unknown file is an error naming it.
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "core/atlas_format.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

class InputKindTest : public ::testing::Test {
 protected:
  fs::path write(const std::string& name, const std::string& bytes) { return dir_.write(name, bytes); }
  test::TempDir dir_{"gimlod-input-kind-cli"};
};

// The command line builds a mesh whose name does not say so, and names an empty or unknown file.
TEST_F(InputKindTest, CommandLine) {
  // An octahedron, as an ASCII PLY named .dat.
  const fs::path scan = write("scan.dat",
                              "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                              "property float z\nelement face 8\nproperty list uchar int vertex_indices\n"
                              "end_header\n1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n"
                              "3 0 2 4\n3 2 1 4\n3 1 3 4\n3 3 0 4\n3 2 0 5\n3 1 2 5\n3 3 1 5\n3 0 3 5\n");
  const auto build = [&](const fs::path& input, const std::string& args, std::string* out) {
    return test::runCommand(test::appPath().string() + " build '" + input.string() + "' -o '" +
                                (dir_.path() / "a.atlas").string() + "' " + args,
                            out);
  };
  std::string out;
  EXPECT_EQ(build(scan, "--charts 8 --chart-size 9 --depth 2 --no-fidelity", &out), 0) << out;
  const AtlasManifest m = readManifest(dir_.path() / "a.atlas");
  EXPECT_EQ(m.kind, AtlasKind::Geometry);
  fs::remove_all(dir_.path() / "a.atlas");

  const fs::path empty = write("nothing", "");
  EXPECT_EQ(build(empty, "", &out), 2) << out;
  EXPECT_NE(out.find(empty.string() + ": empty file"), std::string::npos) << out;
  const fs::path unknown = write("unknown", "neither a mesh nor a raster\n");
  EXPECT_EQ(build(unknown, "", &out), 2) << out;
  EXPECT_NE(out.find(unknown.string()), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir_.path() / "a.atlas"));
}

}  // namespace
}  // namespace gimlod

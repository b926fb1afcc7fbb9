// Input kind detection (pipeline/input_kind.h): by content, with the extension as a hint only
// where the content does not decide. (The command line on such inputs: tests/cli/input_kind_cli_test.cpp.)
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "core/atlas_format.h"
#include "pipeline/input_kind.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

class InputKindTest : public ::testing::Test {
 protected:
  fs::path write(const std::string& name, const std::string& bytes) { return dir_.write(name, bytes); }
  // A binary STL of n triangles: an 80-byte header starting with `header`, the count, 50 bytes each.
  static std::string binaryStl(uint32_t n, const std::string& header) {
    std::string s(80, ' ');
    std::memcpy(s.data(), header.data(), std::min<size_t>(header.size(), 80));
    for (int i = 0; i < 4; ++i) s += char((n >> (8 * i)) & 0xff);
    s += std::string(size_t(n) * 50, '\0');
    return s;
  }

  test::TempDir dir_{"gimlod-input-kind"};
};

const std::string kPly =
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
const std::string kOff = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
const std::string kAsciiStl =
    "solid t\n  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n"
    "      vertex 1 0 0\n      vertex 0 1 0\n    endloop\n  endfacet\nendsolid t\n";
const std::string kObj = "# a triangle\no t\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

TEST_F(InputKindTest, ByContentWithTheRightExtension) {
  EXPECT_EQ(detectInputKind(write("a.ply", kPly)), InputKind::Ply);
  EXPECT_EQ(detectInputKind(write("a.off", kOff)), InputKind::Off);
  EXPECT_EQ(detectInputKind(write("a.stl", kAsciiStl)), InputKind::Stl);
  EXPECT_EQ(detectInputKind(write("b.STL", binaryStl(3, "binary"))), InputKind::Stl);
  EXPECT_EQ(detectInputKind(write("a.obj", kObj)), InputKind::Obj);
  EXPECT_EQ(detectInputKind(test::repoData() / "terrain/mt_rainier_90m.tif"), InputKind::Raster);
  EXPECT_EQ(detectInputKind(test::repoData() / "meshes/bun_zipper.ply"), InputKind::Ply);
}

TEST_F(InputKindTest, ByContentWithAWrongOrMissingExtension) {
  EXPECT_EQ(detectInputKind(write("scan.dat", kPly)), InputKind::Ply);
  EXPECT_EQ(detectInputKind(write("scan", kPly)), InputKind::Ply);
  EXPECT_EQ(detectInputKind(write("scan.tif", kPly)), InputKind::Ply);
  EXPECT_EQ(detectInputKind(write("mesh", kOff)), InputKind::Off);
  EXPECT_EQ(detectInputKind(write("mesh.txt", "COFF\n3 1 0\n0 0 0 1 1 1 1\n")), InputKind::Off);
  EXPECT_EQ(detectInputKind(write("mesh.off.bak", "NOFF\n")), InputKind::Off);
  EXPECT_EQ(detectInputKind(write("part", kAsciiStl)), InputKind::Stl);
  EXPECT_EQ(detectInputKind(write("part.bin", binaryStl(2, "no magic"))), InputKind::Stl);
  // Many binary STL files start with "solid" too: the size decides.
  EXPECT_EQ(detectInputKind(write("part2.bin", binaryStl(5, "solid exported"))), InputKind::Stl);
  EXPECT_EQ(detectInputKind(write("mesh.txt", kObj)), InputKind::Obj);
  EXPECT_EQ(detectInputKind(write("mesh.obj.1", "\n  v 1 2 3\n")), InputKind::Obj);
}

TEST_F(InputKindTest, ExtensionDecidesWhereTheContentDoesNot) {
  // "solid" with no facet yet: an ASCII STL by its extension, else not a mesh.
  EXPECT_EQ(detectInputKind(write("s.stl", "solid name\n")), InputKind::Stl);
  EXPECT_EQ(detectInputKind(write("s.txt", "solid name\n")), InputKind::Raster);
  // A broken mesh keeps its extension's kind, so its reader names the problem.
  EXPECT_EQ(detectInputKind(write("broken.ply", "not a ply\n")), InputKind::Ply);
  // A file that is not there: the extension (the build then says "no such file").
  EXPECT_EQ(detectInputKind(dir_.path() / "missing.obj"), InputKind::Obj);
  EXPECT_EQ(detectInputKind(dir_.path() / "missing.tif"), InputKind::Raster);
}

TEST_F(InputKindTest, UnknownContentIsARaster) {
  EXPECT_EQ(detectInputKind(write("notes", "this is not a mesh\nvertices: none\n")), InputKind::Raster);
  EXPECT_EQ(detectInputKind(write("grid.asc", "ncols 4\nnrows 3\n")), InputKind::Raster);
  std::string binary(200, '\0');
  binary += "\nv 1 2 3\n";  // not text: not an OBJ
  EXPECT_EQ(detectInputKind(write("blob", binary)), InputKind::Raster);
}

TEST_F(InputKindTest, EmptyFileIsAnErrorNamingIt) {
  for (const std::string name : {"empty", "empty.ply", "empty.tif"}) {
    const fs::path p = write(name, "");
    try {
      detectInputKind(p);
      ADD_FAILURE() << name << ": expected InputError";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("empty"), std::string::npos) << e.what();
    }
  }
}

TEST_F(InputKindTest, Names) {
  EXPECT_STREQ(inputKindName(InputKind::Ply), "PLY");
  EXPECT_STREQ(inputKindName(InputKind::Raster), "raster");
  EXPECT_TRUE(isMesh(InputKind::Obj));
  EXPECT_FALSE(isMesh(InputKind::Raster));
}

}  // namespace
}  // namespace gimlod

// An atlas does not depend on the code paths glibc's libm picks for this CPU: each shipped input,
// built as it runs here and again with libm's AVX2, FMA and AVX-512 variants masked
// (GLIBC_TUNABLES), gives the same files byte for byte, all but stats.json (its timings). Before
// the mesh stage took its elementary functions from atlas/mesh/portable_math.h, 32 of the bunny's
// chart files, its manifest and its hierarchy differed between the two builds on an AVX-512 CPU.
// On a CPU without those extensions both builds take the same paths, and the test says so.
#include <gtest/gtest.h>

#include <fstream>
#include <iostream>
#include <ostream>
#include <string>

#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// Whether /proc/cpuinfo lists FMA or AVX2, whose libm variants the masked build does without.
bool cpuHasLibmVariants() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("flags", 0) == 0) {
      line += " ";
      return line.find(" fma ") != std::string::npos || line.find(" avx2 ") != std::string::npos;
    }
  return false;
}

struct PortableCase {
  const char* name;
  const char* input;    // under the repository's data/
  const char* imagery;  // under data/, or empty
  const char* options;
};

// The case's name in the test's output (not its bytes).
void PrintTo(const PortableCase& c, std::ostream* os) { *os << c.name; }

class PortableAtlas : public ::testing::TestWithParam<PortableCase> {};

TEST_P(PortableAtlas, TheSameWhicheverPathsLibmTakes) {
  const PortableCase& c = GetParam();
  const fs::path input = test::repoData() / c.input;
  ASSERT_TRUE(fs::exists(input)) << input;
  test::TempDir tmp("gimlod-portable");
  const fs::path plain = tmp.path() / "plain.atlas", masked = tmp.path() / "masked.atlas";
  const std::string imagery = *c.imagery ? " --imagery " + test::quoted(test::repoData() / c.imagery) : std::string();
  const std::string build =
      test::appPath().string() + " build " + test::quoted(input) + imagery + " " + c.options + " -o ";
  std::string output;
  ASSERT_EQ(test::runCommand(build + test::quoted(plain), &output), 0) << output;
  ASSERT_EQ(test::runCommand(
                "GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4,-AVX512F " + build + test::quoted(masked), &output),
            0)
      << output;
  std::cout << "  FMA or AVX2 on this CPU: "
            << (cpuHasLibmVariants() ? "yes (the masked build takes libm's other paths)"
                                     : "no (both builds take the same paths)")
            << "\n";
  test::expectSameFiles(plain, masked, "stats.json");
}

INSTANTIATE_TEST_SUITE_P(ShippedInputs, PortableAtlas,
                         ::testing::Values(PortableCase{"bunny", "meshes/bun_zipper.ply", "", ""},
                                           PortableCase{"rainier_with_imagery", "terrain/mt_rainier_90m.tif",
                                                        "terrain/mt_rainier_imagery.tif", ""},
                                           PortableCase{"planet", "terrain/etopo_30min.tif", "", "--planet"}),
                         [](const auto& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace gimlod

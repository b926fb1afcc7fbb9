// A mesh atlas does not depend on the code paths glibc's libm picks for this CPU: the shipped
// bunny, built as it runs here and again with libm's AVX2, FMA and AVX-512 variants masked
// (GLIBC_TUNABLES), gives the same files byte for byte, all but stats.json (its timings). Before
// the mesh stage took its elementary functions from atlas/mesh/portable_math.h, 32 of the bunny's
// chart files, its manifest and its hierarchy differed between the two builds on an AVX-512 CPU.
// On a CPU without those extensions both builds take the same paths, and the test says so.
#include <gtest/gtest.h>

#include <fstream>
#include <iostream>
#include <string>

#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// The CPU flags libm's variants follow, as /proc/cpuinfo lists them ("" where it cannot be read).
std::string cpuFlags() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("flags", 0) == 0) return line + " ";
  return {};
}

TEST(PortableMeshBuild, TheBunnyIsTheSameWhicheverPathsLibmTakes) {
  const fs::path bunny = test::repoData() / "meshes" / "bun_zipper.ply";
  ASSERT_TRUE(fs::exists(bunny)) << bunny;
  test::TempDir tmp("gimlod-portable-mesh");
  const fs::path plain = tmp.path() / "plain.atlas", masked = tmp.path() / "masked.atlas";
  const std::string build = test::appPath().string() + " build " + test::quoted(bunny) + " -o ";
  std::string output;
  ASSERT_EQ(test::runCommand(build + test::quoted(plain), &output), 0) << output;
  ASSERT_EQ(test::runCommand(
                "GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4,-AVX512F " + build + test::quoted(masked), &output),
            0)
      << output;
  const std::string flags = cpuFlags();
  const bool variants = flags.find(" fma ") != std::string::npos || flags.find(" avx2 ") != std::string::npos;
  std::cout << "  FMA or AVX2 on this CPU: "
            << (variants ? "yes (the masked build takes libm's other paths)" : "no (both builds take the same paths)")
            << "\n";
  test::expectSameFiles(plain, masked, "stats.json");
}

}  // namespace
}  // namespace gimlod

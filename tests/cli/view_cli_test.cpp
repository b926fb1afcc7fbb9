// `gimlod view`'s command line before any window opens (no display needed): bad options and
// files are named, and a missing display is a clear error, not a crash.
#include <gtest/gtest.h>

#include <string>
#include <utility>
#include <vector>

#include "tests/small_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

using test::quoted;

// Bad options are named before any window opens (no display needed).
TEST(ViewCli, BadOptionsAreNamed) {
  test::TempDir dir("gimlod-view-cli");
  test::buildSmallScanAtlas(dir.path() / "bunny.atlas", false);
  const std::string app = test::appPath().string() + " view ";
  const std::string atlas = quoted(dir.path() / "bunny.atlas");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {atlas + " --up w", "--up 'w'"},
      {atlas + " --frames 3", "--frames needs --path"},
      {atlas + " --size 4x4", "--size '4x4'"},
      {atlas + " --tolerance 0", "--tolerance"},
      {atlas + " --overlay plaid", "--overlay 'plaid'"},
      {atlas + " --path '" + (dir.path() / "none.json").string() + "'", "none.json"},
      {quoted(dir.path() / "missing.atlas"), "missing.atlas"}};
  for (const auto& [args, message] : cases) {
    std::string out;
    EXPECT_EQ(test::runCommand("env -u DISPLAY " + app + args, &out), 2) << args << "\n" << out;
    EXPECT_NE(out.find(message), std::string::npos) << args << "\n" << out;
  }
  // Without a display: a clear error, not a crash.
  std::string out;
  EXPECT_EQ(test::runCommand("env -u DISPLAY -u WAYLAND_DISPLAY " + app + atlas + " --exit-after 1", &out), 1) << out;
  EXPECT_NE(out.find("no display"), std::string::npos) << out;
}

}  // namespace
}  // namespace gimlod

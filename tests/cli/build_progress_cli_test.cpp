// `gimlod build` on a terminal (a pseudo-terminal from script(1)) redraws a progress bar; into a
// pipe it logs lines at the interval asked for (core/progress.h).
#include <gtest/gtest.h>

#include <string>

#include "tests/test_util.h"

namespace gimlod {
namespace {

// `gimlod build` on a terminal (a pseudo-terminal from script(1)) redraws a bar; into a pipe it logs
// lines at the interval asked for.
TEST(Progress, BuildShowsABarOnATerminalAndLinesOtherwise) {
  test::TempDir dir("gimlod-progress");
  const std::string dem = (test::repoData() / "terrain/mt_rainier_90m.tif").string();
  std::string out;
  ASSERT_EQ(test::runCommand("script -qec \"" + test::appPath().string() + " build '" + dem + "' -o '" +
                                 (dir.path() / "a.atlas").string() + "'\" /dev/null",
                             &out),
            0)
      << out;
  EXPECT_NE(out.find("\rcharts ["), std::string::npos) << out;
  EXPECT_NE(out.find("100% 9/9"), std::string::npos) << out;
  EXPECT_NE(out.find("hierarchy ["), std::string::npos) << out;
  ASSERT_EQ(test::runCommand("GIMLOD_PROGRESS_SECONDS=0 " + test::appPath().string() + " build '" + dem + "' -o '" +
                                 (dir.path() / "b.atlas").string() + "'",
                             &out),
            0)
      << out;
  EXPECT_EQ(out.find('\r'), std::string::npos) << out;
  EXPECT_NE(out.find("progress: charts"), std::string::npos) << out;
  EXPECT_NE(out.find("progress: read DEM"), std::string::npos) << out;
}

}  // namespace
}  // namespace gimlod

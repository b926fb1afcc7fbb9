// `gimlod build --planet` on the shipped global DEM: the atlas renders, exports as a closed
// surface, and the options that do not apply are refused by name.
#include <gtest/gtest.h>

#include <regex>
#include <utility>

#include "core/atlas_format.h"
#include "core/planet.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

TEST(PlanetCli, TheShippedGlobeBuildsRendersAndExportsClosed) {
  test::TempDir dir("gimlod-planet-cli");
  const std::string app = test::appPath().string();
  const fs::path dem = test::repoData() / "terrain/etopo_30min.tif";
  const fs::path atlas = dir.path() / "earth.atlas";
  std::string out;
  ASSERT_EQ(
      test::runCommand(app + " build " + test::quoted(dem) + " -o " + test::quoted(atlas) + " --planet 2>&1", &out), 0)
      << out;
  EXPECT_NE(out.find("columns round the planet"), std::string::npos) << out;
  ASSERT_EQ(test::runCommand(app + " export " + test::quoted(atlas) + " -o " + test::quoted(dir.path() / "earth.ply") +
                                 " --level 1 2>&1",
                             &out),
            0)
      << out;
  EXPECT_NE(out.find("; 0 boundary edges"), std::string::npos) << out;
  const fs::path frames = dir.path() / "frames";
  ASSERT_EQ(test::runCommand(app + " render " + test::quoted(atlas) + " -o " + test::quoted(frames) +
                                 " --orbit 3 --size 160x120 2>&1",
                             &out),
            0)
      << out;
  const test::Csv csv = test::readCsv(frames / "stats.csv");
  ASSERT_EQ(csv.rows.size(), 3u);
  for (size_t i = 0; i < csv.rows.size(); ++i) {
    EXPECT_GT(csv.num(i, "nodes"), 1.0);
    EXPECT_LE(csv.num(i, "max_screen_error_px"), 1.0);
  }
  // Under node and triangle budgets (the quad queue), along a flight from orbit to 100 m and back.
  const fs::path path = dir.path() / "flight.json", budget = dir.path() / "budget";
  ASSERT_EQ(test::runCommand("python3 " + test::quoted(test::repoData().parent_path() / "scripts/planet_flight.py") +
                                 " --lon 85.1 --lat 25.6 --ground 60 --frames 24 -o " + test::quoted(path) + " 2>&1",
                             &out),
            0)
      << out;
  ASSERT_EQ(test::runCommand(app + " render " + test::quoted(atlas) + " -o " + test::quoted(budget) + " --path " +
                                 test::quoted(path) + " --size 160x120 --triangles 6000 --max-nodes 24 2>&1",
                             &out),
            0)
      << out;
  const test::Csv b = test::readCsv(budget / "stats.csv");
  ASSERT_EQ(b.rows.size(), 24u);
  for (size_t i = 0; i < b.rows.size(); ++i) {
    EXPECT_LE(b.num(i, "triangles"), 6000.0) << i;
    EXPECT_LE(b.num(i, "nodes"), 24.0) << i;
    EXPECT_EQ(b.num(i, "incomplete"), 0.0) << i;
  }
}

TEST(PlanetCli, OptionsThatDoNotApplyAreRefused) {
  test::TempDir dir("gimlod-planet-cli-bad");
  const std::string app = test::appPath().string();
  std::string out;
  const std::string dem = test::quoted(test::repoData() / "terrain/etopo_30min.tif");
  EXPECT_NE(
      test::runCommand(app + " build " + dem + " -o " + test::quoted(dir.path() / "a") + " --radius 1000 2>&1", &out),
      0);
  EXPECT_NE(out.find("--radius needs --planet"), std::string::npos) << out;
  EXPECT_NE(test::runCommand(
                app + " build " + dem + " -o " + test::quoted(dir.path() / "b") + " --planet --radius -5 2>&1", &out),
            0);
  EXPECT_NE(out.find("--radius"), std::string::npos) << out;
  EXPECT_NE(test::runCommand(app + " build " + test::quoted(test::repoData() / "meshes/bun_zipper.ply") + " -o " +
                                 test::quoted(dir.path() / "c") + " --planet 2>&1",
                             &out),
            0);
  EXPECT_NE(out.find("--planet"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.path() / "c"));
  // The ellipsoid: known by name, on a planet only, and not with a radius of its own.
  const std::pair<const char*, const char*> ellipsoids[] = {
      {" --planet --ellipsoid Clarke1866", "unknown; give WGS84"},
      {" --ellipsoid WGS84", "--ellipsoid needs --planet"},
      {" --planet --ellipsoid WGS84 --radius 6378137", "give one"}};
  for (const auto& [options, message] : ellipsoids) {
    EXPECT_NE(
        test::runCommand(app + " build " + dem + " -o " + test::quoted(dir.path() / "e") + options + " 2>&1", &out), 0)
        << options;
    EXPECT_NE(out.find(message), std::string::npos) << options << ": " << out;
    EXPECT_FALSE(fs::exists(dir.path() / "e"));
  }
}

// --ellipsoid WGS84 (any case) builds the atlas on the ellipsoid, and says so.
TEST(PlanetCli, TheEllipsoidIsRecordedAndLogged) {
  test::TempDir dir("gimlod-planet-cli-wgs84");
  const std::string app = test::appPath().string();
  std::string out;
  const std::string dem = test::quoted(test::repoData() / "terrain/etopo_30min.tif");
  ASSERT_EQ(test::runCommand(app + " build " + dem + " -o " + test::quoted(dir.path() / "w") +
                                 " --planet --ellipsoid wgs84 --chart-size 129 2>&1",
                             &out),
            0)
      << out;
  EXPECT_NE(out.find("an ellipsoid of equatorial radius 6378137.0 m and flattening 1/298.257223563"), std::string::npos)
      << out;
  const AtlasManifest m = readManifest(dir.path() / "w");
  EXPECT_EQ(m.planet.radius, kEllipsoids[0].radius);
  EXPECT_EQ(m.planet.flattening, kEllipsoids[0].flattening);
}

}  // namespace
}  // namespace gimlod

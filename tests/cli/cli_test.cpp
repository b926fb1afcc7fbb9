// The command-line tool on bad input: each case gives a clear error naming the file or option,
// a non-zero exit, and no atlas (partial or otherwise) left behind.
#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>

#include "core/atlas_format.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

class CliTest : public ::testing::Test {
 protected:
  // Runs `gimlod build INPUT -o OUT ARGS`; returns the exit code and keeps the output.
  int build(const fs::path& input, const fs::path& out, const std::string& args = "") {
    return test::runCommand(
        test::appPath().string() + " build '" + input.string() + "' -o '" + out.string() + "' " + args, &output_);
  }
  // Nothing named like the atlas, staged or final, is left in dir.
  void expectNoAtlas(const fs::path& dir, const std::string& name) {
    EXPECT_FALSE(fs::exists(dir / name)) << output_;
    for (const auto& e : fs::directory_iterator(dir))
      EXPECT_EQ(e.path().filename().string().find(name + ".partial"), std::string::npos) << e.path();
  }
  fs::path writeFile(const std::string& name, const std::string& bytes) {
    const fs::path p = dir_.path() / name;
    std::ofstream(p, std::ios::binary) << bytes;
    return p;
  }
  fs::path dem() const { return test::repoData() / "terrain/mt_rainier_90m.tif"; }

  test::TempDir dir_{"gimlod-cli"};
  std::string output_;
};

TEST_F(CliTest, TruncatedGeoTiff) {
  std::ifstream in(dem(), std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 100000u);
  const fs::path cut = writeFile("truncated.tif", bytes.substr(0, bytes.size() / 3));
  EXPECT_NE(build(cut, dir_.path() / "a.atlas"), 0);
  EXPECT_NE(output_.find("truncated.tif"), std::string::npos) << output_;
  expectNoAtlas(dir_.path(), "a.atlas");
}

TEST_F(CliTest, NotARaster) {
  const fs::path p = writeFile("notes.tif", "this is not a raster, just some text\n");
  EXPECT_NE(build(p, dir_.path() / "a.atlas"), 0);
  EXPECT_NE(output_.find("notes.tif"), std::string::npos) << output_;
  expectNoAtlas(dir_.path(), "a.atlas");
}

TEST_F(CliTest, AllNodataRaster) {
  // An ESRI ASCII grid (read through GDAL) whose samples are all nodata.
  std::string grid = "ncols 4\nnrows 3\nxllcorner 0\nyllcorner 0\ncellsize 30\nNODATA_value -9999\n";
  for (int r = 0; r < 3; ++r) grid += "-9999 -9999 -9999 -9999\n";
  const fs::path p = writeFile("void.asc", grid);
  EXPECT_NE(build(p, dir_.path() / "a.atlas"), 0);
  EXPECT_NE(output_.find("void.asc"), std::string::npos) << output_;
  EXPECT_NE(output_.find("nodata"), std::string::npos) << output_;
  expectNoAtlas(dir_.path(), "a.atlas");
}

TEST_F(CliTest, NansAreFilledAndReported) {
  std::string grid = "ncols 9\nnrows 9\nxllcorner 0\nyllcorner 0\ncellsize 30\n";
  for (int r = 0; r < 9; ++r) {
    for (int c = 0; c < 9; ++c) grid += (r == 4 && c >= 3 && c <= 5) ? "nan " : std::to_string(100 + r + c) + ".5 ";
    grid += "\n";
  }
  const fs::path p = writeFile("nans.asc", grid);
  EXPECT_EQ(build(p, dir_.path() / "n.atlas", "--chart-size 9 --depth 2 --node-res 4 --min-node-res 2"), 0) << output_;
  EXPECT_NE(output_.find("voids filled      3"), std::string::npos) << output_;
  EXPECT_TRUE(fs::exists(dir_.path() / "n.atlas/atlas.json"));
}

TEST_F(CliTest, InvalidOptions) {
  for (const std::string args : {"--chart-size 500", "--chart-size 3", "--depth 0", "--depth 40", "--node-res 48",
                                 "--z-scale 0", "--min-node-res 128"}) {
    EXPECT_NE(build(dem(), dir_.path() / "a.atlas", args), 0) << args;
    const std::string opt = args.substr(0, args.find(' '));
    EXPECT_TRUE(output_.find(opt) != std::string::npos || output_.find("depth") != std::string::npos)
        << args << ": " << output_;
    expectNoAtlas(dir_.path(), "a.atlas");
  }
}

// Imagery options: each bad one is named, and nothing is left behind; a bad imagery file is named
// after the DEM was read (the build stops before writing an atlas).
TEST_F(CliTest, InvalidImageryOptions) {
  const std::string imagery = (test::repoData() / "terrain/mt_rainier_imagery.tif").string();
  const fs::path notImage = writeFile("not_an_image.tif", "no pixels here");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--imagery-scale 3 --imagery '" + imagery + "'", "--imagery-scale"},
      {"--imagery-scale 2", "need --imagery"},
      {"--imagery-extent=1,2,3,4", "need --imagery"},
      {"--imagery '" + imagery + "' --imagery-extent=10,0,-10,5", "--imagery-extent"},
      {"--imagery '" + (dir_.path() / "missing.tif").string() + "'", "missing.tif: no such file"},
      {"--imagery '" + notImage.string() + "'", "not_an_image.tif: not a raster"},
  };
  for (const auto& [args, expect] : cases) {
    EXPECT_NE(build(dem(), dir_.path() / "i.atlas", args), 0) << args;
    EXPECT_NE(output_.find(expect), std::string::npos) << args << ": " << output_;
    expectNoAtlas(dir_.path(), "i.atlas");
  }
  const fs::path bunny = test::repoData() / "meshes/bun_zipper.ply";
  EXPECT_NE(build(bunny, dir_.path() / "b.atlas", "--imagery '" + imagery + "'"), 0);
  EXPECT_NE(output_.find("--imagery drapes a raster over a DEM"), std::string::npos) << output_;
}

// The in-memory terrain build refuses a DEM over its memory cap before reading it, naming the
// file, the estimate and the option; within the cap it builds.
TEST_F(CliTest, DemBuildsWithinTheMemoryCapOrSaysWhyNot) {
  // A cap below what the program itself holds is refused before the DEM is read.
  EXPECT_NE(build(dem(), dir_.path() / "m.atlas", "--max-memory 4M"), 0);
  EXPECT_NE(output_.find("--max-memory 4 MiB is below"), std::string::npos) << output_;
  EXPECT_EQ(output_.find("voids filled"), std::string::npos) << output_;  // refused before the read
  expectNoAtlas(dir_.path(), "m.atlas");
  // Imagery window by window (in windows of a few charts under a small cap; under a sanitizer,
  // whose shadow memory the program holds, a larger cap and maybe one window): the imagery files
  // and the manifest are those of the in-memory build.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  const std::string cap = "1G";
  const uint64_t leastWindows = 1;
#else
  const std::string cap = "200M";
  const uint64_t leastWindows = 2;
#endif
  const std::string imagery = (test::repoData() / "terrain/mt_rainier_imagery.tif").string();
  ASSERT_EQ(build(dem(), dir_.path() / "im.atlas", "--imagery '" + imagery + "' --imagery-scale 1"), 0) << output_;
  ASSERT_EQ(build(dem(), dir_.path() / "iw.atlas",
                  "--imagery '" + imagery + "' --imagery-scale 1 --out-of-core --max-memory " + cap),
            0)
      << output_;
  const nlohmann::json iw = nlohmann::json::parse(std::ifstream(dir_.path() / "iw.atlas/stats.json"));
  ASSERT_TRUE(iw.contains("windowed"));
  EXPECT_GE(iw["imagery"]["windows"].get<uint64_t>(), leastWindows) << iw["imagery"];
  EXPECT_EQ(test::fileBytes(dir_.path() / "im.atlas/atlas.json"), test::fileBytes(dir_.path() / "iw.atlas/atlas.json"));
  const AtlasManifest im = readManifest(dir_.path() / "im.atlas");
  ASSERT_TRUE(im.imagery.present);
  for (const ChartInfo& c : im.charts)
    EXPECT_EQ(test::fileBytes(dir_.path() / "im.atlas" / c.imageryFile),
              test::fileBytes(dir_.path() / "iw.atlas" / c.imageryFile))
        << c.imageryFile;
  // The tile fits in memory; --out-of-core builds it window by window all the same.
  EXPECT_EQ(build(dem(), dir_.path() / "m.atlas", "--max-memory 1G"), 0) << output_;
  EXPECT_FALSE(nlohmann::json::parse(std::ifstream(dir_.path() / "m.atlas/stats.json")).contains("windowed"));
  EXPECT_EQ(build(dem(), dir_.path() / "w.atlas", "--max-memory 1G --out-of-core"), 0) << output_;
  EXPECT_TRUE(nlohmann::json::parse(std::ifstream(dir_.path() / "w.atlas/stats.json")).contains("windowed"));
  EXPECT_NE(output_.find("built window by window"), std::string::npos) << output_;
}

// Imagery on charts built in tiles (the shipped tile in one chart of 4097 samples, tiles of 2048
// intervals; the imagery at twice the DEM's lattice, tiles of 4096): the in-memory build and the
// window-by-window one write the same imagery, tile by tile, and the same manifest.
TEST_F(CliTest, ImageryOnTiledChartsIsTheSameInMemoryAndWindowByWindow) {
  const std::string imagery = (test::repoData() / "terrain/mt_rainier_imagery.tif").string();
  const std::string options = "--chart-size 4097 --imagery '" + imagery + "' --imagery-scale 2";
  ASSERT_EQ(build(dem(), dir_.path() / "im.atlas", options), 0) << output_;
  ASSERT_EQ(build(dem(), dir_.path() / "iw.atlas", options + " --out-of-core"), 0) << output_;
  const nlohmann::json im = nlohmann::json::parse(std::ifstream(dir_.path() / "im.atlas/stats.json"));
  EXPECT_FALSE(im.contains("windowed"));
  EXPECT_EQ(im["imagery"]["windows"].get<uint64_t>(), 4u) << im["imagery"];  // one chart, 2 x 2 tiles
  EXPECT_EQ(test::fileBytes(dir_.path() / "im.atlas/atlas.json"), test::fileBytes(dir_.path() / "iw.atlas/atlas.json"));
  const AtlasManifest m = readManifest(dir_.path() / "im.atlas");
  ASSERT_TRUE(m.imagery.present);
  ASSERT_EQ(m.charts.size(), 1u);
  EXPECT_EQ(m.imagery.chartSize(m.chartSize), 8193u);
  const fs::path file = dir_.path() / "im.atlas" / m.charts[0].imageryFile;
  EXPECT_EQ(test::fileBytes(file), test::fileBytes(dir_.path() / "iw.atlas" / m.charts[0].imageryFile));
  // Level 0 holds the reprojected colours inside the DEM (covered, and not one flat colour), and
  // past its last column (2400 on the imagery's lattice) the last column's, edge-clamped.
  const ChartFileReader reader(file);
  std::array<PackedColour, 81> inside, edge, past;
  reader.readColours(0, 1200, 1200, 8, inside.data());
  reader.readColours(0, 2392, 1200, 8, edge.data());
  reader.readColours(0, 4800, 1200, 8, past.data());
  EXPECT_EQ(inside[0][3], 255);
  EXPECT_EQ(inside[80][3], 255);
  EXPECT_NE(inside[0], inside[80]);
  for (int v = 0; v <= 8; ++v)
    for (int u = 0; u <= 8; ++u) EXPECT_EQ(past[size_t(v) * 9 + size_t(u)], edge[size_t(v) * 9 + 8]) << u << " " << v;
}

TEST_F(CliTest, UnwritableOutput) {
  EXPECT_NE(build(dem(), "/proc/gimlod_test.atlas"), 0);
  EXPECT_NE(output_.find("/proc/gimlod_test.atlas"), std::string::npos) << output_;
  const fs::path file = writeFile("plain.txt", "x");
  EXPECT_NE(build(dem(), file / "a.atlas"), 0);
  EXPECT_NE(output_.find("plain.txt"), std::string::npos) << output_;
  // An existing non-atlas directory is never replaced.
  fs::create_directories(dir_.path() / "mine");
  writeFile("mine/keep.txt", "precious");
  EXPECT_NE(build(dem(), dir_.path() / "mine"), 0);
  EXPECT_TRUE(fs::exists(dir_.path() / "mine/keep.txt"));
}

// An output in folders that do not exist yet is built there, the folders made (as `render -o`
// makes its folder): a fresh clone runs `build ... -o out/x.atlas` before out/ exists.
TEST_F(CliTest, MissingOutputFoldersAreMade) {
  const fs::path out = dir_.path() / "not" / "yet" / "rainier.atlas";
  ASSERT_EQ(build(dem(), out), 0) << output_;
  EXPECT_TRUE(fs::is_regular_file(out / "atlas.json")) << output_;
}

TEST_F(CliTest, MissingInputAndBadRenderOptions) {
  EXPECT_NE(build(dir_.path() / "nope.tif", dir_.path() / "a.atlas"), 0);
  EXPECT_NE(output_.find("nope.tif"), std::string::npos) << output_;
  const std::string app = test::appPath().string();
  EXPECT_NE(test::runCommand(app + " render '" + (dir_.path() / "missing.atlas").string() + "' -o '" +
                                 (dir_.path() / "out").string() + "' --orbit 1",
                             &output_),
            0);
  EXPECT_NE(output_.find("missing.atlas"), std::string::npos) << output_;
}

}  // namespace
}  // namespace gimlod

namespace gimlod {
namespace {

// A mesh end to end through the tool: build (charting, quads, resampling, hierarchy), stats,
// export of the welded surface, rendering, and bad mesh input.
TEST_F(CliTest, MeshBuildExportAndBadMeshes) {
  const fs::path atlas = dir_.path() / "bunny.atlas";
  ASSERT_EQ(build(test::realData("meshes/bun_zipper.ply"), atlas, "--charts 24 --chart-size 17"), 0) << output_;
  const std::string stats = [&] {
    std::ifstream f(atlas / "stats.json");
    return std::string((std::istreambuf_iterator<char>(f)), {});
  }();
  EXPECT_NE(stats.find("\"kind\": \"geometry\""), std::string::npos);
  EXPECT_NE(stats.find("\"triangles\": 69451"), std::string::npos) << stats.substr(0, 400);
  const fs::path ply = dir_.path() / "surface.ply";
  ASSERT_EQ(
      test::runCommand(
          test::appPath().string() + " export '" + atlas.string() + "' -o '" + ply.string() + "' --level 1", &output_),
      0)
      << output_;
  EXPECT_TRUE(fs::exists(ply));
  // The same renderer draws the mesh atlas (geometry pages).
  EXPECT_EQ(test::runCommand(test::appPath().string() + " render '" + atlas.string() + "' -o '" +
                                 (dir_.path() / "frames").string() + "' --orbit 1 --size 32x32",
                             &output_),
            0)
      << output_;
  EXPECT_TRUE(fs::exists(dir_.path() / "frames" / "frame_0000.png"));
  EXPECT_NE(
      test::runCommand(
          test::appPath().string() + " export '" + atlas.string() + "' -o '" + ply.string() + "' --level 9", &output_),
      0);
  // Bad meshes: nothing left behind.
  const fs::path empty = writeFile("empty.ply", "");
  EXPECT_NE(build(empty, dir_.path() / "e.atlas"), 0);
  EXPECT_NE(output_.find("empty.ply"), std::string::npos) << output_;
  expectNoAtlas(dir_.path(), "e.atlas");
  const fs::path past = writeFile("past.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n");
  EXPECT_NE(build(past, dir_.path() / "p.atlas"), 0);
  EXPECT_NE(output_.find("past.obj"), std::string::npos) << output_;
  expectNoAtlas(dir_.path(), "p.atlas");
  EXPECT_NE(build(test::realData("meshes/bun_zipper.ply"), dir_.path() / "c.atlas", "--chart-size 16"), 0);
  EXPECT_NE(output_.find("--chart-size"), std::string::npos) << output_;
  EXPECT_NE(build(test::realData("meshes/bun_zipper.ply"), dir_.path() / "m.atlas", "--max-memory 12Q"), 0);
  EXPECT_NE(output_.find("--max-memory"), std::string::npos) << output_;
  expectNoAtlas(dir_.path(), "m.atlas");
  EXPECT_NE(build(test::realData("meshes/bun_zipper.ply"), dir_.path() / "d.atlas", "--chart-metric curved"), 0);
  EXPECT_NE(output_.find("--chart-metric"), std::string::npos) << output_;
  expectNoAtlas(dir_.path(), "d.atlas");
}

}  // namespace
}  // namespace gimlod

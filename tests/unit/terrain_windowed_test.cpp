// The terrain build window by window (atlas/terrain/terrain_windowed.h): on the shipped SRTM tile
// twice upsampled it writes byte for byte the chart files the in-memory build writes, compressed
// or not, with windows far smaller than the DEM; and `gimlod build` of a DEM several times larger than a small
// --max-memory (the tile upsampled by a GDAL VRT, voids and all) stays under the cap, measured
// from the child's own peak resident set.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>

#include <gdal_priv.h>
#include <gdal_utils.h>
#include <nlohmann/json.hpp>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "atlas/terrain/terrain_windowed.h"
#include "core/block_codec.h"
#include "tests/test_util.h"

extern char** environ;

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// The shipped tile upsampled by a GDAL VRT (bilinear, whole metres; its voids come through as
// nodata).
fs::path upsampledTile(const fs::path& dir, const char* scale) {
  const fs::path tile = test::repoData() / "terrain/mt_rainier_90m.tif";
  const fs::path vrt = dir / "upsampled.vrt";
  GDALAllRegister();
  GDALDatasetH src = GDALOpen(tile.c_str(), GA_ReadOnly);
  if (!src) throw std::runtime_error("cannot open " + tile.string());
  const char* argv[] = {"-q", "-of", "VRT", "-outsize", scale, scale, "-r", "bilinear", nullptr};
  GDALTranslateOptions* opts = GDALTranslateOptionsNew(const_cast<char**>(argv), nullptr);
  GDALDatasetH out = GDALTranslate(vrt.c_str(), src, opts, nullptr);
  GDALTranslateOptionsFree(opts);
  if (out) GDALClose(out);  // before its source, which it refers to
  GDALClose(src);
  if (!out) throw std::runtime_error("cannot write " + vrt.string());
  return vrt;
}

// The tile twice upsampled (2401^2 samples, voids and all): in 16 MiB the charts go in groups of
// 3 chart columns, and the void fill in windows of about 500^2.
void expectSameCharts(bool compressed) {
  test::TempDir tmp("gimlod-windowed");
  const fs::path tile = upsampledTile(tmp.path(), "200%");
  TerrainAtlasOptions atlas;
  atlas.chartSize = 257;
  atlas.blockIntervals = 64;
  atlas.coding.compressed = compressed;
  // In memory, as the build does it: filled, then quantized for a compressed atlas.
  DemRaster dem = loadDem(tile);
  // Whole metres, and voids filled with fractions: the scratch holds tiles of both kinds.
  ASSERT_GT(dem.voidsFilled, 0u);
  ASSERT_TRUE(dem.integerHeights);
  if (compressed) {
    atlas.coding.heightPrecision = 1.0;
    for (float& h : dem.heights)
      if (h != std::nearbyint(h)) h = quantizeToStep(h, 1.0);
    dem.minHeight = *std::min_element(dem.heights.begin(), dem.heights.end());
    dem.maxHeight = *std::max_element(dem.heights.begin(), dem.heights.end());
  }
  AtlasManifest a, b;
  fs::create_directories(tmp.path() / "memory");
  fs::create_directories(tmp.path() / "windows");
  writeTerrainCharts(dem, atlas, tmp.path() / "memory", a);
  const DemSource source(tile);
  WindowedTerrainOptions wo;
  wo.atlas = atlas;
  wo.memoryBytes = uint64_t{16} << 20;
  const WindowedTerrainResult r = writeTerrainChartsWindowed(source, tmp.path() / "windows", wo, b);
  EXPECT_EQ(r.heightPrecision, compressed ? 1.0 : 0.0);
  EXPECT_LT(r.bandColumns, dem.width);
  EXPECT_GT(r.scratchBytes, 0u);
  EXPECT_LT(r.scratchBytes, uint64_t(dem.width) * dem.height * 2);  // under 2 of the 5 raw bytes
  EXPECT_EQ(r.dem.voidsFilled, dem.voidsFilled);
  EXPECT_EQ(r.dem.minHeight, dem.minHeight);
  EXPECT_EQ(r.dem.maxHeight, dem.maxHeight);
  EXPECT_EQ(r.dem.integerHeights, dem.integerHeights);
  EXPECT_LT(r.bandRows, dem.height);
  ASSERT_EQ(a.charts.size(), b.charts.size());
  for (size_t i = 0; i < a.charts.size(); ++i)
    EXPECT_EQ(test::fileBytes(tmp.path() / "memory" / a.charts[i].file), test::fileBytes(tmp.path() / "windows" / b.charts[i].file))
        << a.charts[i].file;
  EXPECT_EQ(a.heightRange, b.heightRange);
  EXPECT_EQ(a.compression.present, b.compression.present);
  EXPECT_EQ(a.compression.heightPrecision, b.compression.heightPrecision);
  // The scratch raster is gone.
  for (const auto& e : fs::directory_iterator(tmp.path() / "windows"))
    EXPECT_EQ(e.path().filename().string().find("scratch"), std::string::npos) << e.path();
}

TEST(WindowedTerrain, ChartFilesAreThoseOfTheInMemoryBuild) { expectSameCharts(true); }
TEST(WindowedTerrain, UncompressedChartFilesAreThoseOfTheInMemoryBuild) { expectSameCharts(false); }

// Runs the app with args; returns its exit status and its own peak resident set (KiB).
int runApp(const std::vector<std::string>& args, long* maxRssKib) {
  std::vector<std::string> all{test::appPath().string()};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ) != 0) return -1;
  int status = 0;
  rusage usage{};
  if (wait4(pid, &status, 0, &usage) != pid) return -1;
  *maxRssKib = usage.ru_maxrss;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(WindowedTerrain, ADemSeveralTimesTheMemoryCapBuildsUnderIt) {
  test::TempDir tmp("gimlod-memcap");
  // The tile upsampled 8 times by a VRT (92M samples; its voids come through as nodata). Under a
  // sanitizer (whose shadow memory the cap does not cover) 4 times, and the cap is not checked.
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  const char* scale = "400%";
  constexpr bool kCheckCap = false;
  const std::string cap = "1G";
#else
  const char* scale = "800%";
  constexpr bool kCheckCap = true;
  const std::string cap = "256M";
#endif
  const fs::path vrt = upsampledTile(tmp.path(), scale);
  const DemSource source(vrt);
  const double samples = double(source.info().width) * source.info().height;
  constexpr uint64_t kCap = uint64_t{256} << 20;
  // The in-memory build of it would need several times the cap.
  if (kCheckCap) {
    EXPECT_GT(samples * 17.0, 3.0 * double(kCap));
  }
  long rssKib = 0;
  const fs::path atlas = tmp.path() / "atlas";
  // Over the cap, the build goes window by window by itself (under a sanitizer it is told to).
  std::vector<std::string> args{"build", vrt.string(), "-o", atlas.string(), "--max-memory", cap, "--chart-size", "257"};
  if (!kCheckCap) args.push_back("--out-of-core");
  ASSERT_EQ(runApp(args, &rssKib), 0);
  const nlohmann::json st = nlohmann::json::parse(std::ifstream(atlas / "stats.json"));
  // The child's own peak (VmHWM, which exec resets; wait4's figure can carry the spawning test
  // process's peak over when other tests ran in it first), and the larger wait4 figure beside it.
  const uint64_t peak = st.at("peak_rss_bytes").get<uint64_t>();
  std::printf("  %.0f samples under a %s cap: peak RSS %.1f MiB (wait4: %.1f MiB)\n", samples, cap.c_str(),
              double(peak) / 1048576.0, double(rssKib) / 1024.0);
  EXPECT_GT(peak, uint64_t{32} << 20);
  EXPECT_LE(peak, uint64_t(rssKib) * 1024);
  if (kCheckCap) {
    EXPECT_LT(peak, kCap);
  }
  ASSERT_TRUE(st.contains("windowed")) << st.dump();
  // In chart columns narrower than the DEM (under the small cap), from a scratch raster under 2
  // of the 5 raw bytes.
  if (kCheckCap) {
    EXPECT_LT(st["windowed"]["band_columns"].get<double>(), double(source.info().width));
  }
  EXPECT_LT(st["windowed"]["scratch_bytes"].get<double>(), 2.0 * samples);
  EXPECT_GT(st["voids_filled"].get<uint64_t>(), 0u);
  EXPECT_EQ(st["samples"].get<double>(), samples);
  const AtlasManifest m = readManifest(atlas);
  EXPECT_EQ(m.samplesX, source.info().width);
  EXPECT_TRUE(m.compression.present);
}

}  // namespace
}  // namespace gimlod

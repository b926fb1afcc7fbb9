// `gimlod build` of a DEM several times larger than a small --max-memory (the shipped tile
// upsampled by a GDAL VRT, voids and all) stays under the cap, measured from the child's own peak
// resident set.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include "atlas/terrain/terrain_windowed.h"
#include "core/atlas_format.h"
#include "tests/test_util.h"
#include "tests/upsampled_tile.h"

extern char** environ;

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using test::upsampledTile;

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
  std::vector<std::string> args{"build",        vrt.string(), "-o",           atlas.string(),
                                "--max-memory", cap,          "--chart-size", "257"};
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

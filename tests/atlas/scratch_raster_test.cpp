// The compressed scratch raster of the window-by-window terrain build (atlas/terrain/
// scratch_raster.h): windows written and read back bit for bit against a raster in memory, whole
// metres, floats (-0 and subnormals among them) and voids; rewrites that leave the file about
// one version of every tile; the shipped tile in well under a byte per sample; damage named.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

#include <sys/stat.h>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/scratch_raster.h"
#include "core/atlas_format.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

struct Reference {
  int64_t width, height;
  std::vector<float> h;
  std::vector<uint8_t> v;
  void write(const CellWindow& w, const float* hs, const uint8_t* vs) {
    for (int64_t y = w.y0; y < w.y1; ++y)
      for (int64_t x = w.x0; x < w.x1; ++x) {
        const size_t from = size_t(y - w.y0) * size_t(w.width()) + size_t(x - w.x0), to = size_t(y * width + x);
        h[to] = hs[from];
        if (vs) v[to] = vs[from];
      }
  }
};

// Bit-for-bit equality of a window read back with the reference.
void expectWindow(const ScratchRaster& s, const Reference& ref, const CellWindow& w) {
  std::vector<float> h(w.cells());
  std::vector<uint8_t> v(w.cells());
  s.read(w, h.data(), v.data());
  size_t wrong = 0;
  bool voids = false;
  for (int64_t y = w.y0; y < w.y1; ++y)
    for (int64_t x = w.x0; x < w.x1; ++x) {
      const size_t i = size_t(y - w.y0) * size_t(w.width()) + size_t(x - w.x0), r = size_t(y * ref.width + x);
      wrong += std::bit_cast<uint32_t>(h[i]) != std::bit_cast<uint32_t>(ref.h[r]) || (v[i] != 0) != (ref.v[r] != 0);
      voids = voids || ref.v[r] == 0;
    }
  EXPECT_EQ(wrong, 0u) << "window " << w.x0 << "," << w.y0 << " - " << w.x1 << "," << w.y1;
  EXPECT_EQ(s.hasVoids(w), voids) << "window " << w.x0 << "," << w.y0 << " - " << w.x1 << "," << w.y1;
}

TEST(ScratchRaster, WindowsComeBackBitForBit) {
  test::TempDir tmp("gimlod-scratch");
  const int64_t W = 301, H = 157;  // tiles of 32: partial tiles on the right and at the top
  Reference ref{W, H, std::vector<float>(size_t(W * H), 0.f), std::vector<uint8_t>(size_t(W * H), 0)};
  ScratchRaster s(tmp.path() / "s.scratch", "dem.tif", uint64_t(W), uint64_t(H), 32);
  // Every sample void and 0 until written.
  expectWindow(s, ref, {0, 0, W, H});
  std::mt19937 rng(7);
  std::vector<float> h;
  std::vector<uint8_t> v;
  for (int round = 0; round < 60; ++round) {
    const int64_t x0 = std::uniform_int_distribution<int64_t>(0, W - 1)(rng);
    const int64_t y0 = std::uniform_int_distribution<int64_t>(0, H - 1)(rng);
    const CellWindow w{x0, y0, std::uniform_int_distribution<int64_t>(x0 + 1, W)(rng),
                       std::uniform_int_distribution<int64_t>(y0 + 1, H)(rng)};
    h.resize(w.cells());
    v.resize(w.cells());
    const int kind = round % 4;  // whole metres, floats, floats with -0 and subnormals, large integers
    for (size_t i = 0; i < h.size(); ++i) {
      const double x = double(i % size_t(w.width())), y = double(i / size_t(w.width()));
      const double smooth = 1500.0 + 300.0 * std::sin(x * 0.05 + round) * std::cos(y * 0.03);
      h[i] = kind == 0   ? float(std::round(smooth))
             : kind == 1 ? float(smooth + 0.001 * double(rng() % 1000))
             : kind == 2 ? (i % 7 == 0    ? -0.f
                            : i % 11 == 0 ? std::numeric_limits<float>::denorm_min()
                                          : float(smooth))
                         : float(int64_t(rng() % (1u << 25)) - (1 << 24));
      v[i] = uint8_t(rng() % 9 != 0);
    }
    const bool keepValidity = round % 5 == 4;
    s.write(w, h.data(), keepValidity ? nullptr : v.data());
    ref.write(w, h.data(), keepValidity ? nullptr : v.data());
    expectWindow(s, ref, w);
  }
  expectWindow(s, ref, {0, 0, W, H});
  expectWindow(s, ref, {17, 33, 18, 34});
  expectWindow(s, ref, {31, 31, 65, 65});
  // All valid now: no window has a void, and the tiles say so without being decoded.
  std::fill(ref.v.begin(), ref.v.end(), uint8_t{1});
  s.write({0, 0, W, H}, ref.h.data(), ref.v.data());
  expectWindow(s, ref, {0, 0, W, H});
  EXPECT_FALSE(s.hasVoids({5, 5, 100, 100}));
  // Windows outside the raster are refused.
  float one = 0.f;
  EXPECT_THROW(s.read({W, 0, W + 1, 1}, &one, nullptr), std::invalid_argument);
  EXPECT_THROW(s.write({-1, 0, 0, 1}, &one, nullptr), std::invalid_argument);
  EXPECT_THROW(s.read({3, 3, 3, 4}, &one, nullptr), std::invalid_argument);
}

TEST(ScratchRaster, RewritesKeepAboutOneVersionOfEveryTile) {
  test::TempDir tmp("gimlod-scratch");
  const int64_t W = 512, H = 512;
  std::vector<float> h(size_t(W * H));
  std::vector<uint8_t> v(size_t(W * H), 1);
  std::mt19937 rng(3);
  for (float& x : h) x = float(rng() % 100000);  // incompressible: every version takes its room
  fs::path path;
  {
    ScratchRaster s(tmp.path() / "s.scratch", "dem.tif", uint64_t(W), uint64_t(H), 64);
    path = s.path();
    s.write({0, 0, W, H}, h.data(), v.data());
    const uint64_t once = s.liveBytes();
    EXPECT_GT(once, uint64_t(W * H) * 2);
    for (int k = 0; k < 8; ++k) s.write({0, 0, W, H}, h.data(), v.data());
    EXPECT_EQ(s.liveBytes(), once);
    EXPECT_EQ(s.peakBytes(), once);
    struct stat st {};
    ASSERT_EQ(::stat(path.c_str(), &st), 0);
    // Where the file system frees punched pages, the disk used stays about one version.
    std::printf("  9 versions of %llu bytes: %llu bytes in the file, %llu bytes on disk\n", (unsigned long long)once,
                (unsigned long long)st.st_size, (unsigned long long)st.st_blocks * 512);
    EXPECT_GE(uint64_t(st.st_size), 9 * once);
  }
  EXPECT_FALSE(fs::exists(path));
}

TEST(ScratchRaster, TheShippedTileTakesUnderAByteASample) {
  test::TempDir tmp("gimlod-scratch");
  const DemRaster dem = loadDem(test::repoData() / "terrain/mt_rainier_90m.tif");
  ScratchRaster s(tmp.path() / "s.scratch", "tile", dem.width, dem.height);
  const std::vector<uint8_t> v(dem.heights.size(), 1);
  s.write({0, 0, int64_t(dem.width), int64_t(dem.height)}, dem.heights.data(), v.data());
  const double perSample = double(s.liveBytes()) / double(dem.heights.size());
  std::printf("  %u x %u samples: %.3f bytes per sample\n", dem.width, dem.height, perSample);
  EXPECT_LT(perSample, 1.0);  // a fifth of a raw float and validity byte
  Reference ref{int64_t(dem.width), int64_t(dem.height), dem.heights, v};
  expectWindow(s, ref, {0, 0, int64_t(dem.width), int64_t(dem.height)});
}

TEST(ScratchRaster, ADamagedTileIsNamed) {
  test::TempDir tmp("gimlod-scratch");
  ScratchRaster s(tmp.path() / "s.scratch", "dem.tif", 100, 100, 128);  // one tile
  std::vector<float> h(100 * 100);
  std::mt19937 rng(11);
  for (float& x : h) x = float(rng() % 5000) * 0.25f;
  std::vector<uint8_t> v(100 * 100, 1);
  s.write({0, 0, 100, 100}, h.data(), v.data());
  ASSERT_GT(s.liveBytes(), 1000u);
  {
    // A byte in the middle of the tile's zstd blocks.
    std::fstream f(s.path(), std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(std::streamoff(s.liveBytes() / 2));
    const char c = char(f.get());
    f.seekp(std::streamoff(s.liveBytes() / 2));
    f.put(char(c ^ 0x5a));
  }
  float out[4];
  try {
    s.read({0, 0, 2, 2}, out, nullptr);
    FAIL() << "a damaged tile was read";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("dem.tif"), std::string::npos) << what;
    EXPECT_NE(what.find("s.scratch"), std::string::npos) << what;
    EXPECT_NE(what.find("tile 0"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace gimlod

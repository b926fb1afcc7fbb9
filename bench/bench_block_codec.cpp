// Height block codec throughput (core/block_codec.h): encodes a DEM as 65^2 blocks (the atlas's
// block size) and prints bytes per sample and encode and decode samples per second on one core.
// Usage: bench_block_codec [DEM] [precision]; default the shipped SRTM tile, lossless (integers).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "atlas/terrain/dem.h"
#include "core/block_codec.h"

using namespace gimlod;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  const std::filesystem::path input = argc > 1 ? argv[1] : "data/terrain/mt_rainier_90m.tif";
  const double precision = argc > 2 ? std::atof(argv[2]) : 0.0;
  const DemRaster dem = loadDem(input);
  constexpr uint32_t kSide = 65;
  std::vector<std::vector<float>> blocks;
  for (uint32_t by = 0; (by + 1) * 64 < dem.height; ++by)
    for (uint32_t bx = 0; (bx + 1) * 64 < dem.width; ++bx) {
      std::vector<float> b(size_t(kSide) * kSide);
      for (uint32_t y = 0; y < kSide; ++y)
        for (uint32_t x = 0; x < kSide; ++x) {
          const float v = dem.heights[size_t(by * 64 + y) * dem.width + bx * 64 + x];
          // Lossless runs code the integer metres the source had (the fill makes fractions).
          b[size_t(y) * kSide + x] = precision > 0.0 ? v : std::nearbyint(v);
        }
      blocks.push_back(std::move(b));
    }
  const double samples = double(blocks.size()) * kSide * kSide;
  std::vector<std::vector<uint8_t>> codes;
  auto t0 = Clock::now();
  uint64_t bytes = 0;
  for (const auto& b : blocks) {
    codes.push_back(encodeHeights(b, kSide, precision));
    bytes += codes.back().size();
  }
  const double encodeS = std::chrono::duration<double>(Clock::now() - t0).count();
  std::vector<float> out(size_t(kSide) * kSide);
  const int repeats = 5;
  t0 = Clock::now();
  for (int r = 0; r < repeats; ++r)
    for (const auto& c : codes) decodeHeights(c, kSide, out);
  const double decodeS = std::chrono::duration<double>(Clock::now() - t0).count() / repeats;
  std::printf("%s: %zu blocks of 65^2, %s: %.3f bytes per sample (float32: 4); encode %.1f M samples/s, decode "
              "%.1f M samples/s (one core)\n",
              input.string().c_str(), blocks.size(), precision > 0.0 ? "quantized" : "integer metres, lossless",
              double(bytes) / samples, samples / encodeS * 1e-6, samples / decodeS * 1e-6);
  return 0;
}

// Block codec throughput (core/block_codec.h).
// - bench_block_codec [DEM] [precision]: encodes a DEM as 65^2 blocks (the atlas's block size) and
//   prints bytes per sample and encode and decode samples per second on one core; default the
//   shipped SRTM tile, lossless (integers).
// - bench_block_codec --atlas ATLAS: reads every level of every chart file of an atlas through
//   ChartFileReader, as the page loader does, and prints its bytes per DEM sample by channel and
//   the samples per second read on one core: heights (decoded), and normals (for a compressed
//   terrain atlas derived from the decoded heights, decoding included); then, for a compressed
//   atlas, the heights (or positions) decoded from memory, and their zstd frames alone.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <zstd.h>

#include "atlas/terrain/dem.h"
#include "core/atlas_format.h"
#include "core/block_codec.h"

using namespace gimlod;
using Clock = std::chrono::steady_clock;

namespace {

int benchAtlas(const std::filesystem::path& dir) {
  const AtlasManifest m = readManifest(dir);
  std::vector<std::unique_ptr<ChartFileReader>> charts;
  uint64_t fileBytes = 0;
  for (const ChartInfo& c : m.charts) {
    charts.push_back(std::make_unique<ChartFileReader>(dir / c.file));
    fileBytes += std::filesystem::file_size(dir / c.file);
  }
  const uint64_t hierarchyBytes = std::filesystem::file_size(dir / m.hierarchyFile);
  // Block by block, as pages are read: the heights (or positions) alone, then heights and normals
  // of each block together (a compressed terrain atlas decodes the block once for both).
  double samples = 0.0, heightS = 0.0, normalS = 0.0;
  const bool geometry = m.kind == AtlasKind::Geometry;
  std::vector<float> values;
  std::vector<PackedNormal> normals;
  for (int repeat = 0; repeat < 3; ++repeat) {
    samples = 0.0;
    for (int pass = 0; pass < 2; ++pass) {
      const auto t0 = Clock::now();
      for (const auto& r : charts)
        for (uint32_t k = 0; k < r->levels(); ++k) {
          const LevelLayout l = levelLayout(r->chartSize(), r->blockIntervals(), k);
          const uint32_t b = l.blockSamples - 1;
          values.resize(size_t(l.blockSamples) * l.blockSamples * 3);
          normals.resize(size_t(l.blockSamples) * l.blockSamples);
          for (uint32_t by = 0; by < l.blocksPerSide; ++by)
            for (uint32_t bx = 0; bx < l.blocksPerSide; ++bx) {
              if (geometry)
                r->readPositions(k, bx * b, by * b, b, reinterpret_cast<glm::vec3*>(values.data()));
              else
                r->readHeights(k, bx * b, by * b, b, values.data());
              if (pass == 1) r->readNormals(k, bx * b, by * b, b, normals.data());
              if (pass == 0) samples += double(l.blockSamples) * l.blockSamples;
            }
        }
      (pass == 0 ? heightS : normalS) += std::chrono::duration<double>(Clock::now() - t0).count();
    }
  }
  heightS /= 3;
  normalS /= 3;
  const double demSamples = geometry ? samples : double(m.samplesX) * m.samplesY;
  std::printf(
      "%s: format version %u%s, %zu charts, %.0f stored samples; chart files %.3f bytes per %s sample, "
      "hierarchy %.3f\n",
      dir.string().c_str(), m.version, charts.front()->derivedNormals() ? " (normals derived)" : "", charts.size(),
      samples, double(fileBytes) / demSamples, geometry ? "stored" : "DEM", double(hierarchyBytes) / demSamples);
  std::printf("read block by block on one core: %s alone %.1f M samples/s; with their normals %.1f M samples/s\n",
              geometry ? "positions" : "heights", samples / heightS * 1e-6, samples / normalS * 1e-6);
  if (!charts.front()->compressed()) return 0;
  // From memory: every block's code read first, then decoded (the codec alone, no file reads or
  // window copies), and then its zstd frame alone (the entropy stage, a bound on the codec).
  const ChartChannel channel = geometry ? kChannelPositions : kChannelHeights;
  struct Coded {
    std::vector<uint8_t> code;
    uint32_t side;
  };
  std::vector<Coded> blocks;
  for (const auto& r : charts)
    for (uint32_t k = 0; k < r->storedLevels(); ++k) {  // (the coarser levels subsample the last)
      const LevelLayout l = levelLayout(r->chartSize(), r->blockIntervals(), k);
      // (A terrain's blocks with derived normals hold a ring of heights round them.)
      const uint32_t side = l.blockSamples + (!geometry && r->derivedNormals() ? 2 : 0);
      for (uint32_t by = 0; by < l.blocksPerSide; ++by)
        for (uint32_t bx = 0; bx < l.blocksPerSide; ++bx)
          blocks.push_back({r->readCodedBlock(channel, k, bx, by), side});
    }
  std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> zstd(ZSTD_createDCtx(), ZSTD_freeDCtx);
  double codecS = 0.0, zstdS = 0.0;
  std::vector<uint8_t> raw;
  for (int repeat = 0; repeat < 3; ++repeat) {
    auto t0 = Clock::now();
    for (const Coded& b : blocks) {
      values.resize(size_t(b.side) * b.side * (geometry ? 3 : 1));
      if (geometry)
        decodePositions(b.code, b.side, values);
      else
        decodeHeights(b.code, b.side, values);
    }
    codecS += std::chrono::duration<double>(Clock::now() - t0).count();
    t0 = Clock::now();
    for (const Coded& b : blocks) {  // after the block's 4-byte magic, one zstd frame
      raw.resize(ZSTD_getFrameContentSize(b.code.data() + 4, b.code.size() - 4));
      if (ZSTD_isError(ZSTD_decompressDCtx(zstd.get(), raw.data(), raw.size(), b.code.data() + 4, b.code.size() - 4)))
        throw std::runtime_error("bench_block_codec: a block's zstd frame does not decode");
    }
    zstdS += std::chrono::duration<double>(Clock::now() - t0).count();
  }
  std::printf("from memory on one core: %s decoded %.1f M samples/s; their zstd frames alone %.1f M samples/s\n",
              geometry ? "positions" : "heights", 3 * samples / codecS * 1e-6, 3 * samples / zstdS * 1e-6);
  return 0;
}

int benchDem(const std::filesystem::path& input, double precision) {
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
  std::printf(
      "%s: %zu blocks of 65^2, %s: %.3f bytes per sample (float32: 4); encode %.1f M samples/s, decode "
      "%.1f M samples/s (one core)\n",
      input.string().c_str(), blocks.size(), precision > 0.0 ? "quantized" : "integer metres, lossless",
      double(bytes) / samples, samples / encodeS * 1e-6, samples / decodeS * 1e-6);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h" ||
                   (std::string(argv[1]) == "--atlas" && argc != 3) || argc > 3)) {
    std::printf(
        "usage: %s [DEM [PRECISION]]   heights coded as 65^2 blocks: bytes per sample, encode and decode\n"
        "       %s --atlas ATLAS       an atlas read block by block: samples decoded per second\n",
        argv[0], argv[0]);
    return argc > 1 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") ? 0 : 2;
  }
  try {
    if (argc > 2 && std::string(argv[1]) == "--atlas") return benchAtlas(argv[2]);
    return benchDem(argc > 1 ? argv[1] : "data/terrain/mt_rainier_90m.tif", argc > 2 ? std::atof(argv[2]) : 0.0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return 1;
  }
}

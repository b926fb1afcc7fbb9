// Tests for the chart file format (block layout, round trip, corrupt files) and atomic writes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <atomic>
#include <random>
#include <thread>
#include <vector>

#include "core/atlas_format.h"
#include "core/block_codec.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

ChartPyramid makePyramid(uint32_t chartSize, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(-500.f, 4000.f);
  ChartPyramid p;
  const uint32_t m = chartSize - 1;
  for (uint32_t s = m;; s >>= 1) {
    const size_t n = size_t(s + 1) * (s + 1);
    std::vector<float> h(n);
    std::vector<PackedNormal> nr(n);
    for (size_t i = 0; i < n; ++i) {
      h[i] = d(rng);
      nr[i] = PackedNormal{uint8_t(rng()), uint8_t(rng()), uint8_t(rng()), 255};
    }
    p.heights.push_back(std::move(h));
    p.normals.push_back(std::move(nr));
    if (s == 1) break;
  }
  return p;
}

TEST(FormatChart, LevelLayout) {
  LevelLayout l = levelLayout(65, 16, 0);
  EXPECT_EQ(l.samples, 65u);
  EXPECT_EQ(l.blocksPerSide, 4u);
  EXPECT_EQ(l.blockSamples, 17u);
  l = levelLayout(65, 16, 1);
  EXPECT_EQ(l.samples, 33u);
  EXPECT_EQ(l.blocksPerSide, 2u);
  l = levelLayout(65, 16, 2);
  EXPECT_EQ(l.blocksPerSide, 1u);
  EXPECT_EQ(l.blockSamples, 17u);
  l = levelLayout(65, 16, 3);
  EXPECT_EQ(l.samples, 9u);
  EXPECT_EQ(l.blocksPerSide, 1u);
  EXPECT_EQ(l.blockSamples, 9u);
  l = levelLayout(65, 16, 6);
  EXPECT_EQ(l.samples, 2u);
  EXPECT_EQ(l.blockSamples, 2u);
  EXPECT_THROW(levelLayout(65, 16, 7), std::logic_error);
  EXPECT_THROW(levelLayout(64, 16, 0), std::logic_error);
  EXPECT_THROW(levelLayout(65, 12, 0), std::logic_error);
  AtlasManifest m;
  m.chartSize = 513;
  EXPECT_EQ(m.intervalsLog2(), 9u);
  EXPECT_EQ(m.pyramidLevels(), 10u);
  EXPECT_TRUE(isChartSizeValid(3));
  EXPECT_TRUE(isChartSizeValid(8193));
  EXPECT_FALSE(isChartSizeValid(500));
  EXPECT_FALSE(isChartSizeValid(2));
}

TEST(FormatChart, PackNormal) {
  EXPECT_EQ(packNormal(0, 0, 1), (PackedNormal{128, 128, 255, 255}));
  EXPECT_EQ(packNormal(-1, 1, 0), (PackedNormal{0, 255, 128, 255}));
  auto u = unpackNormal(packNormal(0.6f, -0.8f, 0.f));
  EXPECT_NEAR(u[0], 0.6f, 1.f / 127);
  EXPECT_NEAR(u[1], -0.8f, 1.f / 127);
}

TEST(FormatChart, RoundTripBlocksAndWindows) {
  test::TempDir tmp("gimlod-chart");
  const uint32_t cs = 65, bi = 16;
  const ChartPyramid p = makePyramid(cs, 7);
  ASSERT_EQ(p.heights.size(), 7u);
  const fs::path f = tmp.path() / "chart_0000.bin";
  const uint64_t bytes = writeChartFile(f, p, cs, bi);
  EXPECT_EQ(bytes, fs::file_size(f));
  for (const auto& e : fs::directory_iterator(tmp.path()))
    EXPECT_EQ(e.path().filename(), "chart_0000.bin") << "temporary file left behind";

  ChartFileReader r(f);
  EXPECT_EQ(r.chartSize(), cs);
  EXPECT_EQ(r.blockIntervals(), bi);
  EXPECT_EQ(r.levels(), 7u);
  for (uint32_t k = 0; k < r.levels(); ++k) {
    EXPECT_EQ(r.readLevelHeights(k), p.heights[k]) << "level " << k;
    EXPECT_EQ(r.readLevelNormals(k), p.normals[k]) << "level " << k;
  }
  // Windows: whole blocks, sub-windows, windows touching the shared block row/column.
  struct W {
    uint32_t level, u0, v0, n;
  };
  const W windows[] = {{0, 0, 0, 16}, {0, 16, 32, 16}, {0, 48, 48, 16}, {0, 20, 37, 5}, {0, 16, 16, 0}, {0, 64, 64, 0},
                       {0, 60, 0, 4}, {1, 16, 0, 16},  {1, 3, 18, 8},   {2, 0, 0, 16},  {3, 2, 4, 4},   {6, 0, 0, 1}};
  for (const W& w : windows) {
    const LevelLayout l = levelLayout(cs, bi, w.level);
    const uint32_t n1 = w.n + 1;
    std::vector<float> h(n1 * n1);
    std::vector<PackedNormal> nr(n1 * n1);
    r.readHeights(w.level, w.u0, w.v0, w.n, h.data());
    r.readNormals(w.level, w.u0, w.v0, w.n, nr.data());
    for (uint32_t v = 0; v < n1; ++v)
      for (uint32_t u = 0; u < n1; ++u) {
        const size_t src = size_t(w.v0 + v) * l.samples + w.u0 + u;
        ASSERT_EQ(h[v * n1 + u], p.heights[w.level][src]) << w.level << " " << w.u0 << " " << w.v0;
        ASSERT_EQ(nr[v * n1 + u], p.normals[w.level][src]);
      }
  }
  float buf[64 * 64];
  EXPECT_THROW(r.readHeights(0, 10, 0, 16, buf), std::logic_error);  // crosses u = 16
  EXPECT_THROW(r.readHeights(0, 0, 60, 5, buf), std::logic_error);   // beyond the level
  EXPECT_THROW(r.readHeights(7, 0, 0, 1, buf), std::logic_error);    // no such level
}

// A chart file written block by block in any order, from several threads, reads back as the one
// written in level order; the level-order file is byte for byte what writeChartFile writes, a
// block is written once, and a file missing a block is not committed.
TEST(FormatChart, BlocksWrittenInAnyOrderReadBackTheSame) {
  test::TempDir tmp("gimlod-chart-writer");
  const uint32_t cs = 129, bi = 16;
  const ChartPyramid p = makePyramid(cs, 11);
  const uint32_t levels = uint32_t(p.heights.size()), mask = (1u << kChannelHeights) | (1u << kChannelNormals);
  struct Block {
    uint32_t level, bx, by;
  };
  std::vector<Block> blocks;
  for (uint32_t k = 0; k < levels; ++k) {
    const LevelLayout l = levelLayout(cs, bi, k);
    for (uint32_t by = 0; by < l.blocksPerSide; ++by)
      for (uint32_t bx = 0; bx < l.blocksPerSide; ++bx) blocks.push_back({k, bx, by});
  }
  auto data = [&](const Block& b) {
    const LevelLayout l = levelLayout(cs, bi, b.level);
    const size_t at = size_t(b.by) * (l.blockSamples - 1) * l.samples + size_t(b.bx) * (l.blockSamples - 1);
    BlockData d;
    d[kChannelHeights] = {p.heights[b.level].data() + at, l.samples};
    d[kChannelNormals] = {p.normals[b.level].data() + at, l.samples};
    return d;
  };
  for (const bool compressed : {false, true}) {
    ChartCoding coding;
    coding.compressed = compressed;
    coding.heightPrecision = 0.01;
    const fs::path whole = tmp.path() / "whole.bin", ordered = tmp.path() / "ordered.bin",
                   shuffled = tmp.path() / "shuffled.bin";
    writeChartFile(whole, p, cs, bi, coding);
    {
      ChartFileWriter w(ordered, {cs, bi, levels, mask}, coding);
      for (const Block& b : blocks) w.writeBlock(b.level, b.bx, b.by, data(b));
      const uint64_t bytes = w.commit();
      EXPECT_EQ(bytes, fs::file_size(ordered));
    }
    EXPECT_EQ(test::fileBytes(whole), test::fileBytes(ordered)) << "compressed " << compressed;
    std::vector<Block> order = blocks;
    std::shuffle(order.begin(), order.end(), std::mt19937(5));
    {
      ChartFileWriter w(shuffled, {cs, bi, levels, mask}, coding);
      std::atomic<size_t> next{0};
      std::vector<std::thread> threads;
      for (int t = 0; t < 3; ++t)
        threads.emplace_back([&] {
          for (size_t i; (i = next++) < order.size();)
            w.writeBlock(order[i].level, order[i].bx, order[i].by, data(order[i]));
        });
      for (std::thread& t : threads) t.join();
      EXPECT_THROW(w.writeBlock(0, 0, 0, data(blocks[0])), std::logic_error);
      w.commit();
    }
    EXPECT_NE(test::fileBytes(whole), test::fileBytes(shuffled));
    const ChartFileReader a(whole), b(shuffled);
    for (uint32_t k = 0; k < levels; ++k) {
      EXPECT_EQ(a.readLevelHeights(k), b.readLevelHeights(k)) << "level " << k;
      EXPECT_EQ(a.readLevelNormals(k), b.readLevelNormals(k)) << "level " << k;
    }
    // A window of whole blocks, across blocks.
    const std::vector<float> level1 = a.readLevelHeights(1);
    const std::vector<float> window = b.readHeightsWindow(1, 16, 32, 32);
    ASSERT_EQ(window.size(), 33u * 33u);
    for (uint32_t v = 0; v <= 32; ++v)
      for (uint32_t u = 0; u <= 32; ++u) ASSERT_EQ(window[v * 33 + u], level1[size_t(32 + v) * 65 + 16 + u]);
    EXPECT_THROW(b.readHeightsWindow(1, 8, 0, 16), std::logic_error);  // not on a block
  }
  {
    const fs::path partial = tmp.path() / "partial.bin";
    ChartFileWriter w(partial, {cs, bi, levels, mask}, {});
    for (size_t i = 1; i < blocks.size(); ++i)
      w.writeBlock(blocks[i].level, blocks[i].bx, blocks[i].by, data(blocks[i]));
    EXPECT_THROW(w.commit(), std::logic_error);
  }
  EXPECT_FALSE(fs::exists(tmp.path() / "partial.bin"));
}

TEST(FormatChart, ConcurrentReads) {
  test::TempDir tmp("gimlod-chart");
  const ChartPyramid p = makePyramid(129, 3);
  const fs::path f = tmp.path() / "c.bin";
  writeChartFile(f, p, 129, 32);
  ChartFileReader r(f);
  std::vector<std::thread> threads;
  std::atomic<int> bad{0};
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      std::vector<float> h(33 * 33);
      for (int i = 0; i < 200; ++i) {
        const uint32_t bx = (i + t) % 4, by = (i * 3 + t) % 4;
        r.readHeights(0, bx * 32, by * 32, 32, h.data());
        for (uint32_t v = 0; v <= 32; ++v)
          for (uint32_t u = 0; u <= 32; ++u)
            if (h[v * 33 + u] != p.heights[0][(by * 32 + v) * 129 + bx * 32 + u]) ++bad;
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(bad.load(), 0);
}

// Every level of a geometry chart file reads back as the pyramid has it: positions, normals and
// colours.
void expectGeometryLevels(const ChartFileReader& r, const ChartPyramid& p) {
  ASSERT_EQ(r.levels(), p.positions.size());
  for (uint32_t k = 0; k < r.levels(); ++k) {
    EXPECT_EQ(r.readLevelPositions(k), p.positions[k]) << "level " << k;
    EXPECT_EQ(r.readLevelNormals(k), p.normals[k]) << "level " << k;
    EXPECT_EQ(r.readLevelColours(k), p.colours[k]) << "level " << k;
  }
}

void expectReaderError(const fs::path& f, const char* what) {
  try {
    ChartFileReader r(f);
    FAIL() << "expected InputError (" << what << ")";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(f.filename().string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(FormatChart, TruncatedAndCorruptFiles) {
  test::TempDir tmp("gimlod-chart");
  const ChartPyramid p = makePyramid(65, 1);
  const fs::path good = tmp.path() / "good.bin";
  const uint64_t size = writeChartFile(good, p, 65, 16);
  std::ifstream in(good, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  auto writeBytes = [&](const char* name, const std::vector<char>& b) {
    const fs::path f = tmp.path() / name;
    std::ofstream(f, std::ios::binary).write(b.data(), std::streamsize(b.size()));
    return f;
  };
  expectReaderError(writeBytes("cut_end.bin", {bytes.begin(), bytes.end() - 1}), "truncated");
  expectReaderError(writeBytes("cut_half.bin", {bytes.begin(), bytes.begin() + size / 2}), "truncated");
  expectReaderError(writeBytes("cut_dir.bin", {bytes.begin(), bytes.begin() + 40}), "truncated");
  expectReaderError(writeBytes("cut_header.bin", {bytes.begin(), bytes.begin() + 10}), "truncated");
  expectReaderError(writeBytes("empty.bin", {}), "truncated");
  std::vector<char> bad = bytes;
  bad[0] = 'X';
  expectReaderError(writeBytes("bad_magic.bin", bad), "magic");
  bad = bytes;
  bad[8] = 64;  // chartSize 64
  expectReaderError(writeBytes("bad_size.bin", bad), "corrupt");
  bad = bytes;
  bad[20 + 7] = 0x7f;  // first block's height offset far beyond the file
  expectReaderError(writeBytes("bad_offset.bin", bad), "corrupt");
  expectReaderError(tmp.path() / "missing.bin", "cannot");
}

// Version 2: a geometry chart (positions, normals, colours) in blocks, read back by window and
// by level; a height field still writes version 1.
TEST(FormatChart, GeometryChannelsRoundTrip) {
  test::TempDir tmp("gimlod-chart");
  const uint32_t cs = 33, bi = 8;
  ChartPyramid p = makePyramid(cs, 3);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> d(-2.f, 2.f);
  for (const auto& level : p.heights) {
    std::vector<glm::vec3> pos(level.size());
    std::vector<PackedColour> col(level.size());
    for (size_t i = 0; i < pos.size(); ++i) {
      pos[i] = {d(rng), d(rng), level[i]};
      col[i] = {uint8_t(rng()), uint8_t(rng()), uint8_t(rng()), 255};
    }
    p.positions.push_back(std::move(pos));
    p.colours.push_back(std::move(col));
  }
  ChartPyramid heightField = p;
  heightField.positions.clear();
  heightField.colours.clear();
  EXPECT_THROW(writeChartFile(tmp.path() / "both.bin", p, cs, bi), std::invalid_argument);  // heights and positions
  p.heights.clear();
  const fs::path f = tmp.path() / "geometry.bin";
  const uint64_t bytes = writeChartFile(f, p, cs, bi);
  EXPECT_EQ(bytes, fs::file_size(f));
  ChartFileReader r(f);
  EXPECT_TRUE(r.hasChannel(kChannelPositions));
  EXPECT_TRUE(r.hasChannel(kChannelColours));
  EXPECT_FALSE(r.hasChannel(kChannelHeights));
  expectGeometryLevels(r, p);
  std::vector<glm::vec3> win(5 * 5);
  r.readPositions(0, 9, 17, 4, win.data());
  for (uint32_t v = 0; v < 5; ++v)
    for (uint32_t u = 0; u < 5; ++u) ASSERT_EQ(win[v * 5 + u], p.positions[0][size_t(17 + v) * cs + 9 + u]);
  float h[4];
  EXPECT_THROW(r.readHeights(0, 0, 0, 1, h), std::logic_error);
  // Without colours, and the height field in version 1 as before.
  p.colours.clear();
  writeChartFile(tmp.path() / "nocolour.bin", p, cs, bi);
  EXPECT_FALSE(ChartFileReader(tmp.path() / "nocolour.bin").hasChannel(kChannelColours));
  writeChartFile(tmp.path() / "terrain.bin", heightField, cs, bi);
  std::ifstream in(tmp.path() / "terrain.bin", std::ios::binary);
  char hdr[8];
  in.read(hdr, 8);
  EXPECT_EQ(hdr[4], 1) << "a height field keeps chart file version 1";
  // A corrupt channel mask is reported.
  std::ifstream g(f, std::ios::binary);
  std::vector<char> b((std::istreambuf_iterator<char>(g)), {});
  b[20] = 1;  // heights only, no normals
  const fs::path bad = tmp.path() / "badmask.bin";
  std::ofstream(bad, std::ios::binary).write(b.data(), std::streamsize(b.size()));
  expectReaderError(bad, "channel mask");
}

// A compressed geometry chart whose coarse levels subsample the first level one block holds
// (firstSingleBlockLevel) stores none of them (flag 8), and reads every level, whole or by window,
// as the pyramid has it; one whose coarse levels are not subsamplings is stored whole.
TEST(FormatChart, CoarseLevelsThatSubsampleAreNotStored) {
  test::TempDir tmp("gimlod-chart");
  const uint32_t cs = 257, bi = 64;  // levels 0 to 2 in 16, 4 and 1 blocks; 3 to 8 subsample level 2
  ASSERT_EQ(firstSingleBlockLevel(cs, bi), 2u);
  ASSERT_EQ(firstSingleBlockLevel(65, 64), 0u);
  const double step = std::exp2(-16.0);
  ChartPyramid p;
  std::mt19937 rng(11);
  for (uint32_t k = 0; (256u >> k) >= 1; ++k) {
    const uint32_t s = (256u >> k) + 1;
    std::vector<glm::vec3> pos(size_t(s) * s);
    std::vector<PackedNormal> nrm(pos.size());
    std::vector<PackedColour> col(pos.size());
    for (uint32_t v = 0; v < s; ++v)
      for (uint32_t u = 0; u < s; ++u) {
        // A wavy sheet on the lattice, a function of the level-0 sample: every level subsamples
        // level 0 exactly.
        const uint32_t x = u << k, y = v << k;
        const auto q = [&](double c) { return float(std::round(c / step) * step); };
        pos[size_t(v) * s + u] = {q(x / 256.0), q(y / 256.0), q(0.1 * std::sin(0.05 * x) * std::cos(0.07 * y))};
        nrm[size_t(v) * s + u] = {uint8_t(x * 7 + y), uint8_t(x ^ y), uint8_t(128 + (x + y) % 100), 255};
        col[size_t(v) * s + u] = {uint8_t(x), uint8_t(y), uint8_t(x * y), 255};
      }
    p.positions.push_back(std::move(pos));
    p.normals.push_back(std::move(nrm));
    p.colours.push_back(std::move(col));
    if ((256u >> k) == 1) break;
  }
  ASSERT_EQ(p.positions.size(), 9u);
  EXPECT_TRUE(coarseLevelsSubsampled(p, cs, bi));
  ChartCoding coding;
  coding.compressed = true;
  coding.positionStep = step;
  const fs::path f = tmp.path() / "subsampled.bin";
  const uint64_t bytes = writeChartFile(f, p, cs, bi, coding);
  const ChartFileReader r(f);
  EXPECT_EQ(r.levels(), 9u);
  EXPECT_EQ(r.storedLevels(), 3u);
  expectGeometryLevels(r, p);
  // A window of a level left out (level 4: 17 samples), read after a block of another level.
  std::vector<glm::vec3> xyz(4 * 4);
  r.readPositions(1, 64, 64, 3, xyz.data());
  r.readPositions(4, 5, 9, 3, xyz.data());
  for (uint32_t v = 0; v < 4; ++v)
    for (uint32_t u = 0; u < 4; ++u) ASSERT_EQ(xyz[v * 4 + u], p.positions[4][size_t(9 + v) * 17 + 5 + u]);
  EXPECT_NO_THROW(r.readCodedBlock(kChannelPositions, 2, 0, 0));
  EXPECT_THROW(r.readCodedBlock(kChannelPositions, 3, 0, 0), std::logic_error);
  // Border normals: the left-out levels' borders subsample level 2's, the rest derived.
  coding.deriveGeometryNormals = true;
  const fs::path g = tmp.path() / "border.bin";
  writeChartFile(g, p, cs, bi, coding);
  const ChartFileReader rb(g);
  EXPECT_EQ(rb.storedLevels(), 3u);
  for (uint32_t k = 3; k < rb.levels(); ++k) {
    const uint32_t s = (256u >> k) + 1;
    const std::vector<glm::vec3> pos = rb.readLevelPositions(k);
    EXPECT_EQ(pos, p.positions[k]) << "level " << k;
    std::vector<PackedNormal> want = p.normals[k];
    geometryImageNormals(reinterpret_cast<const float*>(pos.data()), s, want.data());
    EXPECT_EQ(rb.readLevelNormals(k), want) << "level " << k;
  }
  // One coarse sample that is not its level-2 sample: every level stored, as written.
  ChartPyramid other = p;
  other.positions[5][7].z += float(step);
  EXPECT_FALSE(coarseLevelsSubsampled(other, cs, bi));
  coding.deriveGeometryNormals = false;
  const fs::path h = tmp.path() / "whole.bin";
  EXPECT_GT(writeChartFile(h, other, cs, bi, coding), bytes);
  const ChartFileReader rw(h);
  EXPECT_EQ(rw.storedLevels(), rw.levels());
  EXPECT_EQ(rw.readLevelPositions(5), other.positions[5]);
  // Flag 8 on a chart without positions is refused by name.
  std::ifstream in(f, std::ios::binary);
  std::vector<char> b((std::istreambuf_iterator<char>(in)), {});
  b[20] = 3;  // heights and normals
  const fs::path bad = tmp.path() / "badflag.bin";
  std::ofstream(bad, std::ios::binary).write(b.data(), std::streamsize(b.size()));
  expectReaderError(bad, "subsampled levels without positions");
}

// Derived normals of a sphere's grid (u eastwards, v northwards): outward, within a degree.
TEST(FormatChart, GeometryImageNormalsFollowTheSurface) {
  constexpr uint32_t kSide = 65;
  std::vector<float> xyz(3 * size_t(kSide) * kSide);
  for (uint32_t v = 0; v < kSide; ++v)
    for (uint32_t u = 0; u < kSide; ++u) {
      const double lon = 0.01 * u, lat = 0.01 * v - 0.3;
      float* p = xyz.data() + 3 * (size_t(v) * kSide + u);
      p[0] = float(std::cos(lat) * std::cos(lon));
      p[1] = float(std::cos(lat) * std::sin(lon));
      p[2] = float(std::sin(lat));
    }
  std::vector<PackedNormal> n(size_t(kSide) * kSide, PackedNormal{9, 9, 9, 9});
  geometryImageNormals(xyz.data(), kSide, n.data());
  EXPECT_EQ(n[0], (PackedNormal{9, 9, 9, 9}));  // the border is left alone
  for (uint32_t v = 1; v + 1 < kSide; ++v)
    for (uint32_t u = 1; u + 1 < kSide; ++u) {
      const size_t i = size_t(v) * kSide + u;
      const auto d = unpackNormal(n[i]);
      const double c = d[0] * xyz[3 * i] + d[1] * xyz[3 * i + 1] + d[2] * xyz[3 * i + 2];
      ASSERT_GT(c, std::cos(1.0 * 3.14159265358979 / 180.0) * 0.99) << u << "," << v;
    }
}

// Derived normals as their definition has them, sample by sample (the first difference pair whose
// cross product is not 0 and finite, packed with a truncating quantizer), on images made to hit
// every case: random, flat, collapsed to a few points, huge, and holding NaNs and infinities.
TEST(FormatChart, GeometryImageNormalsMatchTheirDefinitionBitForBit) {
  auto pack = [](const float* a, const float* b, PackedNormal& o) {
    const float c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    const float l2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
    if (!(l2 > 0.f) || !std::isfinite(l2)) return false;
    for (int k = 0; k < 3; ++k) o[k] = uint8_t(std::clamp(c[k] * (127.5f / std::sqrt(l2)) + 127.5f, 0.f, 255.f) + 0.5f);
    o[3] = 255;
    return true;
  };
  std::mt19937 rng(3);
  size_t fallbacks = 0;
  for (const uint32_t side : {3u, 5u, 6u, 17u, 65u})
    for (int kind = 0; kind < 5; ++kind) {
      std::vector<float> xyz(3 * size_t(side) * side);
      std::uniform_real_distribution<float> unit(-1.f, 1.f);
      std::uniform_int_distribution<int> few(-1, 1);
      for (uint32_t i = 0; i < side * side; ++i) {
        float* p = xyz.data() + 3 * size_t(i);
        const float u = float(i % side), v = float(i / side);
        if (kind == 0) p[0] = unit(rng), p[1] = unit(rng), p[2] = unit(rng);
        if (kind == 1) p[0] = u, p[1] = v, p[2] = 0.f;
        if (kind == 2) p[0] = float(few(rng)), p[1] = float(few(rng)), p[2] = 0.f;
        if (kind == 3) p[0] = u * 1e19f, p[1] = v * 1e19f, p[2] = unit(rng) * 1e19f;
        if (kind == 4) p[0] = unit(rng) > 0.6f ? NAN : u, p[1] = unit(rng) > 0.8f ? INFINITY : v, p[2] = 0.f;
      }
      std::vector<PackedNormal> n(size_t(side) * side, PackedNormal{9, 9, 9, 9});
      geometryImageNormals(xyz.data(), side, n.data());
      const size_t row = 3 * size_t(side);
      for (uint32_t v = 1; v + 1 < side; ++v)
        for (uint32_t u = 1; u + 1 < side; ++u) {
          const float* q = xyz.data() + v * row + 3 * size_t(u);
          const float *l = q - 3, *r = q + 3, *d = q - row, *t = q + row;
          float a[3], b[3];
          PackedNormal expected{128, 128, 255, 255};  // (0, 0, 1) where every pair vanishes
          bool found = false;
          if (u >= 2 && v >= 2 && u + 2 < side && v + 2 < side) {
            for (int k = 0; k < 3; ++k)
              a[k] = r[k] - l[k] + q[6 + k] - q[k - 6], b[k] = t[k] - d[k] + q[2 * row + k] - q[k - 2 * row];
            found = pack(a, b, expected);
          }
          const float* pairs[5][4] = {{r, l, t, d}, {r, q, t, q}, {q, l, t, q}, {q, l, q, d}, {r, q, q, d}};
          for (const auto& pr : pairs) {
            if (found) break;
            for (int k = 0; k < 3; ++k) a[k] = pr[0][k] - pr[1][k], b[k] = pr[2][k] - pr[3][k];
            found = pack(a, b, expected);
            ++fallbacks;
          }
          ASSERT_EQ(n[size_t(v) * side + u], expected)
              << "side " << side << ", kind " << kind << ", at " << u << "," << v;
        }
      EXPECT_EQ(n[0], (PackedNormal{9, 9, 9, 9}));  // the border is left alone
    }
  EXPECT_GT(fallbacks, 1000u);
}

// A geometry chart on a sphere, compressed with its normals stored on block borders only: the
// reader gives the stored normals on every block's border (so blocks and charts meeting there
// agree bit for bit) and, inside, the normals geometryImageNormals makes of the decoded
// positions, within a degree of the sphere's own; a damaged border-normal block is an error
// naming the file and the block.
TEST(FormatChart, GeometryNormalsDerivedInsideBlocks) {
  test::TempDir tmp("gimlod-chart");
  const uint32_t cs = 65, bi = 16;
  ChartPyramid p;
  for (uint32_t k = 0; (64u >> k) >= 1; ++k) {
    const uint32_t s = (64u >> k) + 1;
    std::vector<glm::vec3> pos(size_t(s) * s);
    std::vector<PackedNormal> nrm(pos.size());
    for (uint32_t v = 0; v < s; ++v)
      for (uint32_t u = 0; u < s; ++u) {
        // A patch of the unit sphere, u eastwards and v northwards: outward normals.
        const double lon = 0.8 * (double(u << k) / 64.0 - 0.5), lat = 0.8 * (double(v << k) / 64.0 - 0.5);
        const glm::vec3 q(float(std::cos(lat) * std::cos(lon)), float(std::cos(lat) * std::sin(lon)),
                          float(std::sin(lat)));
        pos[size_t(v) * s + u] = q;
        nrm[size_t(v) * s + u] = packNormal(q.x, q.y, q.z);
      }
    p.positions.push_back(std::move(pos));
    p.normals.push_back(std::move(nrm));
    if ((64u >> k) == 1) break;
  }
  ChartCoding coding;
  coding.compressed = true;
  coding.positionStep = std::exp2(-20.0);
  coding.deriveGeometryNormals = true;
  const fs::path f = tmp.path() / "derived.bin";
  writeChartFile(f, p, cs, bi, coding);
  coding.deriveGeometryNormals = false;
  const fs::path g = tmp.path() / "stored.bin";
  writeChartFile(g, p, cs, bi, coding);
  EXPECT_LT(fs::file_size(f), fs::file_size(g));
  const ChartFileReader r(f);
  EXPECT_TRUE(r.derivedNormals());
  EXPECT_FALSE(ChartFileReader(g).derivedNormals());
  EXPECT_THROW(r.readCodedBlock(kChannelPositions, r.levels(), 0, 0), std::logic_error);
  EXPECT_THROW(r.readCodedBlock(kChannelPositions, 0, 4, 0), std::logic_error);  // 4 blocks a side
  // The sphere's levels are subsamplings of one another: those past level 2 (16 intervals, one
  // block) are not stored, and have no code.
  ASSERT_EQ(r.storedLevels(), 3u);
  EXPECT_THROW(r.readCodedBlock(kChannelPositions, 3, 0, 0), std::logic_error);
  EXPECT_THROW(r.readCodedBlock(kChannelHeights, 0, 0, 0), std::logic_error);
  double worst = 0.0;
  size_t derived = 0;
  for (uint32_t k = 0; k < r.levels(); ++k) {
    const LevelLayout l = levelLayout(cs, bi, k);
    const uint32_t b = l.blockSamples - 1, s = l.samples;
    const std::vector<glm::vec3> pos = r.readLevelPositions(k);
    const std::vector<PackedNormal> nrm = r.readLevelNormals(k);
    for (uint32_t by = 0; by < l.blocksPerSide; ++by)
      for (uint32_t bx = 0; bx < l.blocksPerSide; ++bx) {
        // The block as the reader sees it, its normals derived anew from its positions.
        std::vector<float> xyz(3 * size_t(l.blockSamples) * l.blockSamples);
        std::vector<PackedNormal> mine(size_t(l.blockSamples) * l.blockSamples);
        r.readPositions(k, bx * b, by * b, b, reinterpret_cast<glm::vec3*>(xyz.data()));
        r.readNormals(k, bx * b, by * b, b, mine.data());
        std::vector<PackedNormal> again = mine;
        geometryImageNormals(xyz.data(), l.blockSamples, again.data());
        EXPECT_EQ(again, mine) << "level " << k << " block " << bx << "," << by;
        // The block's code as stored decodes to what the reader gave.
        std::vector<float> coded(xyz.size());
        if (k < r.storedLevels()) {
          decodePositions(r.readCodedBlock(kChannelPositions, k, bx, by), l.blockSamples, coded);
          EXPECT_EQ(coded, xyz) << "level " << k << " block " << bx << "," << by;
        }
        for (uint32_t v = 0; v <= b; ++v)
          for (uint32_t u = 0; u <= b; ++u) {
            const size_t i = size_t(by * b + v) * s + bx * b + u;
            const bool border = u == 0 || v == 0 || u == b || v == b;
            if (border) {
              ASSERT_EQ(nrm[i], p.normals[k][i]) << "level " << k << " sample " << i;
              continue;
            }
            const auto n = unpackNormal(nrm[i]);
            const glm::vec3 q = pos[i];
            const double c = (n[0] * q.x + n[1] * q.y + n[2] * q.z) /
                             std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
            worst = std::max(worst, std::acos(std::min(1.0, c)) * 180.0 / 3.14159265358979);
            ++derived;
          }
      }
  }
  EXPECT_GT(derived, 2000u);
  EXPECT_LT(worst, 1.0) << "degrees between a derived normal and the sphere's";
  // A flipped byte in the checksum of the file's last block (a flip inside a code may land on
  // bits the decoder never reads, and then rightly decodes the same samples).
  std::ifstream in(f, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  in.close();
  bytes[bytes.size() - 2] = char(bytes[bytes.size() - 2] ^ 0x5a);
  const fs::path bad = tmp.path() / "bad.bin";
  std::ofstream(bad, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
  const ChartFileReader rb(bad);
  std::string message;
  try {
    for (uint32_t k = 0; k < rb.levels(); ++k) {
      (void)rb.readLevelPositions(k);
      (void)rb.readLevelNormals(k);
    }
  } catch (const InputError& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("bad.bin"), std::string::npos) << message;
  EXPECT_NE(message.find("block"), std::string::npos) << message;
}

TEST(FormatChart, AtomicWriteFailsCleanly) {
  test::TempDir tmp("gimlod-chart");
  const char data[] = "hello";
  const fs::path ok = tmp.path() / "ok.txt";
  atomicWriteFile(ok, data, 5);
  atomicWriteFile(ok, data, 3);  // overwrite
  EXPECT_EQ(fs::file_size(ok), 3u);
  const fs::path bad = tmp.path() / "no_such_dir" / "x.bin";
  try {
    atomicWriteFile(bad, data, 5);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_dir/x.bin"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("No such file"), std::string::npos) << e.what();
  }
  // Renaming onto a directory fails after the temp file was written: the temp must be gone.
  const fs::path dirTarget = tmp.path() / "a_directory";
  fs::create_directories(dirTarget / "child");
  EXPECT_THROW(atomicWriteFile(dirTarget, data, 5), InputError);
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(tmp.path())) files += e.is_regular_file();
  EXPECT_EQ(files, 1u);  // only ok.txt
}

// Files written inside a staged directory (flushed together by its commit, not one by one) appear
// whole when it is committed and not before; a stage dropped uncommitted leaves the earlier output
// and no staging directory; a file outside any stage is written as before.
TEST(FormatChart, StagedFilesAppearWholeWhenTheDirectoryIsCommitted) {
  test::TempDir tmp("gimlod-chart");
  const fs::path target = tmp.path() / "out";
  std::vector<uint8_t> bytes(size_t{1} << 20);
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = uint8_t(i * 7 + (i >> 9));
  auto fileBytes = [](const fs::path& f) {
    std::ifstream in(f, std::ios::binary);
    return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), {});
  };
  {
    StagedDirectory stage(target, "marker", "test output");
    atomicWriteFile(stage.path() / "marker", "m", 1);
    AtomicFileWriter w(stage.path() / "big.bin");
    w.write(bytes.data(), bytes.size() / 2);
    w.write(bytes.data() + bytes.size() / 2, bytes.size() - bytes.size() / 2);
    w.commit();
    EXPECT_FALSE(fs::exists(target));
    stage.commit();
  }
  EXPECT_EQ(fileBytes(target / "big.bin"), bytes);
  {
    StagedDirectory stage(target, "marker", "test output");
    atomicWriteFile(stage.path() / "marker", "n", 1);
  }
  EXPECT_EQ(fileBytes(target / "marker"), std::vector<uint8_t>{'m'});
  size_t entries = 0;
  for (const auto& e : fs::directory_iterator(tmp.path())) entries += e.path() != target;
  EXPECT_EQ(entries, 0u) << "a staging directory was left";
  atomicWriteFile(tmp.path() / "outside.bin", bytes.data(), bytes.size());
  EXPECT_EQ(fileBytes(tmp.path() / "outside.bin"), bytes);
}

}  // namespace
}  // namespace gimlod

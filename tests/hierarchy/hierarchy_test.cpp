#include <gtest/gtest.h>

#include <fstream>

#include <cmath>
#include <cstring>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "hierarchy/hierarchy.h"
#include "tests/synthetic_terrain.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

// Independent brute force: max over the node's closed region of |h - surface at level k'|,
// maximised over 1 <= k' <= k; the surface splits each cell along (0,0)-(1,1).
float bruteError(const std::vector<float>& h, uint32_t S, uint32_t level, uint32_t x, uint32_t y, uint32_t k) {
  const uint32_t M = S - 1, size = M >> level;
  float worst = 0.f;
  for (uint32_t kk = 1; kk <= k; ++kk) {
    const uint32_t s = 1u << kk;
    for (uint32_t v = y * size; v <= (y + 1) * size; ++v)
      for (uint32_t u = x * size; u <= (x + 1) * size; ++u) {
        const uint32_t cu = std::min(u / s, M / s - 1), cv = std::min(v / s, M / s - 1);
        const double fx = double(u - cu * s) / s, fy = double(v - cv * s) / s;
        auto at = [&](uint32_t a, uint32_t b) { return double(h[size_t(b * s) * S + a * s]); };
        const double h00 = at(cu, cv), h10 = at(cu + 1, cv), h01 = at(cu, cv + 1), h11 = at(cu + 1, cv + 1);
        // Barycentric interpolation on the triangle containing (fx, fy).
        const double z =
            fx >= fy ? h00 * (1 - fx) + h10 * (fx - fy) + h11 * fy : h00 * (1 - fy) + h01 * (fy - fx) + h11 * fx;
        worst = std::max(worst, float(std::fabs(h[size_t(v) * S + u] - z)));
      }
  }
  return worst;
}

void checkInvariants(const Hierarchy& hier, const AtlasManifest& m,
                     const std::function<std::vector<float>(uint32_t)>& source) {
  const HierarchyParams& p = hier.params;
  const uint32_t S = m.chartSize, M = S - 1;
  for (uint32_t c = 0; c < hier.chartCount(); ++c) {
    const std::vector<float> h = source(c);
    for (uint32_t l = 0; l < p.depth; ++l) {
      const uint32_t size = M >> l;
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) {
          const NodeId n{c, l, x, y};
          // Error is zero at the source resolution and never decreases as resolution drops.
          if (p.maxResLog2(l) == p.intervalsLog2 - l) {
            EXPECT_EQ(hier.error(n, p.maxResLog2(l)), 0.f);
          }
          for (uint32_t r = p.minNodeResLog2; r < p.maxResLog2(l); ++r)
            ASSERT_GE(hier.error(n, r), hier.error(n, r + 1)) << "chart " << c << " level " << l;
          // A parent's error is at least each child's at the same pyramid level.
          if (l + 1 < p.depth)
            for (uint32_t i = 0; i < 4; ++i)
              for (uint32_t r = std::max(p.minNodeResLog2 + 1, 1u); r <= p.maxResLog2(l); ++r)
                if (r - 1 <= p.maxResLog2(l + 1) && r - 1 >= p.minNodeResLog2) {
                  ASSERT_GE(hier.error(n, r), hier.error(n.child(i), r - 1));
                }
          // Bounds contain every sample of the region.
          const auto& b = hier.bounds(n);
          for (uint32_t v = y * size; v <= (y + 1) * size; ++v)
            for (uint32_t u = x * size; u <= (x + 1) * size; ++u) {
              const float z = h[size_t(v) * S + u];
              ASSERT_LE(b[2], z);
              ASSERT_GE(b[5], z);
            }
        }
    }
  }
}

TEST(Hierarchy, ErrorsMatchBruteForceOnHandMadeCharts) {
  const AtlasManifest m = test::syntheticManifest(33, 2, 1, 3, 4, 1);
  auto source = [&](uint32_t c) { return test::syntheticChart(m, c); };
  const Hierarchy hier = buildTerrainHierarchy(m, source);
  const HierarchyParams& p = hier.params;
  ASSERT_EQ(hier.chartCount(), 2u);
  for (uint32_t c = 0; c < 2; ++c) {
    const auto h = source(c);
    for (uint32_t l = 0; l < p.depth; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x)
          for (uint32_t r = p.minNodeResLog2; r <= p.maxResLog2(l); ++r) {
            const uint32_t k = p.pyramidLevel(l, r);
            const float expect = k == 0 ? 0.f : bruteError(h, m.chartSize, l, x, y, k);
            EXPECT_NEAR(hier.error({c, l, x, y}, r), expect, 1e-4f + 1e-6f * expect)
                << "chart " << c << " level " << l << " node " << x << "," << y << " res " << r;
          }
  }
  checkInvariants(hier, m, source);
}

TEST(Hierarchy, PlaneHasZeroError) {
  const AtlasManifest m = test::syntheticManifest(17, 1, 1, 2, 3, 1);
  auto source = [&](uint32_t) {
    std::vector<float> h(17 * 17);
    for (uint32_t v = 0; v < 17; ++v)
      for (uint32_t u = 0; u < 17; ++u) h[v * 17 + u] = 0.5f * float(u) - 0.25f * float(v);
    return h;
  };
  const Hierarchy hier = buildTerrainHierarchy(m, source);
  for (uint32_t r = 1; r <= 3; ++r) EXPECT_LE(hier.error({0, 0, 0, 0}, r), 1e-5f);
}

TEST(Hierarchy, RootNeighboursAndEmptyNodes) {
  AtlasManifest m = test::syntheticManifest(17, 3, 2, 3, 3, 1);
  m.samplesX = 2 * 16 + 5;  // the third chart column is mostly padding
  const Hierarchy hier = buildTerrainHierarchy(m, [&](uint32_t c) { return test::syntheticChart(m, c); });
  EXPECT_EQ(hier.roots[0][kEdgeRight].chart, 1);
  EXPECT_EQ(hier.roots[0][kEdgeRight].edge, kEdgeLeft);
  EXPECT_EQ(hier.roots[0][kEdgeLeft].chart, -1);
  EXPECT_EQ(hier.roots[0][kEdgeTop].chart, 3);
  EXPECT_EQ(hier.roots[4][kEdgeBottom].chart, 1);
  // Chart 2 (x = 2) covers gx 32..48 but the data ends at gx 36: its right half is empty.
  EXPECT_FALSE(hier.flags({2, 1, 0, 0}) & kNodeEmpty);
  EXPECT_TRUE(hier.flags({2, 1, 1, 0}) & kNodeEmpty);
  EXPECT_TRUE(hier.flags({2, 2, 3, 3}) & kNodeEmpty);
}

TEST(Hierarchy, FileRoundTripAndCorruption) {
  const AtlasManifest m = test::syntheticManifest(33, 2, 2, 3, 4, 1);
  const Hierarchy hier = buildTerrainHierarchy(m, [&](uint32_t c) { return test::syntheticChart(m, c); });
  test::TempDir dir;
  uintmax_t rawBytes = 0;
  for (const bool compressed : {false, true}) {
    SCOPED_TRACE(compressed ? "version 2 (compressed)" : "version 1");
    const auto path = dir.path() / (compressed ? "hierarchy2.bin" : "hierarchy1.bin");
    writeHierarchy(path, hier, compressed);
    uint32_t version = 0;
    std::ifstream(path, std::ios::binary).seekg(4).read(reinterpret_cast<char*>(&version), 4);
    EXPECT_EQ(version, compressed ? 2u : 1u);
    const Hierarchy back = readHierarchy(path);
    ASSERT_EQ(back.chartCount(), hier.chartCount());
    for (uint32_t c = 0; c < hier.chartCount(); ++c) {
      // Bitwise: unavailable resolutions hold NaN.
      ASSERT_EQ(back.charts[c].errors.size(), hier.charts[c].errors.size());
      EXPECT_EQ(std::memcmp(back.charts[c].errors.data(), hier.charts[c].errors.data(),
                            hier.charts[c].errors.size() * sizeof(float)),
                0);
      EXPECT_EQ(back.charts[c].bounds, hier.charts[c].bounds);
      EXPECT_EQ(back.charts[c].flags, hier.charts[c].flags);
      for (uint32_t e = 0; e < 4; ++e) {
        EXPECT_EQ(back.roots[c][e].chart, hier.roots[c][e].chart);
        EXPECT_EQ(back.roots[c][e].edge, hier.roots[c][e].edge);
        EXPECT_EQ(back.roots[c][e].reversed, hier.roots[c][e].reversed);
      }
    }
    const uintmax_t bytes = std::filesystem::file_size(path);
    if (compressed) {
      EXPECT_LT(bytes, rawBytes);
      // A flipped byte anywhere past the header: the checksum (or the frame) catches it.
      for (const uintmax_t at : {uintmax_t(12), bytes / 2, bytes - 2}) {
        const auto bad = dir.path() / "bad.bin";
        std::filesystem::copy_file(path, bad, std::filesystem::copy_options::overwrite_existing);
        std::fstream f(bad, std::ios::binary | std::ios::in | std::ios::out);
        char b = 0;
        f.seekg(std::streamoff(at)).read(&b, 1);
        b = char(b ^ 0x21);
        f.seekp(std::streamoff(at)).write(&b, 1);
        f.close();
        EXPECT_THROW(readHierarchy(bad), InputError) << "byte " << at;
      }
    } else {
      rawBytes = bytes;
    }
    std::filesystem::resize_file(path, bytes / 2);
    EXPECT_THROW(readHierarchy(path), InputError);
  }
  EXPECT_THROW(readHierarchy(dir.path() / "missing.bin"), InputError);
}

// The fuzz corpus's version-2 files were coded from its version-1 files by a separate
// implementation of the format (a Python script, zstd's command line): they decode to the same
// hierarchy, so the layout is the one documented, not merely what writeHierarchy happens to do.
TEST(Hierarchy, Version2FilesOfTheFuzzCorpusDecodeLikeTheirVersion1Originals) {
  const auto corpus = test::repoData().parent_path() / "tests/fuzz/corpus/fuzz_hierarchy";
  for (const char* name : {"heightfield", "geometry"}) {
    SCOPED_TRACE(name);
    const Hierarchy a = readHierarchy(corpus / (std::string(name) + ".bin"));
    const Hierarchy b = readHierarchy(corpus / (std::string(name) + "_v2.bin"));
    ASSERT_EQ(a.chartCount(), b.chartCount());
    ASSERT_GT(a.chartCount(), 0u);
    for (uint32_t c = 0; c < a.chartCount(); ++c) {
      ASSERT_EQ(a.charts[c].errors.size(), b.charts[c].errors.size());
      EXPECT_EQ(std::memcmp(a.charts[c].errors.data(), b.charts[c].errors.data(), a.charts[c].errors.size() * 4), 0);
      EXPECT_EQ(a.charts[c].bounds, b.charts[c].bounds);
      EXPECT_EQ(a.charts[c].flags, b.charts[c].flags);
      for (uint32_t e = 0; e < 4; ++e) EXPECT_EQ(a.roots[c][e].chart, b.roots[c][e].chart);
    }
  }
}

TEST(Hierarchy, InvalidParametersAreRejected) {
  HierarchyParams p;
  p.intervalsLog2 = 4;
  p.depth = 5;  // leaves would have 1 interval < 2^2
  p.maxNodeResLog2 = 4;
  p.minNodeResLog2 = 2;
  EXPECT_THROW(p.validate(), InputError);
  p.depth = 3;
  EXPECT_NO_THROW(p.validate());
  p.maxNodeResLog2 = 5;
  EXPECT_THROW(p.validate(), InputError);
}

TEST(Hierarchy, InvariantsOnRealSrtmTile) {
  const DemRaster dem = loadDem(test::realData("terrain/mt_rainier_90m.tif"));
  AtlasManifest m = test::syntheticManifest(257, 5, 5, 4, 6, 2);
  m.samplesX = dem.width;
  m.samplesY = dem.height;
  m.spacing = dem.spacing;
  auto source = [&](uint32_t c) { return extractChart(dem, m.charts[c].gridX, m.charts[c].gridY, m.chartSize); };
  const Hierarchy hier = buildTerrainHierarchy(m, source);
  checkInvariants(hier, m, source);
  // Brute-force spot check on the real data for a few nodes of the first chart.
  const auto h = source(0);
  for (uint32_t l = 1; l < 4; ++l)
    for (uint32_t r = hier.params.minNodeResLog2; r <= hier.params.maxResLog2(l); ++r) {
      const uint32_t k = hier.params.pyramidLevel(l, r);
      const float expect = k == 0 ? 0.f : bruteError(h, 257, l, 1, 0, k);
      EXPECT_NEAR(hier.error({0, l, 1, 0}, r), expect, 1e-2f);  // float rounding at ~4 km heights
    }
}

}  // namespace
}  // namespace gimlod

// The geometry-image hierarchy (mesh atlases): errors and bounds against independent brute force,
// against the terrain hierarchy on a lifted height field, monotonicity, and bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <glm/glm.hpp>

#include "hierarchy/hierarchy.h"
#include "tests/synthetic_terrain.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

// A curved chart: a cap of a sphere of radius 3 over [-1, 1]^2, plus a ripple.
std::vector<glm::vec3> capChart(uint32_t S, float ripple) {
  std::vector<glm::vec3> P(size_t(S) * S);
  for (uint32_t v = 0; v < S; ++v)
    for (uint32_t u = 0; u < S; ++u) {
      const float x = -1.f + 2.f * float(u) / float(S - 1), y = -1.f + 2.f * float(v) / float(S - 1);
      const float z = std::sqrt(9.f - x * x - y * y) + ripple * std::sin(7.f * x) * std::cos(5.f * y);
      P[size_t(v) * S + u] = {x, y, z};
    }
  return P;
}

// Independent brute force: the max over the node's samples and over k' in [1, k] of the distance
// to the level-k' grid's triangle (diagonal (0,0)-(1,1)) interpolated at the sample's (u, v).
float bruteError(const std::vector<glm::vec3>& P, uint32_t S, uint32_t L, const NodeId& n, uint32_t r) {
  const uint32_t size = 1u << (L - n.level), u0 = n.x * size, v0 = n.y * size;
  const uint32_t k = L - n.level - r;
  float worst = 0.f;
  for (uint32_t kk = 1; kk <= k; ++kk) {
    const uint32_t s = 1u << kk;
    for (uint32_t v = v0; v <= v0 + size; ++v)
      for (uint32_t u = u0; u <= u0 + size; ++u) {
        const uint32_t cu = std::min(u / s, (S - 1) / s - 1), cv = std::min(v / s, (S - 1) / s - 1);
        const double fx = double(u - cu * s) / s, fy = double(v - cv * s) / s;
        auto at = [&](uint32_t a, uint32_t b) { return glm::dvec3(P[size_t(b) * S + a]); };
        const glm::dvec3 a = at(cu * s, cv * s), b = at(cu * s + s, cv * s), c = at(cu * s, cv * s + s),
                         d = at(cu * s + s, cv * s + s);
        const glm::dvec3 q = fx >= fy ? a + fx * (b - a) + fy * (d - b) : a + fy * (c - a) + fx * (d - c);
        worst = std::max(worst, float(glm::length(glm::dvec3(P[size_t(v) * S + u]) - q)));
      }
  }
  return worst;
}

HierarchyParams params(uint32_t L, uint32_t depth, uint32_t maxResLog2, uint32_t minRes) {
  HierarchyParams p;
  p.intervalsLog2 = L;
  p.depth = depth;
  p.maxNodeResLog2 = maxResLog2;
  p.minNodeResLog2 = minRes;
  return p;
}

TEST(GeometryHierarchy, ErrorsAndBoundsMatchBruteForceOnACurvedChart) {
  const uint32_t L = 5, S = 33;
  const HierarchyParams p = params(L, 3, 4, 1);
  const auto P = capChart(S, 0.05f);
  const Hierarchy h = buildGeometryHierarchy(p, {std::array<RootNeighbour, 4>{}}, [&](uint32_t) { return P; });
  ASSERT_EQ(h.chartCount(), 1u);
  uint32_t checked = 0;
  for (uint32_t l = 0; l < p.depth; ++l)
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x) {
        const NodeId n{0, l, x, y};
        // Bounds: the box of the node's samples.
        const uint32_t size = 1u << (L - l);
        glm::vec3 lo(1e30f), hi(-1e30f);
        for (uint32_t v = y * size; v <= (y + 1) * size; ++v)
          for (uint32_t u = x * size; u <= (x + 1) * size; ++u)
            lo = glm::min(lo, P[v * S + u]), hi = glm::max(hi, P[v * S + u]);
        const auto& b = h.bounds(n);
        EXPECT_EQ(b[0], lo.x);
        EXPECT_EQ(b[2], lo.z);
        EXPECT_EQ(b[4], hi.y);
        EXPECT_EQ(b[5], hi.z);
        for (uint32_t r = p.minNodeResLog2; r <= p.maxResLog2(l); ++r) {
          EXPECT_NEAR(h.error(n, r), bruteError(P, S, L, n, r), 1e-5f) << l << " " << x << " " << y << " res " << r;
          ++checked;
          if (r > p.minNodeResLog2) {
            EXPECT_LE(h.error(n, r), h.error(n, r - 1));  // coarser: never smaller
          }
          if (l + 1 < p.depth && r <= p.maxResLog2(l + 1)) {
            for (uint32_t c = 0; c < 4; ++c) EXPECT_GE(h.error(n, r), h.error(n.child(c), r) - 1e-7f);
          }
        }
        EXPECT_EQ(h.error(n, L - l <= p.maxResLog2(l) ? L - l : p.maxResLog2(l)) == 0.f, L - l <= p.maxResLog2(l));
      }
  EXPECT_GT(checked, 20u);
  EXPECT_GT(h.error({0, 0, 0, 0}, 1), 0.01f);  // the curved chart does have error
}

TEST(GeometryHierarchy, LiftedHeightFieldHasTheTerrainErrors) {
  // x and y are linear in (u, v), so the 3D error of (u, v, h) is the vertical error.
  const AtlasManifest m = test::syntheticManifest(65, 2, 1, 4, 5, 2);
  const Hierarchy terrain = buildTerrainHierarchy(m, [&](uint32_t c) { return test::syntheticChart(m, c); });
  std::vector<std::array<RootNeighbour, 4>> roots;
  for (const ChartInfo& c : m.charts) roots.push_back(c.neighbours);
  const Hierarchy geometry = buildGeometryHierarchy(hierarchyParams(m), roots, [&](uint32_t c) {
    const std::vector<float> hgt = test::syntheticChart(m, c);
    std::vector<glm::vec3> P(hgt.size());
    for (uint32_t v = 0; v < 65; ++v)
      for (uint32_t u = 0; u < 65; ++u)
        P[v * 65 + u] = {float(m.charts[c].gridX * 64 + u), float(m.charts[c].gridY * 64 + v), hgt[v * 65 + u]};
    return P;
  });
  ASSERT_EQ(geometry.chartCount(), terrain.chartCount());
  EXPECT_EQ(geometry.roots[1][kEdgeLeft].chart, terrain.roots[1][kEdgeLeft].chart);
  double worst = 0.0;
  for (uint32_t c = 0; c < 2; ++c)
    for (uint32_t l = 0; l < 4; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) {
          const NodeId n{c, l, x, y};
          for (uint32_t r = 2; r <= geometry.params.maxResLog2(l); ++r)
            worst = std::max(worst, std::fabs(double(geometry.error(n, r)) - double(terrain.error(n, r))));
          EXPECT_EQ(geometry.bounds(n)[2], terrain.bounds(n)[2]);
          EXPECT_EQ(geometry.bounds(n)[5], terrain.bounds(n)[5]);
        }
  EXPECT_LT(worst, 1e-3);
}

uint32_t fileVersion(const std::filesystem::path& path) {
  uint32_t version = 0;
  std::ifstream(path, std::ios::binary).seekg(4).read(reinterpret_cast<char*>(&version), 4);
  return version;
}

// Three curved charts of different sizes and ripples, with neighbours, at depth 4.
Hierarchy threeCaps() {
  const HierarchyParams p = params(6, 4, 4, 1);
  std::vector<std::array<RootNeighbour, 4>> roots(3);
  roots[0][kEdgeRight] = {1, kEdgeLeft, true};
  roots[1][kEdgeLeft] = {0, kEdgeRight, true};
  roots[1][kEdgeTop] = {2, kEdgeBottom, false};
  roots[2][kEdgeBottom] = {1, kEdgeTop, false};
  return buildGeometryHierarchy(p, roots, [](uint32_t c) {
    std::vector<glm::vec3> P = capChart(65, 0.02f + 0.05f * float(c));
    for (glm::vec3& q : P) q = q * (1.f + float(c)) + glm::vec3(float(c) * 3.f, -1.f, 1000.f * float(c));
    return P;
  });
}

// Quantized (version 3): every box read back holds the exact box, inset from its parent's by
// whole 255ths, and every error is the exact one rounded up by less than 2^-7 of it (NaN where
// the node has none); flags and roots are the same, the file under half of version 2's, and the
// decoded hierarchy codes to itself again. A box outside its parent's makes it version 2, exact.
TEST(GeometryHierarchy, QuantizedFilesHoldTheExactBoxesAndErrors) {
  const Hierarchy h = threeCaps();
  test::TempDir dir;
  const auto v2 = dir.path() / "v2.bin", v3 = dir.path() / "v3.bin";
  writeHierarchy(v2, h, HierarchyCoding::kGrouped);
  writeHierarchy(v3, h, HierarchyCoding::kQuantized);
  EXPECT_EQ(fileVersion(v2), 2u);
  ASSERT_EQ(fileVersion(v3), 3u);
  EXPECT_LT(2 * std::filesystem::file_size(v3), std::filesystem::file_size(v2));
  const Hierarchy back = readHierarchy(v3);
  ASSERT_EQ(back.chartCount(), h.chartCount());
  EXPECT_EQ(back.params.depth, h.params.depth);
  uint32_t insetBoxes = 0, roundedErrors = 0;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const auto &exact = h.charts[c], &read = back.charts[c];
    EXPECT_EQ(read.bounds[0], exact.bounds[0]);  // the root's box is stored whole
    for (size_t n = 0; n < exact.bounds.size(); ++n)
      for (uint32_t k = 0; k < 3; ++k) {
        ASSERT_LE(read.bounds[n][k], exact.bounds[n][k]) << c << " " << n << " " << k;
        ASSERT_GE(read.bounds[n][k + 3], exact.bounds[n][k + 3]) << c << " " << n << " " << k;
        // Within 1/255 of the root's extent (the parent's, and so at most the root's) per side.
        const float slack = (exact.bounds[0][k + 3] - exact.bounds[0][k]) / 255.f * 1.001f;
        EXPECT_LE(exact.bounds[n][k] - read.bounds[n][k], slack);
        EXPECT_LE(read.bounds[n][k + 3] - exact.bounds[n][k + 3], slack);
        insetBoxes += read.bounds[n][k] > read.bounds[0][k];
      }
    ASSERT_EQ(read.errors.size(), exact.errors.size());
    for (size_t i = 0; i < exact.errors.size(); ++i) {
      if (std::isnan(exact.errors[i])) {
        EXPECT_TRUE(std::isnan(read.errors[i])) << i;
        continue;
      }
      ASSERT_GE(read.errors[i], exact.errors[i]) << c << " " << i;
      EXPECT_LE(read.errors[i], exact.errors[i] * (1.f + 1.f / 128.f)) << c << " " << i;
      roundedErrors += read.errors[i] > exact.errors[i];
    }
    EXPECT_EQ(read.flags, exact.flags);
    for (uint32_t e = 0; e < 4; ++e) {
      EXPECT_EQ(back.roots[c][e].chart, h.roots[c][e].chart);
      EXPECT_EQ(back.roots[c][e].edge, h.roots[c][e].edge);
      EXPECT_EQ(back.roots[c][e].reversed, h.roots[c][e].reversed);
    }
  }
  EXPECT_GT(insetBoxes, 100u);
  EXPECT_GT(roundedErrors, 100u);
  // The decoded hierarchy is coded by the same boxes and errors.
  writeHierarchy(dir.path() / "again.bin", back, HierarchyCoding::kQuantized);
  const Hierarchy again = readHierarchy(dir.path() / "again.bin");
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    EXPECT_EQ(again.charts[c].bounds, back.charts[c].bounds);
    EXPECT_EQ(std::memcmp(again.charts[c].errors.data(), back.charts[c].errors.data(),
                          back.charts[c].errors.size() * sizeof(float)),
              0);
  }
  // A box outside its parent's cannot be inset: version 2, bit for bit.
  Hierarchy outside = h;
  outside.charts[1].bounds[7][4] = outside.charts[1].bounds[0][4] + 1.f;
  writeHierarchy(v3, outside, HierarchyCoding::kQuantized);
  EXPECT_EQ(fileVersion(v3), 2u);
  EXPECT_EQ(readHierarchy(v3).charts[1].bounds, outside.charts[1].bounds);
}

// Damaged version 3 files are refused naming the file: a flipped byte (the checksum), a cut file,
// and a body whose size does not match its header.
TEST(GeometryHierarchy, DamagedQuantizedFilesAreRefused) {
  test::TempDir dir;
  const auto path = dir.path() / "hierarchy.bin";
  writeHierarchy(path, threeCaps(), HierarchyCoding::kQuantized);
  const std::string good = test::fileBytes(path);
  auto expectRefused = [&](const std::string& bytes, const char* what) {
    std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(bytes.size()));
    try {
      readHierarchy(path);
      ADD_FAILURE() << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
  };
  for (const size_t at : {size_t(12), good.size() / 2, good.size() - 2}) {
    std::string bad = good;
    bad[at] = char(bad[at] ^ 0x21);
    expectRefused(bad, "a flipped byte");
  }
  expectRefused(good.substr(0, good.size() / 2), "a cut file");
  expectRefused(good.substr(0, 8), "no body");
}

TEST(GeometryHierarchy, BadImagesAreRejected) {
  const HierarchyParams p = params(4, 2, 4, 1);
  std::vector<glm::vec3> P(17 * 17, glm::vec3(0.f));
  EXPECT_THROW(buildGeometryHierarchy(p, {std::array<RootNeighbour, 4>{}},
                                      [&](uint32_t) { return std::vector<glm::vec3>(16 * 16); }),
               InputError);
  P[40].y = std::nanf("");
  try {
    buildGeometryHierarchy(p, {std::array<RootNeighbour, 4>{}, std::array<RootNeighbour, 4>{}},
                           [&](uint32_t c) { return c == 1 ? P : std::vector<glm::vec3>(17 * 17); });
    ADD_FAILURE() << "no error for a NaN position";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("chart 1"), std::string::npos) << e.what();
  }
  EXPECT_THROW(buildGeometryHierarchy(params(4, 6, 4, 1), {std::array<RootNeighbour, 4>{}},
                                      [&](uint32_t) { return std::vector<glm::vec3>(17 * 17); }),
               InputError);  // too deep for the chart
}

}  // namespace
}  // namespace gimlod

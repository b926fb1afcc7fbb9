// The geometry-image hierarchy (mesh atlases): errors and bounds against independent brute force,
// against the terrain hierarchy on a lifted height field, monotonicity, and bad input.
#include <gtest/gtest.h>

#include <cmath>

#include <glm/glm.hpp>

#include "hierarchy/hierarchy.h"
#include "tests/synthetic_terrain.h"

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

// Index lists of the reusable (u,v) grids: the strips draw exactly the triangles the error
// metric assumes, counter-clockwise. No GL.
#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include <glm/glm.hpp>

#include "runtime/grid_strips.h"

namespace gimlod {
namespace {

// Rotates a triangle so its smallest index comes first (keeps the winding).
Triangle canonical(Triangle t) {
  std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
  return t;
}

std::vector<Triangle> sortedCanonical(std::vector<Triangle> ts) {
  for (Triangle& t : ts) t = canonical(t);
  std::sort(ts.begin(), ts.end());
  return ts;
}

TEST(GridStrips, TriangleSetIsTheDiagonalSplit) {
  for (uint32_t res = 0; res <= 7; ++res) {
    for (uint32_t band : {1u, 3u, kStripBandQuads}) {
      const std::vector<uint32_t> idx = buildGridStripIndices(res, band);
      const auto tris = expandStrips(idx);
      const uint32_t side = (1u << res) + 1;
      EXPECT_EQ(tris.size(), size_t(2) << (2 * res)) << "res " << res << " band " << band;
      EXPECT_EQ(sortedCanonical(tris), sortedCanonical(expectedGridTriangles(res)))
          << "res " << res << " band " << band;
      std::vector<bool> used(size_t(side) * side, false);
      for (uint32_t i : idx) {
        if (i == kPrimitiveRestartIndex) continue;
        ASSERT_LT(i, used.size());
        used[i] = true;
      }
      EXPECT_EQ(std::count(used.begin(), used.end(), false), 0) << "res " << res;
    }
  }
}

TEST(GridStrips, ExpectedSetDistinguishesTheOtherDiagonal) {
  // The comparison above can fail: strips starting on the lower row split each quad along
  // (i+1,j)-(i,j+1) and must not match.
  const uint32_t res = 2, n = 4;
  std::vector<uint32_t> other;
  for (uint32_t j = 0; j < n; ++j) {
    if (!other.empty()) other.push_back(kPrimitiveRestartIndex);
    for (uint32_t i = 0; i <= n; ++i) {
      other.push_back(gridVertexIndex(res, i, j));
      other.push_back(gridVertexIndex(res, i, j + 1));
    }
  }
  const auto tris = expandStrips(other);
  EXPECT_EQ(tris.size(), size_t(32));
  EXPECT_NE(sortedCanonical(tris), sortedCanonical(expectedGridTriangles(res)));
}

TEST(GridStrips, StripsAreCounterClockwiseFromAbove) {
  const uint32_t res = 3, side = 9;
  for (const Triangle& t : expandStrips(buildGridStripIndices(res))) {
    auto xy = [&](uint32_t v) { return glm::ivec2(int(v % side), int(v / side)); };
    const glm::ivec2 a = xy(t[0]), b = xy(t[1]), c = xy(t[2]);
    const int cross = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    EXPECT_GT(cross, 0);
  }
}

}  // namespace
}  // namespace gimlod

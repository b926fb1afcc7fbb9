// The fidelity figure against cases with known answers.
#include <gtest/gtest.h>

#include <cmath>

#include "atlas/fidelity.h"

namespace gimlod {
namespace {

// An n x n grid over [0,1]^2 at height z (two triangles a cell).
void grid(uint32_t n, float z, std::vector<glm::vec3>& p, std::vector<std::array<uint32_t, 3>>& t) {
  p.clear();
  t.clear();
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) p.push_back({float(i) / n, float(j) / n, z});
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i, b = a + 1, c = b + n + 1, d = a + n + 1;
      t.push_back({a, b, c});
      t.push_back({a, c, d});
    }
}

TEST(Fidelity, KnownDistances) {
  std::vector<glm::vec3> p0, p1;
  std::vector<std::array<uint32_t, 3>> t0, t1;
  grid(4, 0.f, p0, t0);
  grid(16, 0.f, p1, t1);  // the same plane, finer: distance 0 both ways
  FidelityStats s = measureFidelity(p0, t0, p1, t1);
  EXPECT_NEAR(s.hausdorff, 0.0, 1e-7);
  EXPECT_NEAR(s.diagonal, std::sqrt(2.0), 1e-6);
  grid(16, 0.25f, p1, t1);  // lifted by 0.25
  s = measureFidelity(p0, t0, p1, t1);
  EXPECT_NEAR(s.hausdorff, 0.25, 1e-6);
  EXPECT_NEAR(s.meanAtlasToMesh, 0.25, 1e-6);
  EXPECT_NEAR(s.hausdorffPercent, 100.0 * 0.25 / std::sqrt(2.0), 1e-4);
  // One-sided: the atlas covers only half the mesh; the uncovered half is up to 0.5 away.
  std::vector<glm::vec3> half = p1;
  for (glm::vec3& q : half) q = {q.x * 0.5f, q.y, 0.f};
  s = measureFidelity(p0, t0, half, t1);
  EXPECT_NEAR(s.maxAtlasToMesh, 0.0, 1e-7);
  EXPECT_NEAR(s.maxMeshToAtlas, 0.5, 1e-6);
  EXPECT_THROW(measureFidelity(p0, {}, p1, t1), std::invalid_argument);
}

}  // namespace
}  // namespace gimlod

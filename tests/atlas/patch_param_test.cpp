// Tests for the n-gon patch parameterization: a flat square maps affinely (stretch 1), disks and
// hemisphere caps with 3, 5 and 8 sides embed without flips and with bounded stretch, the
// stretch reduction never makes things worse, its local sweeps run to convergence on a deep cup,
// and malformed patches are rejected.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>

#include "atlas/mesh/patch_param.h"
#include "tests/chart_layout_fixture.h"

namespace gimlod {
namespace {

// Signed area of the polygon's corner i, i+1 and the point: >= 0 when p is left of edge i.
double leftOf(const std::vector<glm::dvec2>& corners, uint32_t i, const glm::dvec2& p) {
  const glm::dvec2 a = corners[i], b = corners[(i + 1) % corners.size()];
  return (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
}

// The stretch energy computed another way, as the reference for gramStretchEnergy: from the map's
// Jacobian J = [ss st], its columns in 3D, with the gradient from their derivatives.
double jacobianStretchEnergy(const glm::dvec2 p[3], const glm::dvec3 q[3], double area3D, double k2, int moving = 0,
                             glm::dvec2* gradient = nullptr) {
  const double inf = std::numeric_limits<double>::infinity();
  const glm::dvec2 e1 = p[1] - p[0], e2 = p[2] - p[0];
  const double twice = e1.x * e2.y - e2.x * e1.y;
  if (!(twice > 1e-14 * (glm::dot(e1, e1) + glm::dot(e2, e2)))) return inf;
  // J = [ss st]: ss = sum q_i (y_{i+1} - y_{i+2}) / T, st = sum q_i (x_{i+2} - x_{i+1}) / T,
  // T = twice the parameter area.
  const glm::dvec3 ss = (q[0] * (p[1].y - p[2].y) + q[1] * (p[2].y - p[0].y) + q[2] * (p[0].y - p[1].y)) / twice;
  const glm::dvec3 st = (q[0] * (p[2].x - p[1].x) + q[1] * (p[0].x - p[2].x) + q[2] * (p[1].x - p[0].x)) / twice;
  // Derivatives of ss and st with respect to the moving point's x and y.
  glm::dvec3 ssx(0.0), ssy(0.0), stx(0.0), sty(0.0);
  if (gradient) {
    const int n1 = (moving + 1) % 3, n2 = (moving + 2) % 3;
    const double tx = p[n1].y - p[n2].y, ty = p[n2].x - p[n1].x;  // dT/dx, dT/dy
    ssx = -ss * (tx / twice);
    ssy = (q[n2] - q[n1]) / twice - ss * (ty / twice);
    stx = (q[n1] - q[n2]) / twice - st * (tx / twice);
    sty = -st * (ty / twice);
  }
  if (k2 > 0.0) {
    // Symmetric Dirichlet: tr(M) + tr(M^-1) of the scaled metric M = k^2 J^T J, which grows
    // without bound as a triangle is squeezed or spread in any direction (isometry: 4).
    const double a = glm::dot(ss, ss) * k2, b = glm::dot(ss, st) * k2, cc = glm::dot(st, st) * k2;
    const double det = a * cc - b * b;
    if (!(det > 0.0)) return inf;
    if (gradient) {
      auto d = [&](const glm::dvec3& sd, const glm::dvec3& td) {
        const double da = 2.0 * k2 * glm::dot(ss, sd), dc = 2.0 * k2 * glm::dot(st, td);
        const double db = k2 * (glm::dot(sd, st) + glm::dot(ss, td));
        const double ddet = da * cc + a * dc - 2.0 * b * db;
        return area3D * ((da + dc) * (1.0 + 1.0 / det) - (a + cc) * ddet / (det * det));
      };
      *gradient = glm::dvec2(d(ssx, stx), d(ssy, sty));
    }
    return area3D * ((a + cc) + (a + cc) / det);
  }
  if (gradient) {
    *gradient = area3D * glm::dvec2(glm::dot(ss, ssx) + glm::dot(st, stx), glm::dot(ss, ssy) + glm::dot(st, sty));
  }
  return area3D * 0.5 * (glm::dot(ss, ss) + glm::dot(st, st));
}

TEST(PatchParam, DomainPolygonFollowsSideLengths) {
  // Equal sides: the regular polygon.
  for (const uint32_t n : {3u, 5u, 8u}) {
    const std::vector<glm::dvec2> c = patchPolygon(std::vector<double>(n, 2.5));
    ASSERT_EQ(c.size(), n);
    for (uint32_t i = 0; i < n; ++i) {
      EXPECT_NEAR(c[i].x, polygonCorner(n, i).x, 1e-12);
      EXPECT_NEAR(c[i].y, polygonCorner(n, i).y, 1e-12);
    }
  }
  // Central angles in proportion to the lengths where no clamp applies: 1 : 1 : 1 : 1.5.
  auto angle = [](const glm::dvec2& a, const glm::dvec2& b) {
    return std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0));
  };
  std::vector<glm::dvec2> c = patchPolygon({1, 1, 1, 1.5});
  EXPECT_NEAR(angle(c[3], c[0]) / angle(c[0], c[1]), 1.5, 1e-9);
  EXPECT_NEAR(angle(c[1], c[2]), angle(c[0], c[1]), 1e-12);
  // Extreme lengths are clamped: every central angle below pi (convex, origin inside), every
  // corner on the unit circle, and the short sides keep 0.4 of the regular angle.
  for (const std::vector<double>& lengths : {std::vector<double>{100, 1, 1}, std::vector<double>{1, 1e-6, 1, 1e-6, 50},
                                             std::vector<double>{1, 2, 3, 4, 5, 6, 7, 200}}) {
    c = patchPolygon(lengths);
    const size_t n = lengths.size();
    double sum = 0.0;
    for (size_t i = 0; i < n; ++i) {
      EXPECT_NEAR(glm::length(c[i]), 1.0, 1e-12);
      const double a = angle(c[i], c[(i + 1) % n]);
      // Left turn at every corner, and the origin strictly left of every side.
      EXPECT_GT(leftOf(c, uint32_t(i), glm::dvec2(0.0)), 0.0);
      EXPECT_GE(a, 0.4 * 2.0 * std::numbers::pi / double(n) * (1 - 1e-9));
      sum += a;
    }
    EXPECT_NEAR(sum, 2.0 * std::numbers::pi, 1e-9);
  }
}

TEST(PatchParam, TriangleEnergyGradientMatchesDifferences) {
  // The local sweeps descend along the exact gradient: it must agree with central differences
  // of the energy, for both energies, whichever corner moves, on a skewed triangle in 3D.
  const glm::dvec3 q[3] = {{0.0, 0.0, 0.0}, {2.0, 0.3, 0.5}, {0.4, 1.5, -0.7}};
  const TriangleGram gram = triangleGram(q[0], q[1], q[2]);
  auto energy = [&](const glm::dvec2 p[3], double k2, int moving = 0, glm::dvec2* g = nullptr) {
    return gramStretchEnergy(gram, p[0], p[1], p[2], k2, moving, g);
  };
  for (const double k2 : {0.0, 0.37}) {
    for (int moving = 0; moving < 3; ++moving) {
      glm::dvec2 p[3] = {{0.1, 0.05}, {0.9, 0.2}, {0.3, 0.8}};
      glm::dvec2 g;
      const double e = energy(p, k2, moving, &g);
      ASSERT_TRUE(std::isfinite(e));
      EXPECT_EQ(e, energy(p, k2));  // the gradient does not change it
      const double h = 1e-6;
      glm::dvec2 fd;
      for (int axis = 0; axis < 2; ++axis) {
        glm::dvec2 plus[3] = {p[0], p[1], p[2]}, minus[3] = {p[0], p[1], p[2]};
        plus[moving][axis] += h;
        minus[moving][axis] -= h;
        fd[axis] = (energy(plus, k2) - energy(minus, k2)) / (2 * h);
      }
      EXPECT_NEAR(g.x, fd.x, 1e-6 * std::max(1.0, std::abs(fd.x))) << "k2 " << k2 << " corner " << moving;
      EXPECT_NEAR(g.y, fd.y, 1e-6 * std::max(1.0, std::abs(fd.y))) << "k2 " << k2 << " corner " << moving;
      EXPECT_GT(glm::length(g), 0.0);
    }
  }
  // A flipped triangle has no finite energy.
  const glm::dvec2 flipped[3] = {{0.0, 0.0}, {0.0, 1.0}, {1.0, 0.0}};
  EXPECT_TRUE(std::isinf(energy(flipped, 0.37)));
}

TEST(PatchParam, GramEnergyEqualsTheJacobianEnergy) {
  // The local sweeps' energy and gradient from the 3D edges' Gram matrix must be those of the
  // map's Jacobian, for both energies, on random triangles in 3D and in the plane (slivers included),
  // and infinite where the parameter triangle is flipped or flat.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 400; ++trial) {
    const glm::dvec3 q[3] = {
        {u(rng), u(rng), u(rng)}, {u(rng), u(rng), u(rng)}, {u(rng), u(rng), trial % 4 == 0 ? 0.0 : u(rng)}};
    glm::dvec2 p[3] = {{u(rng), u(rng)}, {u(rng), u(rng)}, {u(rng), u(rng)}};
    if (trial % 7 == 0) p[2] = p[0] + 1e-3 * (p[1] - p[0]) + glm::dvec2(1e-4 * u(rng), 1e-4 * u(rng));  // a sliver
    const TriangleGram g = triangleGram(q[0], q[1], q[2]);
    const double area = 0.5 * glm::length(glm::cross(q[1] - q[0], q[2] - q[0]));
    EXPECT_NEAR(g.area3D, area, 1e-12 * std::max(1.0, area));
    for (const double k2 : {0.0, 0.37, 2.5}) {
      const double reference = jacobianStretchEnergy(p, q, area, k2);
      const double gram = gramStretchEnergy(g, p[0], p[1], p[2], k2);
      if (std::isinf(reference)) {
        EXPECT_TRUE(std::isinf(gram)) << "trial " << trial << " k2 " << k2;
        continue;
      }
      EXPECT_NEAR(gram, reference, 1e-8 * std::abs(reference)) << "trial " << trial << " k2 " << k2;
      // And the gradient, whichever corner moves.
      for (int moving = 0; moving < 3; ++moving) {
        glm::dvec2 want, got;
        jacobianStretchEnergy(p, q, area, k2, moving, &want);
        EXPECT_EQ(gramStretchEnergy(g, p[0], p[1], p[2], k2, moving, &got), gram);
        const double scale = std::max(1e-12, glm::length(want));
        EXPECT_NEAR(got.x, want.x, 1e-7 * scale) << "trial " << trial << " k2 " << k2 << " corner " << moving;
        EXPECT_NEAR(got.y, want.y, 1e-7 * scale) << "trial " << trial << " k2 " << k2 << " corner " << moving;
      }
    }
  }
  const glm::dvec3 q0(0.0), q1(1.0, 0.0, 0.0), q2(0.0, 1.0, 0.0);
  const TriangleGram g = triangleGram(q0, q1, q2);
  // An isometry: symmetric Dirichlet 4 (k2 = 1) and L2 1, times the area.
  EXPECT_NEAR(gramStretchEnergy(g, {0, 0}, {1, 0}, {0, 1}, 1.0), 4.0 * 0.5, 1e-12);
  EXPECT_NEAR(gramStretchEnergy(g, {0, 0}, {1, 0}, {0, 1}, 0.0), 1.0 * 0.5, 1e-12);
  EXPECT_TRUE(std::isinf(gramStretchEnergy(g, {0, 0}, {0, 1}, {1, 0}, 1.0)));
  EXPECT_TRUE(std::isinf(gramStretchEnergy(g, {0, 0}, {1, 0}, {2, 0}, 0.0)));
}

TEST(PatchParam, MeasureStretchOfKnownMaps) {
  // Parameter triangle (0,0), (1,0), (0,1) onto (0,0,0), (2,0,0), (0,1,0): Jacobian diag(2, 1).
  const std::vector<glm::dvec2> uv{{0, 0}, {1, 0}, {0, 1}};
  const std::vector<glm::dvec3> xyz{{0, 0, 0}, {2, 0, 0}, {0, 1, 0}};
  ParamQuality q = measureStretch(uv, xyz, {{0, 1, 2}});
  // Raw L2 = sqrt((4 + 1) / 2), Linf = 2; normalized by sqrt(area3D / areaParam) = sqrt(2).
  EXPECT_NEAR(q.stretchL2, std::sqrt(2.5) / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(q.stretchLinf, 2.0 / std::sqrt(2.0), 1e-12);
  EXPECT_EQ(q.flippedTriangles, 0u);
  // A similarity has stretch 1; the reversed triangle is flipped; a collinear one degenerate.
  const std::vector<glm::dvec3> sim{{1, 1, 1}, {1, 4, 1}, {1, 1, 4}};
  EXPECT_NEAR(measureStretch(uv, sim, {{0, 1, 2}}).stretchL2, 1.0, 1e-12);
  EXPECT_NEAR(measureStretch(uv, sim, {{0, 1, 2}}).stretchLinf, 1.0, 1e-12);
  q = measureStretch(uv, sim, {{0, 2, 1}});
  EXPECT_EQ(q.flippedTriangles, 1u);
  const std::vector<glm::dvec2> line{{0, 0}, {1, 0}, {2, 0}};
  EXPECT_EQ(measureStretch(line, sim, {{0, 1, 2}}).degenerateTriangles, 1u);
}

TEST(PatchParam, FlatSquareIsAffine) {
  const PatchLayout layout = test::gridLayout(10, 10, 2.f, 2.f);
  const PatchParameterization pp = parameterizePatch(layout, 0);
  ASSERT_EQ(pp.sides, 4u);
  ASSERT_EQ(pp.uv.size(), layout.positions.size());
  // Grid corners (0,0), (2,0), (2,2), (0,2) go to polygon corners 0..3: the affine map
  // x -> c0 + x/2 (c1 - c0) + y/2 (c3 - c0).
  const glm::dvec2 c0 = polygonCorner(4, 0), c1 = polygonCorner(4, 1), c3 = polygonCorner(4, 3);
  for (size_t k = 0; k < pp.vertices.size(); ++k) {
    const glm::vec3 x = layout.positions[pp.vertices[k]];
    const glm::dvec2 expect = c0 + double(x.x) / 2 * (c1 - c0) + double(x.y) / 2 * (c3 - c0);
    EXPECT_NEAR(pp.uv[k].x, expect.x, 1e-9);
    EXPECT_NEAR(pp.uv[k].y, expect.y, 1e-9);
  }
  EXPECT_NEAR(pp.quality.stretchL2, 1.0, 1e-6);
  EXPECT_NEAR(pp.quality.stretchLinf, 1.0, 1e-6);
  EXPECT_EQ(pp.quality.flippedTriangles, 0u);
  EXPECT_EQ(pp.quality.degenerateTriangles, 0u);
  EXPECT_EQ(pp.boundary.size(), 40u);
  EXPECT_EQ(pp.cornerIndex, (std::vector<uint32_t>{0, 10, 20, 30}));
}

// A large patch's mean-value system is factored in single precision and refined with
// double-precision residuals: on a flat patch, which the weights map affinely, the solve alone (no
// reweighting, no sweeps) is as exact as a double factorization. A single-precision solve
// unrefined is off by about 1e-7 here.
TEST(PatchParam, TheSolveIsExactToDoublePrecision) {
  const PatchLayout layout = test::gridLayout(80, 80, 2.f, 2.f);
  ParamOptions o;
  o.stretchIterations = 0;
  o.stretchSweeps = 0;
  o.singlePrecisionFrom = 0;
  const PatchParameterization pp = parameterizePatch(layout, 0, o);
  ASSERT_EQ(pp.sides, 4u);
  const glm::dvec2 c0 = polygonCorner(4, 0), c1 = polygonCorner(4, 1), c3 = polygonCorner(4, 3);
  double worst = 0.0;
  for (size_t k = 0; k < pp.vertices.size(); ++k) {
    const glm::vec3 x = layout.positions[pp.vertices[k]];
    const glm::dvec2 expect = c0 + double(x.x) / 2 * (c1 - c0) + double(x.y) / 2 * (c3 - c0);
    worst = std::max(worst, glm::length(pp.uv[k] - expect));
  }
  EXPECT_LT(worst, 1e-12);
  EXPECT_EQ(pp.initial.flippedTriangles, 0u);
}

TEST(PatchParam, NGonDisksEmbedWithoutFlips) {
  for (const bool hemisphere : {false, true}) {
    for (const uint32_t n : {3u, 5u, 8u}) {
      SCOPED_TRACE(testing::Message() << "n=" << n << " hemisphere=" << hemisphere);
      const PatchLayout layout = test::diskLayout(n, 12, 48, hemisphere);
      const PatchParameterization pp = parameterizePatch(layout, 0);
      EXPECT_EQ(pp.quality.flippedTriangles, 0u);
      EXPECT_EQ(pp.quality.degenerateTriangles, 0u);
      EXPECT_EQ(pp.initial.flippedTriangles, 0u);
      EXPECT_TRUE(std::isfinite(pp.quality.stretchL2));
      EXPECT_GE(pp.quality.stretchL2, 1.0 - 1e-9);
      EXPECT_LT(pp.quality.stretchL2, 1.5);
      EXPECT_LT(pp.quality.stretchLinf, 4.0);
      EXPECT_LE(pp.quality.stretchL2, pp.initial.stretchL2);
      // Corners on the polygon's vertices, every vertex inside the polygon.
      ASSERT_EQ(pp.corners.size(), n);
      for (uint32_t i = 0; i < n; ++i) {
        const glm::dvec2 c = pp.uv[pp.boundary[pp.cornerIndex[i]]];
        EXPECT_EQ(c, pp.corners[i]);
      }
      for (const glm::dvec2& p : pp.uv) {
        for (uint32_t i = 0; i < n; ++i) EXPECT_GE(leftOf(pp.corners, i, p), -1e-12);
      }
      std::printf("  n=%u %s: L2 %.4f -> %.4f, Linf %.4f -> %.4f (%u reweightings, %u sweeps)\n", n,
                  hemisphere ? "hemisphere" : "flat disk", pp.initial.stretchL2, pp.quality.stretchL2,
                  pp.initial.stretchLinf, pp.quality.stretchLinf, pp.iterationsUsed, pp.sweepsUsed);
    }
  }
}

// A deep lopsided cup: a flat unit disc (the disk layout's r <= 0.5) closed round by a tube whose
// length grows from 0.8 on one side to 15.2 on the other (r > 0.5), like a hoof's sole and wall
// cut off at a slant. Far from developable: the sole's area has to be moved across the whole
// patch, which the local sweeps do a ring at a time.
PatchLayout lopsidedCup(uint32_t rings) {
  PatchLayout layout = test::diskLayout(6, rings, 4 * rings, false);
  for (glm::vec3& p : layout.positions) {
    const double r = std::hypot(double(p.x), double(p.y)), theta = std::atan2(double(p.y), double(p.x));
    if (r <= 0.5) {
      p = glm::vec3(glm::dvec3(2.0 * r * std::cos(theta), 2.0 * r * std::sin(theta), 0.0));
    } else {
      const double length = 8.0 * (1.0 + 0.9 * std::cos(theta));
      p = glm::vec3(glm::dvec3(std::cos(theta), std::sin(theta), (r - 0.5) / 0.5 * length));
    }
  }
  return layout;
}

TEST(PatchParam, LocalSweepsRunToConvergenceOnACup) {
  const PatchLayout layout = lopsidedCup(30);
  const PatchParameterization full = parameterizePatch(layout, 0);
  ParamOptions capped;
  capped.stretchSweeps = 30;  // the earlier default
  const PatchParameterization cut = parameterizePatch(layout, 0, capped);
  std::printf("  cup: L2 %.4f (%u sweeps), cut at 30 sweeps %.4f; Linf %.4f, %.4f\n", full.quality.stretchL2,
              full.sweepsUsed, cut.quality.stretchL2, full.quality.stretchLinf, cut.quality.stretchLinf);
  EXPECT_EQ(cut.sweepsUsed, 30u);
  // The default's cap is not what stops it: the energy stops dropping (measured: 161 sweeps).
  EXPECT_GT(full.sweepsUsed, 30u);
  EXPECT_LT(full.sweepsUsed, ParamOptions{}.stretchSweeps);
  EXPECT_LT(full.quality.stretchL2, cut.quality.stretchL2);
  EXPECT_EQ(full.quality.flippedTriangles, 0u);
}

TEST(PatchParam, StretchReductionIsOptional) {
  const PatchLayout layout = test::diskLayout(4, 10, 40, true);
  ParamOptions off;
  off.stretchIterations = 0;
  off.stretchSweeps = 0;
  const PatchParameterization a = parameterizePatch(layout, 0, off);
  EXPECT_EQ(a.iterationsUsed, 0u);
  EXPECT_EQ(a.sweepsUsed, 0u);
  EXPECT_EQ(a.quality.stretchL2, a.initial.stretchL2);
  const PatchParameterization b = parameterizePatch(layout, 0);
  EXPECT_EQ(b.initial.stretchL2, a.initial.stretchL2);
  EXPECT_LE(b.quality.stretchL2, a.quality.stretchL2);
  EXPECT_EQ(b.quality.flippedTriangles, 0u);
}

TEST(PatchParam, RejectsMalformedPatches) {
  const PatchLayout good = test::gridLayout(4, 4, 1.f, 1.f);
  EXPECT_NO_THROW(parameterizePatch(good, 0));
  EXPECT_THROW(parameterizePatch(good, 1), std::invalid_argument);

  PatchLayout twoSides = good;  // merge sides 0 and 1 and sides 2 and 3
  auto& s = twoSides.patches[0].sides;
  s[0].vertices.insert(s[0].vertices.end(), s[1].vertices.begin() + 1, s[1].vertices.end());
  s[2].vertices.insert(s[2].vertices.end(), s[3].vertices.begin() + 1, s[3].vertices.end());
  s = {s[0], s[2]};
  EXPECT_THROW(parameterizePatch(twoSides, 0), std::invalid_argument);

  PatchLayout broken = good;  // side 1 no longer starts where side 0 ends
  broken.patches[0].sides[1].vertices.erase(broken.patches[0].sides[1].vertices.begin());
  EXPECT_THROW(parameterizePatch(broken, 0), std::invalid_argument);

  PatchLayout reversed = good;  // sides listed clockwise
  for (auto& side : reversed.patches[0].sides) std::reverse(side.vertices.begin(), side.vertices.end());
  std::reverse(reversed.patches[0].sides.begin(), reversed.patches[0].sides.end());
  EXPECT_THROW(parameterizePatch(reversed, 0), std::invalid_argument);

  PatchLayout holed = good;  // an annulus: the centre cell's two triangles removed
  auto& tris = holed.patches[0].triangles;
  tris.erase(tris.begin() + 2 * (1 * 4 + 1), tris.begin() + 2 * (1 * 4 + 1) + 2);
  EXPECT_THROW(parameterizePatch(holed, 0), std::invalid_argument);

  PatchLayout zero = good;  // a side of zero length
  for (uint32_t v : zero.patches[0].sides[0].vertices) zero.positions[v] = {0.f, 0.f, 0.f};
  EXPECT_THROW(parameterizePatch(zero, 0), std::invalid_argument);
}

TEST(PatchParam, CombineQualityWeightsByArea) {
  ParamQuality a, b;
  a.stretchL2 = 1.0, a.stretchLinf = 1.5, a.area3D = 3.0, a.flippedTriangles = 1;
  b.stretchL2 = 2.0, b.stretchLinf = 3.0, b.area3D = 1.0, b.degenerateTriangles = 2;
  const ParamQuality c = combineQuality({a, b});
  EXPECT_NEAR(c.stretchL2, std::sqrt((3.0 * 1.0 + 1.0 * 4.0) / 4.0), 1e-12);
  EXPECT_EQ(c.stretchLinf, 3.0);
  EXPECT_EQ(c.flippedTriangles, 1u);
  EXPECT_EQ(c.degenerateTriangles, 2u);
}

}  // namespace
}  // namespace gimlod

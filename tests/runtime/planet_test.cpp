// The planet lattice (core/planet.h) and horizon culling (runtime/camera.h), on the CPU.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <numbers>
#include <random>

#include "core/planet.h"
#include "runtime/camera.h"

namespace gimlod {
namespace {

bool sameBits(const glm::dvec3& a, const glm::dvec3& b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// A whole planet of 1-degree cells, cell-centred, with pole rows added (as atlas/terrain/planet_grid.h lays a
// cell-centred DEM).
PlanetInfo wholeDegrees() {
  PlanetInfo p;
  p.present = true;
  p.lon0Deg = -179.5;
  p.lat0Deg = -90.5;
  p.dlonDeg = 1.0;
  p.dlatDeg = 1.0;
  p.wrapColumns = 360;
  return p;
}

TEST(PlanetFrame, TheAntimeridianAndThePolesAreSharedSamples) {
  const PlanetFrame f(wholeDegrees(), 361, 182);
  for (int64_t y = 0; y < 182; ++y) EXPECT_TRUE(sameBits(f.position(0, y, 100.0), f.position(360, y, 100.0))) << y;
  for (int64_t x = 1; x < 361; ++x) {
    EXPECT_TRUE(sameBits(f.position(x, 0, -4000.0), f.position(0, 0, -4000.0))) << x;
    EXPECT_TRUE(sameBits(f.position(x, 181, 2500.0), f.position(0, 181, 2500.0))) << x;
  }
  EXPECT_EQ(f.position(17, 0, 0.0), glm::dvec3(0.0, 0.0, -kEarthRadius));
  EXPECT_EQ(f.position(17, 181, 0.0), glm::dvec3(0.0, 0.0, kEarthRadius));
  // Padding past the last row and column folds onto them.
  EXPECT_TRUE(sameBits(f.position(400, 300, 1.0), f.position(0, 181, 1.0)));
  EXPECT_EQ(f.pole(0), -1);
  EXPECT_EQ(f.pole(1), 0);
  EXPECT_EQ(f.pole(180), 0);
  EXPECT_EQ(f.pole(181), 1);
  // The sample under a point is the one it came from.
  std::mt19937 rng(7);
  for (int i = 0; i < 200; ++i) {
    const int64_t x = rng() % 360, y = 1 + rng() % 180;
    const auto g = f.sampleUnder(f.position(x, y, 3000.0));
    EXPECT_EQ(g[0], x);
    EXPECT_EQ(g[1], y);
  }
}

TEST(PlanetFrame, ARegionalLatticeNeitherWrapsNorReachesAPole) {
  PlanetInfo p;
  p.present = true;
  p.lon0Deg = -122.0;
  p.lat0Deg = 46.0;
  p.dlonDeg = p.dlatDeg = 1.0 / 1200.0;
  const PlanetFrame f(p, 1201, 1201);
  EXPECT_EQ(f.southPoleRow(), -1);
  EXPECT_EQ(f.northPoleRow(), INT32_MAX);
  EXPECT_EQ(f.column(1300), 1200);
  EXPECT_NEAR(f.longitude(1200) * 180.0 / std::numbers::pi, -121.0, 1e-9);
  EXPECT_NEAR(f.latitude(600) * 180.0 / std::numbers::pi, 46.5, 1e-9);
}

// The largest difference between planetOffset (float, as the vertex shader computes it) and the
// double-precision offset, over samples within `reach` of the anchor; and the same for plain
// float32 planet-centred positions (the control).
struct OffsetErrors {
  double relative = 0.0;  // metres, over the offset's length plus a metre
  double absolute = 0.0, control = 0.0;
};
OffsetErrors offsetErrors(const PlanetFrame& f, int64_t ax, int64_t ay, int64_t reach) {
  const PlanetAnchor a = planetAnchor(f, ax, ay);
  OffsetErrors e;
  std::mt19937 rng(11);
  for (int i = 0; i < 4000; ++i) {
    const int64_t x = ax + int64_t(rng() % (2 * reach + 1)) - reach, y = ay + int64_t(rng() % (2 * reach + 1)) - reach;
    const float h = float(int(rng() % 9000) - 500) + 0.25f;
    const glm::dvec3 exact = f.position(x, y, h) - a.position;
    const double err = glm::length(glm::dvec3(planetOffset(f, a, x, y, h)) - exact);
    e.absolute = std::max(e.absolute, err);
    e.relative = std::max(e.relative, err / (glm::length(exact) + 1.0));
    const glm::dvec3 plain = glm::dvec3(glm::vec3(f.position(x, y, h)) - glm::vec3(a.position));
    e.control = std::max(e.control, glm::length(plain - exact));
  }
  return e;
}

// One arc-second samples (31 m) round a planet of `radius` and `flattening`, cell-centred, with pole
// rows: 1,296,000 columns a turn and 648,002 rows.
PlanetInfo arcSecondPlanet(double radius, double flattening) {
  PlanetInfo p = wholeDegrees();
  p.radius = radius;
  p.flattening = flattening;
  p.dlonDeg = p.dlatDeg = 1.0 / 3600.0;
  p.lon0Deg = -180.0 + 0.5 * p.dlonDeg;
  p.lat0Deg = -90.0 - 0.5 * p.dlatDeg;
  p.wrapColumns = 360 * 3600;
  return p;
}
constexpr uint32_t kArcSecondRows = 180 * 3600 + 2;

// Offsets of a few kilometres keep millimetres round anchors by the antimeridian, the poles and
// elsewhere, where planet-centred float32 positions are off by decimetres; far from the anchor the
// error stays a small fraction of the distance.
void expectExactNearTheAnchor(const PlanetFrame& f) {
  const uint32_t rows = kArcSecondRows;
  for (const auto& [ax, ay] : {std::array<int64_t, 2>{500000, 300000},
                               {1296000 - 3, 400000},
                               {2, 100000},
                               {777777, rows - 40},
                               {123456, 30},
                               {40000, 324001}}) {
    const OffsetErrors e = offsetErrors(f, ax, ay, 100);
    EXPECT_LT(e.absolute, 2e-3) << ax << ", " << ay;
    EXPECT_LT(e.relative, 1e-6) << ax << ", " << ay;
    EXPECT_GT(e.control, 0.05) << ax << ", " << ay;
  }
  EXPECT_LT(offsetErrors(f, 500000, 300000, 200000).relative, 1e-6);
}

TEST(PlanetOffset, ExactNearTheAnchorAtThePlanetsScale) {
  const PlanetInfo p = arcSecondPlanet(kEarthRadius, 0.0);
  expectExactNearTheAnchor(PlanetFrame(p, p.wrapColumns + 1, kArcSecondRows));
}

// The same lattice on the WGS84 ellipsoid: the offsets' own terms (the radius of curvature's and
// the polar shift's differences) keep millimetres too; and the ellipsoid is not the sphere (its
// positions differ by kilometres away from the equator).
TEST(PlanetOffset, ExactNearTheAnchorOnTheWgs84Ellipsoid) {
  const PlanetInfo p = arcSecondPlanet(kEllipsoids[0].radius, kEllipsoids[0].flattening);
  const uint32_t rows = kArcSecondRows;
  const PlanetFrame f(p, p.wrapColumns + 1, rows);
  expectExactNearTheAnchor(f);
  PlanetInfo sphere = p;
  sphere.flattening = 0.0;
  const PlanetFrame s(sphere, p.wrapColumns + 1, rows);
  EXPECT_GT(glm::length(f.position(1000, 500000, 0.0) - s.position(1000, 500000, 0.0)), 1.0e4);
  // Poles and the antimeridian still share their samples, and a sample is found under its point.
  for (int64_t y : {int64_t(0), int64_t(rows - 1)})
    for (int64_t x : {int64_t(0), int64_t(12345), int64_t(p.wrapColumns)})
      EXPECT_TRUE(sameBits(f.position(x, y, 50.0), f.position(0, y, 50.0))) << x << ", " << y;
  EXPECT_TRUE(sameBits(f.position(0, 300000, 7.0), f.position(p.wrapColumns, 300000, 7.0)));
  EXPECT_NEAR(f.position(0, rows - 1, 0.0).z, p.polarRadius(), 1e-6);
  std::mt19937 rng(5);
  for (int i = 0; i < 200; ++i) {
    const int64_t x = rng() % p.wrapColumns, y = 1 + rng() % (rows - 2);
    const auto g = f.sampleUnder(f.position(x, y, 0.0));
    EXPECT_EQ(g[0], x);
    EXPECT_EQ(g[1], y);
  }
}

// A frustum that contains everything, so that only the horizon culls.
Frustum everything() {
  Frustum f;
  for (glm::dvec4& p : f.planes) p = {0.0, 0.0, 0.0, 1.0};
  return f;
}

glm::dvec3 boxLo(const glm::dvec3& c, double r) { return c - glm::dvec3(r); }
glm::dvec3 boxHi(const glm::dvec3& c, double r) { return c + glm::dvec3(r); }

TEST(HorizonCulling, BoxesBehindThePlanetAreCulledAndTheOthersKept) {
  const double R = 6.371e6;
  Frustum f = everything();
  f.setHorizon({2.0 * R, 0.0, 0.0}, R);
  // Under the eye: in front of the horizon.
  EXPECT_EQ(f.classify(boxLo({R, 0, 0}, 1e4), boxHi({R, 0, 0}, 1e4)), 2);
  // The far side: hidden.
  EXPECT_FALSE(f.intersects(boxLo({-R, 0, 0}, 1e5), boxHi({-R, 0, 0}, 1e5)));
  EXPECT_EQ(f.classify(boxLo({-R, 0, 0}, 1e5), boxHi({-R, 0, 0}, 1e5)), 0);
  // Beyond the limb but high above the planet: seen past it.
  EXPECT_TRUE(f.intersects(boxLo({-0.2 * R, 1.5 * R, 0}, 1e4), boxHi({-0.2 * R, 1.5 * R, 0}, 1e4)));
  // On the limb (the horizon's circle lies at x = R / 2): kept.
  const glm::dvec3 limb{0.5 * R, R * std::sqrt(0.75), 0.0};
  EXPECT_TRUE(f.intersects(boxLo(limb, 1e3), boxHi(limb, 1e3)));
  // Without a horizon nothing is culled; inside the sphere neither.
  EXPECT_TRUE(everything().intersects(boxLo({-R, 0, 0}, 1e5), boxHi({-R, 0, 0}, 1e5)));
  Frustum inside = everything();
  inside.setHorizon({0.5 * R, 0, 0}, R);
  EXPECT_TRUE(inside.intersects(boxLo({-R, 0, 0}, 1e5), boxHi({-R, 0, 0}, 1e5)));
}

TEST(HorizonCulling, ABoxInsideAClassifiedBoxHasItsClass) {
  const double R = 6.371e6;
  Frustum f = everything();
  f.setHorizon({0.3 * R, 1.4 * R, 0.2 * R}, R);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.2 * R, 1.2 * R), size(1e3, 2e6), t(0.0, 1.0);
  uint32_t seen[3] = {0, 0, 0};
  for (int i = 0; i < 3000; ++i) {
    const glm::dvec3 c{u(rng), u(rng), u(rng)}, r{size(rng), size(rng), size(rng)};
    const int k = f.classify(c - r, c + r);
    ++seen[k];
    if (k == 1) continue;
    for (int j = 0; j < 8; ++j) {
      const glm::dvec3 a{t(rng), t(rng), t(rng)}, b{t(rng), t(rng), t(rng)};
      const glm::dvec3 lo = c - r + 2.0 * r * glm::min(a, b), hi = c - r + 2.0 * r * glm::max(a, b);
      EXPECT_EQ(f.classify(lo, hi), k);
    }
  }
  EXPECT_GT(seen[0], 50u);
  EXPECT_GT(seen[2], 50u);
}

}  // namespace
}  // namespace gimlod

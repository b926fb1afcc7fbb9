// The hierarchy of a planet atlas bounds the drawn surface on the sphere: every node's error at
// every resolution is at least the distance, measured in double precision, from each of its samples
// to its grid drawn at that resolution; every box holds its samples. Charts measured whole and in
// tiles alike, and tiles keep the precision of their own extent.
#include <gtest/gtest.h>

#include <cmath>

#include "hierarchy/hierarchy.h"

namespace gimlod {
namespace {

constexpr uint32_t kM = 32;  // chart intervals

// A whole planet of 64 columns a turn (5.625 degrees) and 34 rows, the first and last on the poles,
// in 2 x 2 charts of 33 samples; heights with kilometres of relief.
struct TinyPlanet {
  AtlasManifest m;
  std::vector<float> heights;  // samplesX x samplesY
  TinyPlanet(double radius, double flattening = 0.0) {
    m.chartSize = kM + 1;
    m.blockIntervals = 16;
    m.depth = 3;
    m.maxNodeResLog2 = 4;
    m.minNodeResLog2 = 1;
    m.samplesX = 65;
    m.samplesY = 34;
    m.chartsX = 2;
    m.chartsY = 2;
    m.planet.present = true;
    m.planet.radius = radius;
    m.planet.flattening = flattening;
    m.planet.wrapColumns = 64;
    m.planet.dlonDeg = 5.625;
    m.planet.dlatDeg = 180.0 / 33.0;
    m.planet.lon0Deg = -180.0;
    m.planet.lat0Deg = -90.0;
    for (uint32_t y = 0; y < 2; ++y)
      for (uint32_t x = 0; x < 2; ++x) {
        ChartInfo c;
        c.id = y * 2 + x;
        c.gridX = int32_t(x);
        c.gridY = int32_t(y);
        c.neighbours[kEdgeRight] = {int32_t(y * 2 + 1 - x), uint8_t(kEdgeLeft), true};
        c.neighbours[kEdgeLeft] = {int32_t(y * 2 + 1 - x), uint8_t(kEdgeRight), true};
        c.neighbours[kEdgeTop] = y == 0 ? RootNeighbour{int32_t(2 + x), uint8_t(kEdgeBottom), true} : RootNeighbour{};
        c.neighbours[kEdgeBottom] = y == 1 ? RootNeighbour{int32_t(x), uint8_t(kEdgeTop), true} : RootNeighbour{};
        m.charts.push_back(c);
      }
    heights.resize(size_t(m.samplesX) * m.samplesY);
    for (uint32_t y = 0; y < m.samplesY; ++y)
      for (uint32_t x = 0; x < m.samplesX; ++x) {
        const uint32_t c = x % 64;
        float h = float(3000.0 * std::sin(0.7 * c) * std::cos(0.45 * y) + 2500.0 * std::sin(1.9 * c + 0.3 * y));
        if (y == 0 || y + 1 == m.samplesY) h = y == 0 ? -4000.0f : 2800.0f;  // uniform pole rows
        heights[size_t(y) * m.samplesX + x] = h;
      }
    for (uint32_t y = 0; y < m.samplesY; ++y) height(64, y) = height(0, y);  // the wrap column
  }
  float& height(int64_t x, int64_t y) { return heights[size_t(y) * m.samplesX + size_t(x)]; }
  float clamped(int64_t x, int64_t y) {
    return height(std::clamp<int64_t>(x, 0, m.samplesX - 1), std::clamp<int64_t>(y, 0, m.samplesY - 1));
  }
  ChartWindowSource source() {
    return [this](uint32_t c, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n) {
      std::vector<float> out(size_t(n + 1) * (n + 1));
      const ChartInfo& ch = m.charts[c];
      for (uint32_t v = 0; v <= n; ++v)
        for (uint32_t u = 0; u <= n; ++u)
          out[size_t(v) * (n + 1) + u] = clamped(int64_t(ch.gridX) * kM + (int64_t(u0 + u) << level),
                                                 int64_t(ch.gridY) * kM + (int64_t(v0 + v) << level));
      return out;
    };
  }
};

// maxTile: the hierarchy's tiles (kM or more: each chart whole).
void checkBounds(double radius, double flattening = 0.0, uint32_t maxTile = kHierarchyTile) {
  TinyPlanet t(radius, flattening);
  const Hierarchy h = buildPlanetHierarchy(t.m, t.source(), nullptr, maxTile);
  const PlanetFrame frame(t.m.planet, t.m.samplesX, t.m.samplesY);
  const HierarchyParams& p = h.params;
  uint64_t checked = 0, tight = 0, empty = 0;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const ChartInfo& ch = t.m.charts[c];
    auto P = [&](int64_t u, int64_t v) {  // chart sample (u, v), planet-centred
      const int64_t gx = int64_t(ch.gridX) * kM + u, gy = int64_t(ch.gridY) * kM + v;
      return frame.position(gx, gy, t.clamped(gx, gy));
    };
    for (uint32_t l = 0; l < p.depth; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) {
          const NodeId n{c, l, x, y};
          const uint32_t size = kM >> l;
          // Past the last row: never drawn. Measured whole, a chart's boxes and errors still cover
          // its padding (the clamped last row); in tiles, a tile wholly past it is not read.
          const bool past = int64_t(ch.gridY) * kM + int64_t(y * size) >= int64_t(t.m.samplesY) - 1;
          EXPECT_EQ(past, (h.flags(n) & kNodeEmpty) != 0);
          empty += past;
          if (past && maxTile < kM) continue;
          const auto& b = h.bounds(n);
          for (uint32_t v = 0; v <= size; ++v)
            for (uint32_t u = 0; u <= size; ++u) {
              const glm::dvec3 q = P(x * size + u, y * size + v);
              for (int k = 0; k < 3; ++k) {
                EXPECT_LE(double(b[k]), q[k]);
                EXPECT_GE(double(b[3 + k]), q[k]);
              }
            }
          for (uint32_t r = p.minNodeResLog2; r <= h.maxResLog2(n); ++r) {
            const uint32_t s = size >> r;  // level-0 intervals between the grid's vertices
            double worst = 0.0;
            for (uint32_t v = 0; v <= size; ++v)
              for (uint32_t u = 0; u <= size; ++u) {
                const uint32_t cx = std::min(u / s, (1u << r) - 1), cy = std::min(v / s, (1u << r) - 1);
                const float fx = float(u - cx * s) / float(s), fy = float(v - cy * s) / float(s);
                auto corner = [&](uint32_t i, uint32_t j) { return P(x * size + i * s, y * size + j * s); };
                // The grid's triangles split along (0,0)-(1,1), as cellSurface and the renderer.
                const glm::dvec3 h00 = corner(cx, cy), h10 = corner(cx + 1, cy), h01 = corner(cx, cy + 1),
                                 h11 = corner(cx + 1, cy + 1);
                const double dx = fx, dy = fy;
                const glm::dvec3 drawn =
                    dx >= dy ? h00 + dx * (h10 - h00) + dy * (h11 - h10) : h00 + dy * (h01 - h00) + dx * (h11 - h01);
                worst = std::max(worst, glm::length(drawn - P(x * size + u, y * size + v)));
              }
            const double stored = h.error(n, r);
            EXPECT_GE(stored, worst - 1e-6) << "chart " << c << " node " << l << "," << x << "," << y << " res " << r;
            tight += stored <= 1.01 * worst + 1.0;
            ++checked;
          }
        }
  }
  EXPECT_GT(checked, 100u);
  EXPECT_GT(empty, 0u);
  // The bound is the measure itself, not a loose one: most are within 1% of it.
  EXPECT_GT(tight, checked / 2);
}

TEST(PlanetHierarchy, ErrorsBoundTheDrawnSurfaceOnTheSphere) { checkBounds(kEarthRadius); }

TEST(PlanetHierarchy, ErrorsBoundTheDrawnSurfaceOnASmallPlanet) { checkBounds(1.5e5); }

TEST(PlanetHierarchy, ErrorsBoundTheDrawnSurfaceOnTheWgs84Ellipsoid) {
  checkBounds(kEllipsoids[0].radius, kEllipsoids[0].flattening);
}

// A small planet flattened as much as a planet may be (kMaxPlanetFlattening; Saturn's is 0.098).
TEST(PlanetHierarchy, ErrorsBoundTheDrawnSurfaceOnAFlattenedPlanet) { checkBounds(1.5e5, kMaxPlanetFlattening); }

// In tiles of 8 intervals (each leaf a tile: the levels above come from the tiles' summaries, and
// the coarse levels' cells span several tiles), of 16 (leaves inside a tile) and of 4 (every node
// above its tiles); the second row of charts has tiles wholly past the last row.
TEST(PlanetHierarchy, TiledErrorsBoundTheDrawnSurfaceOnTheSphere) {
  for (const uint32_t tile : {4u, 8u, 16u}) {
    SCOPED_TRACE(tile);
    checkBounds(kEarthRadius, 0.0, tile);
  }
}

TEST(PlanetHierarchy, TiledErrorsBoundTheDrawnSurfaceOnAFlattenedPlanet) {
  checkBounds(1.5e5, kMaxPlanetFlattening, 8);
}

// A regional planet of one chart of 513 samples 0.002 degrees apart (about 114 km across) with
// metres of relief: measured in tiles of 16 intervals, every error of a resolution whose cells lie
// within a tile is within 2 mm of the exact one (the float steps of a tile's 2.5 km); measured whole,
// the float steps of the chart's extent add centimetres to every one.
TEST(PlanetHierarchy, TilesKeepTheirOwnPrecisionInALargeChart) {
  constexpr uint32_t M = 512;
  AtlasManifest m;
  m.chartSize = M + 1;
  m.blockIntervals = 16;
  m.depth = 3;
  m.maxNodeResLog2 = 7;
  m.minNodeResLog2 = 1;
  m.samplesX = m.samplesY = M + 1;
  m.chartsX = m.chartsY = 1;
  m.planet.present = true;
  m.planet.dlonDeg = m.planet.dlatDeg = 0.002;
  m.planet.lon0Deg = 10.0;
  m.planet.lat0Deg = 30.0;
  ChartInfo chart;
  m.charts.push_back(chart);
  std::vector<float> heights(size_t(M + 1) * (M + 1));
  for (uint32_t y = 0; y <= M; ++y)
    for (uint32_t x = 0; x <= M; ++x)
      heights[size_t(y) * (M + 1) + x] =
          float(300.0 + 40.0 * std::sin(0.05 * x) * std::cos(0.031 * y) + 3.0 * std::sin(0.9 * x + 0.7 * y));
  const ChartWindowSource source = [&](uint32_t, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n) {
    std::vector<float> out(size_t(n + 1) * (n + 1));
    for (uint32_t v = 0; v <= n; ++v)
      for (uint32_t u = 0; u <= n; ++u)
        out[size_t(v) * (n + 1) + u] = heights[size_t((v0 + v) << level) * (M + 1) + ((u0 + u) << level)];
    return out;
  };
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  std::vector<glm::dvec3> P(heights.size());
  for (uint32_t y = 0; y <= M; ++y)
    for (uint32_t x = 0; x <= M; ++x)
      P[size_t(y) * (M + 1) + x] = frame.position(x, y, heights[size_t(y) * (M + 1) + x]);
  constexpr uint32_t kTile = 16;
  // The largest excess of a stored error over the exact one, over the leaves at the resolutions
  // whose cells are at most a tile.
  auto excess = [&](uint32_t maxTile) {
    const Hierarchy h = buildPlanetHierarchy(m, source, nullptr, maxTile);
    const uint32_t l = m.depth - 1, size = M >> l;
    double most = -1.0;
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x)
        for (uint32_t r = m.minNodeResLog2; r < h.maxResLog2(NodeId{0, l, x, y}); ++r) {
          const uint32_t s = size >> r;
          if (s > kTile) continue;
          double worst = 0.0;
          for (uint32_t v = 0; v <= size; ++v)
            for (uint32_t u = 0; u <= size; ++u) {
              const uint32_t cx = std::min(u / s, (1u << r) - 1), cy = std::min(v / s, (1u << r) - 1);
              const double fx = double(u - cx * s) / s, fy = double(v - cy * s) / s;
              auto corner = [&](uint32_t i, uint32_t j) {
                return P[size_t(y * size + j * s) * (M + 1) + x * size + i * s];
              };
              const glm::dvec3 h00 = corner(cx, cy), h10 = corner(cx + 1, cy), h01 = corner(cx, cy + 1),
                               h11 = corner(cx + 1, cy + 1);
              const glm::dvec3 drawn =
                  fx >= fy ? h00 + fx * (h10 - h00) + fy * (h11 - h10) : h00 + fy * (h01 - h00) + fx * (h11 - h01);
              worst = std::max(worst, glm::length(drawn - P[size_t(y * size + v) * (M + 1) + x * size + u]));
            }
          const double stored = h.error(NodeId{0, l, x, y}, r);
          EXPECT_GE(stored, worst - 1e-6) << "tile " << maxTile << " node " << x << "," << y << " res " << r;
          most = std::max(most, stored - worst);
        }
    return most;
  };
  const double tiled = excess(kTile), whole = excess(M);
  EXPECT_GE(tiled, 0.0);
  EXPECT_LE(tiled, 0.002);
  EXPECT_GE(whole, 0.02);
}

}  // namespace
}  // namespace gimlod

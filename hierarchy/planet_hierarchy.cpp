// Based on: Niski, Purnomo, Cohen, I3D 2007, sections 6 and 8 (the spherical Earth: a radius field
// on a longitude/latitude lattice); the node errors as buildGeometryHierarchy measures them.
#include <cmath>
#include <limits>

#include <tbb/parallel_for.h>

#include "hierarchy/hierarchy.h"

namespace gimlod {
namespace {

// The planet-centred position of chart c's centre sample.
glm::dvec3 chartCentre(const AtlasManifest& m, const PlanetFrame& frame, uint32_t c) {
  const int64_t M = int64_t(m.chartSize - 1);
  const ChartInfo& chart = m.charts[c];
  return frame.position(chart.gridX * M + M / 2, chart.gridY * M + M / 2, 0.0);
}

}  // namespace

Hierarchy buildPlanetHierarchy(const AtlasManifest& m, const ChartWindowSource& source, HierarchyStats* stats) {
  const HierarchyParams params = hierarchyParams(m);
  const uint32_t M = 1u << params.intervalsLog2;
  if (M > kMaxPlanetChartIntervals)
    throw InputError(optionRef("chartSize") + " " + std::to_string(m.chartSize) +
                     ": planet atlases are built with charts of at most " +
                     std::to_string(kMaxPlanetChartIntervals + 1) + " samples");
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  std::vector<std::array<RootNeighbour, 4>> roots;
  for (const ChartInfo& c : m.charts) roots.push_back(c.neighbours);
  Hierarchy h = buildGeometryHierarchy(
      params, roots,
      [&](uint32_t c) {
        const std::vector<float> heights = source(c, 0, 0, 0, M);
        const glm::dvec3 centre = chartCentre(m, frame, c);
        const ChartInfo& chart = m.charts[c];
        // The directions are separable: a column's longitude and a row's latitude, each once.
        std::vector<glm::dvec2> lon(M + 1);
        for (uint32_t u = 0; u <= M; ++u) {
          const double a = frame.longitude(int64_t(chart.gridX) * M + u);
          lon[u] = {std::cos(a), std::sin(a)};
        }
        std::vector<glm::vec3> p(heights.size());
        const double e2 = m.planet.eccentricity2();
        for (uint32_t v = 0; v <= M; ++v) {
          const int64_t gy = int64_t(chart.gridY) * M + v;
          const double lat = frame.latitude(gy), cl = frame.pole(gy) ? 0.0 : std::cos(lat), sl = std::sin(lat);
          const double z = frame.pole(gy) ? double(frame.pole(gy)) : sl;
          // The row's radius of curvature in the prime vertical (PlanetFrame::position).
          const double N = m.planet.normalRadius(z);
          for (uint32_t u = 0; u <= M; ++u) {
            const size_t i = size_t(v) * (M + 1) + u;
            const double r = N + double(heights[i]);
            p[i] = glm::vec3(glm::dvec3(r * cl * lon[u].x, r * cl * lon[u].y, r * z - e2 * N * z) - centre);
          }
        }
        return p;
      },
      stats);
  const float inf = std::numeric_limits<float>::infinity();
  tbb::parallel_for(uint32_t(0), h.chartCount(), [&](uint32_t c) {
    Hierarchy::ChartNodes& nodes = h.charts[c];
    const glm::dvec3 centre = chartCentre(m, frame, c);
    const auto& root = nodes.bounds[0];
    const double extent = std::max({std::fabs(root[0]), std::fabs(root[1]), std::fabs(root[2]), std::fabs(root[3]),
                                    std::fabs(root[4]), std::fabs(root[5])});
    const float margin = float(4.0 * extent * std::ldexp(1.0, -23));
    for (float& e : nodes.errors)
      if (e > 0.0f) e += margin;
    const ChartInfo& chart = m.charts[c];
    for (uint32_t l = 0; l < params.depth; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) {
          const uint32_t i = nodeIndex(l, x, y), size = M >> l;
          auto& b = nodes.bounds[i];
          for (int k = 0; k < 3; ++k) {
            b[k] = std::nextafter(float(double(b[k]) - double(margin) + centre[k]), -inf);
            b[3 + k] = std::nextafter(float(double(b[3 + k]) + double(margin) + centre[k]), inf);
          }
          const int64_t ox = int64_t(chart.gridX) * M + int64_t(x) * size;
          const int64_t oy = int64_t(chart.gridY) * M + int64_t(y) * size;
          nodes.flags[i] = ox >= int64_t(m.samplesX) - 1 || oy >= int64_t(m.samplesY) - 1 ? kNodeEmpty : 0;
        }
  });
  return h;
}

}  // namespace gimlod

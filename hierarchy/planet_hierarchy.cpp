// Based on: Niski, Purnomo, Cohen, I3D 2007, sections 6 and 8 (the spherical Earth: a radius field
// on a longitude/latitude lattice); the node errors as buildGeometryHierarchy measures them.
#include <bit>
#include <cmath>

#include <tbb/parallel_for.h>

#include "hierarchy/hierarchy.h"

namespace gimlod {
namespace {

// The (n + 1)^2 lattice samples (gx0 + u * step, gy0 + v * step).
struct LatticeWindow {
  int64_t gx0 = 0, gy0 = 0, step = 1;
  uint32_t n = 0;
};

// The positions of the samples of window w, heights h (row = v), relative to `origin`, as
// PlanetFrame::position places them.
std::vector<glm::vec3> placeSamples(const AtlasManifest& m, const PlanetFrame& frame, const std::vector<float>& h,
                                    const LatticeWindow& w, const glm::dvec3& origin) {
  const int64_t gx0 = w.gx0, gy0 = w.gy0, step = w.step;
  const uint32_t n = w.n;
  // The directions are separable: a column's longitude and a row's latitude, each once.
  std::vector<glm::dvec2> lon(n + 1);
  for (uint32_t u = 0; u <= n; ++u) {
    const double a = frame.longitude(gx0 + u * step);
    lon[u] = {std::cos(a), std::sin(a)};
  }
  std::vector<glm::vec3> p(size_t(n + 1) * (n + 1));
  const double e2 = m.planet.eccentricity2();
  for (uint32_t v = 0; v <= n; ++v) {
    const int64_t gy = gy0 + v * step;
    const double lat = frame.latitude(gy), cl = frame.pole(gy) ? 0.0 : std::cos(lat), sl = std::sin(lat);
    const double z = frame.pole(gy) ? double(frame.pole(gy)) : sl;
    // The row's radius of curvature in the prime vertical (PlanetFrame::position).
    const double N = m.planet.normalRadius(z);
    for (uint32_t u = 0; u <= n; ++u) {
      const size_t i = size_t(v) * (n + 1) + u;
      const double r = N + double(h[i]);
      p[i] = glm::vec3(glm::dvec3(r * cl * lon[u].x, r * cl * lon[u].y, r * z - e2 * N * z) - origin);
    }
  }
  return p;
}

}  // namespace

Hierarchy buildPlanetHierarchy(const AtlasManifest& m, const ChartWindowSource& source, HierarchyStats* stats,
                               uint32_t maxTile) {
  const HierarchyParams params = hierarchyParams(m);
  params.validate();
  const uint32_t L = params.intervalsLog2, M = 1u << L;
  if (!std::has_single_bit(maxTile) || maxTile < 2)
    throw std::invalid_argument("buildPlanetHierarchy: the tile must be a power of two");
  const uint32_t t = std::min(L, uint32_t(std::countr_zero(maxTile))), T = 1u << t, tiles = M / T;
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  std::vector<std::array<RootNeighbour, 4>> roots;
  for (const ChartInfo& c : m.charts) roots.push_back(c.neighbours);
  // Each chart's level t, for the levels whose cells span several tiles.
  std::vector<std::vector<float>> coarse(m.charts.size());
  if (tiles > 1)
    tbb::parallel_for(size_t(0), coarse.size(), [&](size_t c) {
      coarse[c] = source(uint32_t(c), t, 0, 0, tiles);
      if (coarse[c].size() != size_t(tiles + 1) * (tiles + 1))
        throw InputError("chart " + std::to_string(c) + ": expected " + std::to_string(tiles + 1) +
                         "^2 heights of level " + std::to_string(t));
    });
  Hierarchy h = buildTiledGeometryHierarchy(
      params, roots,
      [&](uint32_t c, uint32_t, uint32_t tx, uint32_t ty) -> std::optional<GeometryTile> {
        const ChartInfo& chart = m.charts[c];
        const int64_t gx = int64_t(chart.gridX) * M + int64_t(tx) * T, gy = int64_t(chart.gridY) * M + int64_t(ty) * T;
        // A tile past the DEM's last sample (padding of the chart grid) holds no data.
        if (tiles > 1 && (gx >= int64_t(m.samplesX) - 1 || gy >= int64_t(m.samplesY) - 1)) return std::nullopt;
        const std::vector<float> heights = source(c, 0, tx * T, ty * T, T);
        if (heights.size() != size_t(T + 1) * (T + 1))
          throw InputError("chart " + std::to_string(c) + ": expected " + std::to_string(T + 1) + "^2 heights");
        GeometryTile g;
        g.origin = frame.position(gx + T / 2, gy + T / 2, 0.0);
        g.positions = placeSamples(m, frame, heights, {gx, gy, 1, T}, g.origin);
        if (tiles > 1)
          g.coarse = placeSamples(m, frame, coarse[c], {int64_t(chart.gridX) * M, int64_t(chart.gridY) * M, T, tiles},
                                  g.origin);
        return g;
      },
      stats, maxTile);
  tbb::parallel_for(uint32_t(0), h.chartCount(), [&](uint32_t c) {
    Hierarchy::ChartNodes& nodes = h.charts[c];
    const ChartInfo& chart = m.charts[c];
    for (uint32_t l = 0; l < params.depth; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) {
          const uint32_t i = nodeIndex(l, x, y), size = M >> l;
          const int64_t ox = int64_t(chart.gridX) * M + int64_t(x) * size;
          const int64_t oy = int64_t(chart.gridY) * M + int64_t(y) * size;
          nodes.flags[i] = ox >= int64_t(m.samplesX) - 1 || oy >= int64_t(m.samplesY) - 1 ? kNodeEmpty : 0;
        }
  });
  return h;
}

}  // namespace gimlod

// The surface a level of a chart's pyramid draws, and how far the finer samples lie from it: the
// measure that the hierarchy's node errors (hierarchy/) and the mesh stage's choice of each
// chart's finest level (atlas/mesh/) share. Pure C++ (glm for vectors).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

namespace gimlod {

// A grid cell's surface at (fx, fy) in [0, 1]^2 from its corners h00 (0, 0), h10 (1, 0), h01
// (0, 1) and h11 (1, 1), split along (0,0)-(1,1) as the render grids draw it. T: float (heights)
// or glm::vec3 (geometry images).
template <typename T>
inline T cellSurface(const T& h00, const T& h10, const T& h01, const T& h11, float fx, float fy) {
  return fx >= fy ? h00 + fx * (h10 - h00) + fy * (h11 - h10)   // lower triangle
                  : h00 + fy * (h01 - h00) + fx * (h11 - h01);  // upper triangle
}

// For k = 0..levels: the largest distance from a sample of a side^2 geometry image (row = v) to
// the surface of its level k', drawn as the render grids draw it, at the sample's own (u, v), over
// k' <= k: the chart-wide form of buildGeometryHierarchy's node errors (out[0] = 0).
std::vector<float> geometryLevelErrors(const std::vector<glm::vec3>& positions, uint32_t side, uint32_t levels);

// The surface of level k of a side^2 geometry image (row = v), drawn as the render grids draw it,
// at every level-0 sample's (u, v): side^2 positions, the level's own samples where they lie.
std::vector<glm::vec3> geometryLevelSurface(const std::vector<glm::vec3>& positions, uint32_t side, uint32_t k);

// fn(i, surface_k(u_i, v_i)) for every level-0 sample i (row-major), where surface_k is the
// piecewise-linear interpolation of the level-k subsampled grid split along (0,0)-(1,1), as the
// render grids draw it. T is float (heights) or glm::vec3 (geometry images).
template <typename T, typename Fn>
void forEachLevelSample(const std::vector<T>& h, uint32_t S, uint32_t k, Fn&& fn) {
  const uint32_t M = S - 1;
  const uint32_t n = M >> k;
  const uint32_t s = 1u << k;
  const float inv = 1.0f / float(s);
  for (uint32_t y = 0; y <= M; ++y) {
    const uint32_t cy = std::min(y >> k, n - 1);
    const float fy = float(y - cy * s) * inv;
    const T* row0 = &h[size_t(cy * s) * S];
    const T* row1 = &h[size_t((cy + 1) * s) * S];
    const size_t at = size_t(y) * S;
    for (uint32_t cx = 0; cx < n; ++cx) {
      const uint32_t x0 = cx * s;
      const T h00 = row0[x0], h10 = row0[x0 + s], h01 = row1[x0], h11 = row1[x0 + s];
      const uint32_t xend = (cx == n - 1) ? s : s - 1;
      for (uint32_t dx = 0; dx <= xend; ++dx) {
        const float fx = float(dx) * inv;
        fn(at + x0 + dx, cellSurface(h00, h10, h01, h11, fx, fy));
      }
    }
  }
}

// running[i] = max(running[i], dist(p_i, surface_k(u_i, v_i))) for every level-0 sample
// (forEachLevelSample). Dist: |a - b| for heights, Euclidean for geometry images.
template <typename T, typename Dist>
void accumulateLevelError(const std::vector<T>& h, uint32_t S, uint32_t k, std::vector<float>& running, Dist dist) {
  forEachLevelSample(h, S, k,
                     [&](size_t i, const T& interp) { running[i] = std::max(running[i], dist(h[i], interp)); });
}

// note: function objects, not functions: a function pointer as Dist would be an indirect call
// per sample in accumulateLevelError's inner loop.
struct HeightDistance {
  float operator()(float a, float b) const { return std::fabs(a - b); }
};
struct PointDistance {
  float operator()(const glm::vec3& a, const glm::vec3& b) const {
    const glm::vec3 d = a - b;
    return std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  }
};

}  // namespace gimlod

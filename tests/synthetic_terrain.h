// Small hand-made height-field atlases for tests: a manifest with a chart grid and neighbours,
// and deterministic heights.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"

namespace gimlod::test {

// A chartsX x chartsY grid of charts of `chartSize` samples, spacing 1.
inline AtlasManifest syntheticManifest(uint32_t chartSize, uint32_t chartsX, uint32_t chartsY, uint32_t depth,
                                       uint32_t maxResLog2, uint32_t minRes) {
  AtlasManifest m;
  m.chartSize = chartSize;
  m.blockIntervals = 1u << maxResLog2;
  m.chartsX = chartsX;
  m.chartsY = chartsY;
  const uint32_t M = chartSize - 1;
  m.samplesX = chartsX * M + 1;
  m.samplesY = chartsY * M + 1;
  m.depth = depth;
  m.maxNodeResLog2 = maxResLog2;
  m.minNodeResLog2 = minRes;
  for (uint32_t y = 0; y < chartsY; ++y)
    for (uint32_t x = 0; x < chartsX; ++x) {
      ChartInfo c;
      c.id = y * chartsX + x;
      c.gridX = int32_t(x);
      c.gridY = int32_t(y);
      c.file = "charts/chart_" + std::to_string(c.id) + ".bin";
      auto at = [&](int32_t cx, int32_t cy, uint8_t edge) {
        RootNeighbour r;
        if (cx >= 0 && cy >= 0 && cx < int32_t(chartsX) && cy < int32_t(chartsY)) {
          r.chart = cy * int32_t(chartsX) + cx;
          r.edge = edge;
        }
        return r;
      };
      c.neighbours[kEdgeBottom] = at(int32_t(x), int32_t(y) - 1, kEdgeTop);
      c.neighbours[kEdgeRight] = at(int32_t(x) + 1, int32_t(y), kEdgeLeft);
      c.neighbours[kEdgeTop] = at(int32_t(x), int32_t(y) + 1, kEdgeBottom);
      c.neighbours[kEdgeLeft] = at(int32_t(x) - 1, int32_t(y), kEdgeRight);
      m.charts.push_back(c);
    }
  return m;
}

// Smooth hills plus seeded noise, as a global function of the sample position, so neighbouring
// charts agree on shared samples.
inline float syntheticHeight(int64_t gx, int64_t gy, uint32_t seed = 1) {
  uint64_t z = uint64_t(gx) * 0x9E3779B97F4A7C15ull ^ uint64_t(gy) * 0xC2B2AE3D27D4EB4Full ^ seed;
  z = (z ^ (z >> 31)) * 0xBF58476D1CE4E5B9ull;
  z ^= z >> 29;
  const float noise = float(z % 1000) / 1000.f - 0.5f;
  return 20.f * std::sin(float(gx) * 0.05f) * std::cos(float(gy) * 0.07f) + 3.f * noise;
}

inline std::vector<float> syntheticChart(const AtlasManifest& m, uint32_t chart, uint32_t seed = 1) {
  const uint32_t S = m.chartSize, M = S - 1;
  const ChartInfo& c = m.charts[chart];
  std::vector<float> h(size_t(S) * S);
  for (uint32_t v = 0; v < S; ++v)
    for (uint32_t u = 0; u < S; ++u)
      h[size_t(v) * S + u] = syntheticHeight(int64_t(c.gridX) * M + u, int64_t(c.gridY) * M + v, seed);
  return h;
}

}  // namespace gimlod::test

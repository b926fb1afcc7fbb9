// Seam checks of resampled geometry images (atlas/mesh/resample.h), shared by the resampling
// tests of both quad layouts.
#pragma once

#include <gtest/gtest.h>

#include <cstring>

#include "atlas/mesh/resample.h"

namespace gimlod::test {

inline bool sameBytes(const void* a, const void* b, size_t n) { return std::memcmp(a, b, n) == 0; }

// Every chart edge with a neighbour: the neighbour's table points back, and at every pyramid
// level (2^k+1 subsampling) sample k here is byte-identical to sample M-k there (reversed) in
// position, normal and colour. Returns the number of samples compared.
inline size_t expectSeamless(const GeometryImageSet& set) {
  const uint32_t size = set.chartSize, m = size - 1;
  size_t compared = 0;
  for (uint32_t c = 0; c < set.charts.size(); ++c) {
    const GeometryImage& a = set.charts[c];
    for (uint32_t e = 0; e < 4; ++e) {
      const RootNeighbour nb = a.neighbours[e];
      if (nb.chart < 0) continue;
      EXPECT_LT(uint32_t(nb.chart), set.charts.size());
      if (uint32_t(nb.chart) >= set.charts.size()) continue;
      const GeometryImage& b = set.charts[uint32_t(nb.chart)];
      const RootNeighbour back = b.neighbours[nb.edge];
      EXPECT_EQ(back.chart, int32_t(c));
      EXPECT_EQ(back.edge, e);
      EXPECT_EQ(back.reversed, nb.reversed);
      for (uint32_t step = 1; step <= m; step *= 2) {  // pyramid level log2(step)
        for (uint32_t k = 0; k <= m; k += step) {
          const uint32_t ia = edgeSampleIndex(size, e, k);
          const uint32_t ib = edgeSampleIndex(size, nb.edge, nb.reversed ? m - k : k);
          EXPECT_TRUE(sameBytes(&a.positions[ia], &b.positions[ib], sizeof(glm::vec3)))
              << "chart " << c << " edge " << e << " k " << k << " step " << step;
          EXPECT_TRUE(sameBytes(&a.normals[ia], &b.normals[ib], sizeof(PackedNormal)));
          if (!a.colours.empty()) {
            EXPECT_TRUE(sameBytes(&a.colours[ia], &b.colours[ib], sizeof(glm::u8vec4)));
          }
          ++compared;
        }
      }
    }
  }
  return compared;
}

// The image figures of a resampled test::cubeLayout: no degenerate texel; the cube's charts are
// isometric (L2 stretch 1, area 6), the sphere's nearly so.
inline void expectCubeImage(const GeometryImageSet& set, bool sphere) {
  EXPECT_EQ(set.image.degenerateTexels, 0u);
  if (!sphere) {
    EXPECT_NEAR(set.image.stretchL2, 1.0, 1e-4);
    EXPECT_NEAR(set.image.area3D, 6.0, 1e-4);
  } else {
    EXPECT_LT(set.image.stretchL2, 1.2);
  }
}

}  // namespace gimlod::test

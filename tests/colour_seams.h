// Colour seams: every pair of charts sharing an edge holds bit-identical colours on it, at every
// pyramid level. For mesh vertex colours (in the chart files) and terrain imagery (attribute files).
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "core/atlas_format.h"

namespace gimlod::test {

// Compares the shared edges of `charts` (one reader per manifest chart, of colour charts of
// chartSize samples per side) at each of `levels` levels; returns the samples compared.
inline uint64_t expectColourSeamsBitIdentical(const AtlasManifest& m,
                                              const std::vector<std::unique_ptr<ChartFileReader>>& charts,
                                              uint32_t chartSize, uint32_t levels) {
  uint64_t compared = 0;
  for (uint32_t level = 0; level < levels; ++level) {
    const uint32_t n = ((chartSize - 1) >> level) + 1;
    std::vector<std::vector<PackedColour>> colours;
    for (const auto& r : charts) colours.push_back(r->readLevelColours(level));
    for (uint32_t c = 0; c < m.charts.size(); ++c)
      for (uint32_t e = 0; e < 4; ++e) {
        const RootNeighbour& nb = m.charts[c].neighbours[e];
        if (nb.chart < 0) continue;
        for (uint32_t k = 0; k < n; ++k, ++compared) {
          const uint32_t kk = nb.reversed ? n - 1 - k : k;
          if (colours[c][edgeSampleIndex(n, e, k)] != colours[size_t(nb.chart)][edgeSampleIndex(n, nb.edge, kk)]) {
            ADD_FAILURE() << "level " << level << " chart " << c << " edge " << e << " sample " << k;
            return compared;
          }
        }
      }
  }
  return compared;
}

}  // namespace gimlod::test

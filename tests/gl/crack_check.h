// Shared by the transform-feedback crack tests (crack_gl_test.cpp, scan_crack_gl_test.cpp): the
// crack count of a cut captured from the real vertex shader, with its negative control, and how
// mixed a cut is across node sides (level and resolution differences, within and across charts).
#pragma once

#include <gtest/gtest.h>

#include <vector>

#include "runtime/cut.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/stitch.h"

namespace gimlod::test {

// Crack count of `cut` through the real shader: every border vertex against the neighbours drawn
// across that side. Checks that every node was captured at its resolution. With
// expectControlToFail, the same cut captured without the stitching tables must crack, or the test
// could not fail.
inline CrackReport captureCracks(gl::AtlasScene& scene, const Cut& cut, bool expectControlToFail = true) {
  const auto verts = scene.capture(cut);
  EXPECT_EQ(verts.size(), cut.nodes.size());
  for (size_t i = 0; i < verts.size() && i < cut.nodes.size(); ++i) {
    const size_t side = (size_t(1) << cut.nodes[i].resLog2) + 1;
    EXPECT_EQ(verts[i].size(), side * side) << "node " << i;
  }
  const CrackReport r = countCracks(scene.atlas().hierarchy, cut, verts);
  if (expectControlToFail) {
    const CrackReport control = countCracks(scene.atlas().hierarchy, cut, scene.capture(cut, false));
    EXPECT_GT(control.mismatches, 0u) << "negative control found no cracks";
  }
  return r;
}

// Node-side adjacencies of a cut (each counted from both sides) and how many of them join nodes of
// different levels or resolutions, within a chart and across chart borders.
struct CutMix {
  uint64_t sides = 0;                // (node side, drawn neighbour) pairs
  uint64_t mixed = 0;                // of those, level or resolution differs
  uint64_t crossChart = 0;           // neighbour in another chart
  uint64_t crossChartLevelDiff = 0;  // across charts, different levels
  uint64_t crossChartResDiff = 0;    // across charts, different resolutions
  CutMix& operator+=(const CutMix& o) {
    sides += o.sides;
    mixed += o.mixed;
    crossChart += o.crossChart;
    crossChartLevelDiff += o.crossChartLevelDiff;
    crossChartResDiff += o.crossChartResDiff;
    return *this;
  }
};

inline CutMix cutMix(const Hierarchy& h, const Cut& cut) {
  CutMix mix;
  std::vector<SideNeighbour> ns;
  for (const CutNode& n : cut.nodes)
    for (uint32_t s = 0; s < 4; ++s) {
      ns.clear();
      sideNeighbours(h, cut, n.id, s, ns);
      for (const SideNeighbour& sn : ns) {
        const CutNode& m = cut.nodes[sn.cutIndex];
        const bool levelDiff = m.id.level != n.id.level, resDiff = m.resLog2 != n.resLog2;
        ++mix.sides;
        mix.mixed += levelDiff || resDiff;
        if (m.id.chart != n.id.chart) {
          ++mix.crossChart;
          mix.crossChartLevelDiff += levelDiff;
          mix.crossChartResDiff += resDiff;
        }
      }
    }
  return mix;
}

}  // namespace gimlod::test

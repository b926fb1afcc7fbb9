// Cracks on the real scans: the atlas of every shared scan (default mesh options, as `gimlod build`
// makes it), adapted by the coherent dual-queue adapter frame after frame along a camera path
// that spirals in from far away to close up, so that charts near the camera are refined while
// their neighbours across chart borders stay coarse. Every frame's cut is captured from the real
// vertex shader with transform feedback, and every border vertex is checked against the drawn
// neighbours across that side: 0 mismatches. The path must actually produce neighbours at
// different levels and at different resolutions across chart borders, and the same cut without
// the stitching tables must crack (the negative control), so the test can fail.
#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>

#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"
#include "tests/gl/gl_context_test.h"
#include "runtime/stitch.h"
#include "tests/gl/crack_check.h"
#include "tests/scan_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

class ScanCrackTest : public test::GlContextTest<::testing::TestWithParam<std::string>> {};

// A path spiralling in: frame i of `frames` circles the box centre at a distance going from
// `far` to `near` times the diagonal (orbitPath's frame i at that distance).
std::vector<Camera> spiralPath(const glm::dvec3& lo, const glm::dvec3& hi, uint32_t frames, double far, double near,
                               double elevationDeg) {
  std::vector<Camera> path;
  for (uint32_t i = 0; i < frames; ++i) {
    const double t = frames > 1 ? double(i) / (frames - 1) : 0.0;
    path.push_back(orbitPath(lo, hi, frames, far + (near - far) * t, elevationDeg)[i]);
  }
  return path;
}

TEST_P(ScanCrackTest, DualQueueCutsAlongAPathHaveNoCracks) {
  const std::string name = GetParam();
  GIMLOD_NEED_SHARED_DATA(test::haveSharedScan(name));
  const test::BuiltScanAtlas* built = nullptr;
  // With the fidelity measure, as the CPU tests ask: one build of the scan serves both.
  ASSERT_NO_THROW(built = &test::scanAtlas(name, true)) << "gimlod build " << test::sharedScanPath(name);
  const AtlasView atlas = openAtlas(built->dir);
  const Hierarchy& h = atlas.hierarchy;
  ASSERT_EQ(atlas.manifest.kind, AtlasKind::Geometry);
  // Small frames: CI renders on llvmpipe. The capture costs the cut's vertices, not the pixels.
  gl::SceneOptions so;
  so.width = 128;
  so.height = 96;
  gl::AtlasScene scene(atlas, so);
  AdaptOptions ao;
  ao.tolerancePx = 0.5;
  // Every node of a cut must have a page in the GPU pool, or its captured data would be wrong. The
  // roots' pages stay locked there; the nodes below them need free layers. The scene's node budget
  // (3/4 of the free layers, on the drawn nodes, roots included; what renderFrame uses) keeps them
  // within the pool, which is checked below. With many charts (the turbine blade) the drawn roots
  // alone fill it from afar, so the path ends close up, where most charts are culled.
  const uint32_t charts = h.chartCount();
  const uint32_t freeLayers = scene.renderer().pageCapacity() - charts;
  ao.maxNodes = scene.nodeBudget(0);
  std::cout << "  " << name << ": " << charts << " charts, " << freeLayers << " free page layers, node budget "
            << ao.maxNodes << "\n";
  DualQueueAdapter dq(h);
  test::CutMix total;
  uint64_t checked = 0, nodes = 0;
  // Charts keep their pyramids from different finest levels (ChartInfo::finestLevel): the drawn
  // sides where two such charts meet, if the atlas has any.
  bool mixedSeams = false;
  for (const ChartInfo& c : atlas.manifest.charts)
    for (const RootNeighbour& r : c.neighbours)
      mixedSeams =
          mixedSeams || (r.chart >= 0 && atlas.manifest.charts[uint32_t(r.chart)].finestLevel != c.finestLevel);
  uint64_t mixedSides = 0;
  std::vector<SideNeighbour> across;
  uint32_t maxLevel = 0, controls = 0;
  const std::vector<Camera> path = spiralPath(atlas.lo, atlas.hi, 8, 1.0, 0.2, 25.0);
  for (size_t f = 0; f < path.size(); ++f) {
    Camera cam = path[f];
    fitClipPlanes(cam, atlas.lo, atlas.hi);
    const Cut& cut = dq.update(makeViewParams(cam, so.width, so.height), ao);
    ASSERT_FALSE(cut.nodes.empty()) << "frame " << f;
    ASSERT_EQ(countStitchViolations(h, cut), 0u) << "frame " << f;
    uint32_t belowRoots = 0;
    for (const CutNode& n : cut.nodes) belowRoots += n.id.level > 0;
    ASSERT_LE(belowRoots, freeLayers) << "frame " << f << ": the cut does not fit the page pool";
    const test::CutMix mix = test::cutMix(h, cut);
    // The negative control on the first two frames whose cut is mixed across chart borders.
    const bool control = controls < 2 && mix.crossChartLevelDiff + mix.crossChartResDiff > 0;
    controls += control;
    const CrackReport r = test::captureCracks(scene, cut, control);
    EXPECT_EQ(r.mismatches, 0u) << name << " frame " << f << ": " << r.mismatches << " of " << r.borderVertices
                                << " border vertices match no neighbour vertex";
    for (const CutNode& n : cut.nodes) maxLevel = std::max<uint32_t>(maxLevel, n.id.level);
    std::cout << "  frame " << f << ": " << cut.nodes.size() << " nodes, " << r.borderVertices << " border vertices, "
              << r.mismatches << " mismatches; across charts " << mix.crossChart << " sides, "
              << mix.crossChartLevelDiff << " level and " << mix.crossChartResDiff << " resolution differences\n";
    total += mix;
    for (const CutNode& n : cut.nodes)
      for (uint32_t s = 0; s < 4; ++s) {
        across.clear();
        sideNeighbours(h, cut, n.id, s, across);
        for (const SideNeighbour& a : across) {
          const uint32_t other = cut.nodes[a.cutIndex].id.chart;
          mixedSides += other != n.id.chart && h.finestLevel(other) != h.finestLevel(n.id.chart);
        }
      }
    checked += r.borderVertices;
    nodes += cut.nodes.size();
  }
  std::cout << "  " << name << ": " << nodes << " nodes in " << path.size() << " frames, deepest level " << maxLevel
            << ", " << checked << " border vertices checked\n";
  EXPECT_GT(checked, 10000u);
  EXPECT_GT(controls, 0u) << "no frame was mixed across chart borders, so the negative control never ran";
  // The deepest level a chart has (depth 2 at 65^2, where the finest nodes are 32 intervals wide),
  // or at least level 2.
  EXPECT_GE(maxLevel, std::min(2u, h.params.depth - 1)) << "the path never came close enough to refine charts";
  EXPECT_GT(maxLevel, 0u) << "no chart was refined";
  EXPECT_GT(total.crossChartLevelDiff, 0u) << "no chart-border neighbours at different levels";
  EXPECT_GT(total.crossChartResDiff, 0u) << "no chart-border neighbours at different resolutions";
  std::cout << "  " << mixedSides << " drawn sides between charts of different finest levels\n";
  if (mixedSeams) {
    EXPECT_GT(mixedSides, 0u) << "charts of different finest levels meet, but no frame drew such a seam";
  }
}

INSTANTIATE_TEST_SUITE_P(SharedScans, ScanCrackTest, ::testing::ValuesIn(test::sharedScanNames()),
                         [](const ::testing::TestParamInfo<std::string>& i) { return i.param; });

}  // namespace
}  // namespace gimlod

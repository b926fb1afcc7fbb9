#include <gtest/gtest.h>

#include <random>
#include <set>

#include "runtime/adapt.h"
#include "runtime/stitch.h"
#include "tests/synthetic_terrain.h"

namespace gimlod {
namespace {

struct World {
  AtlasManifest m;
  Hierarchy h;
};

World makeWorld(uint32_t chartSize = 65, uint32_t cx = 3, uint32_t cy = 2, uint32_t depth = 4) {
  World w;
  w.m = test::syntheticManifest(chartSize, cx, cy, depth, 5, 2);
  w.h = buildTerrainHierarchy(w.m, [&](uint32_t c) { return test::syntheticChart(w.m, c); });
  return w;
}

Camera lookAt(glm::dvec3 eye, glm::dvec3 target, const World& w) {
  Camera c;
  c.eye = eye;
  c.target = target;
  c.nearPlane = 0.0;
  c.farPlane = 0.0;
  fitClipPlanes(c, {0, 0, -30}, {double(w.m.samplesX), double(w.m.samplesY), 30});
  return c;
}

// True when the cut tiles every non-empty chart area exactly once (no frustum culling).
void expectPartition(const World& w, const Cut& cut) {
  const uint32_t L = w.h.params.intervalsLog2;
  for (const CutNode& n : cut.nodes)
    for (NodeId a = n.id; a.level > 0;) {
      a = a.parent();
      ASSERT_LT(cut.find(a), 0) << "node and its ancestor both in the cut";
    }
  uint64_t area = 0;
  for (const CutNode& n : cut.nodes) area += 1ull << (2 * (L - n.id.level));
  EXPECT_EQ(area, uint64_t(w.h.chartCount()) << (2 * L));
}

TEST(Adapt, ErrorWithinToleranceAndPartition) {
  const World w = makeWorld();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(0, w.m.samplesX), uy(0, w.m.samplesY), uz(5, 200);
  for (int i = 0; i < 20; ++i) {
    const Camera cam = lookAt({ux(rng), uy(rng), uz(rng)}, {ux(rng), uy(rng), 0}, w);
    const ViewParams v = makeViewParams(cam, 320, 240);
    AdaptOptions o;
    o.tolerancePx = 0.5 + i * 0.2;
    o.maxNodes = 0;
    o.frustumCull = false;
    AdaptStats st;
    const Cut cut = adaptErrorThreshold(w.h, v, o, &st);
    expectPartition(w, cut);
    EXPECT_FALSE(st.nodeBudgetBound);
    for (const CutNode& n : cut.nodes) {
      const bool atFinest = n.resLog2 == w.h.params.maxResLog2(n.id.level) && n.id.level + 1 == w.h.params.depth;
      if (!atFinest) {
        EXPECT_LE(n.errorPx, o.tolerancePx + 1e-9) << "level " << n.id.level;
      }
    }
    EXPECT_EQ(countStitchViolations(w.h, cut), 0u);
  }
}

TEST(Adapt, NodeBudgetBindsAndIsReported) {
  const World w = makeWorld();
  const Camera cam = lookAt({10, 10, 3}, {100, 60, 0}, w);
  AdaptOptions o;
  o.tolerancePx = 0.05;
  o.maxNodes = 10;
  o.frustumCull = false;
  AdaptStats st;
  const Cut cut = adaptErrorThreshold(w.h, makeViewParams(cam, 320, 240), o, &st);
  EXPECT_TRUE(st.nodeBudgetBound);
  EXPECT_GT(st.maxErrorPx, o.tolerancePx);
  EXPECT_LE(cut.nodes.size(), o.maxNodes);
  EXPECT_EQ(countStitchViolations(w.h, cut), 0u);
  expectPartition(w, cut);
}

// A cut seven levels deep at chart 0's right border, beside chart 1's root: the stitching
// constraint must split nodes whose maxResLog2 (2^5) is below their level difference to the deep
// nodes, past the node budget; groups merge back until the budget holds, every constraint still
// met and the charts still tiled.
TEST(Adapt, ConstraintSplitsMergeBackIntoTheNodeBudget) {
  const World w = makeWorld(1025, 2, 1, 8);
  Cut cut;
  cut.nodes.push_back({NodeId{1, 0, 0, 0}, 2, 0.f});
  NodeId deep{0, 0, 0, 0};
  for (uint32_t l = 0; l < 7; ++l) {
    for (uint32_t c = 0; c < 4; ++c)
      if (c != 1) cut.nodes.push_back({deep.child(c), 2, 0.f});
    deep = deep.child(1);  // the bottom-right child, along the border with chart 1
  }
  cut.nodes.push_back({deep, 2, 0.f});
  cut.rebuildIndex();
  const uint32_t budget = uint32_t(cut.nodes.size());
  const ViewParams view = makeViewParams(lookAt({1024, -600, 900}, {1024, 512, 0}, w), 320, 240);
  AdaptStats st;
  ASSERT_TRUE(enforceStitchConstraint(w.h, cut, &view, 1.0, &st));
  EXPECT_GT(st.constraintSplits, 0u);
  ASSERT_GT(cut.nodes.size(), budget);
  const uint32_t merges = holdNodeBudget(w.h, cut, view, budget);
  EXPECT_GT(merges, 0u);
  EXPECT_LE(cut.nodes.size(), budget);
  EXPECT_EQ(countStitchViolations(w.h, cut), 0u);
  for (const CutNode& n : cut.nodes) EXPECT_LE(n.resLog2, w.h.maxResLog2(n.id));
  expectPartition(w, cut);
}

TEST(Adapt, FrustumCullingDropsNodesBehindTheCamera) {
  const World w = makeWorld();
  const Camera cam = lookAt({5, 5, 20}, {-50, -50, 0}, w);  // looking away from the terrain
  AdaptOptions o;
  AdaptStats st;
  const Cut cut = adaptErrorThreshold(w.h, makeViewParams(cam, 320, 240), o, &st);
  AdaptOptions all = o;
  all.frustumCull = false;
  const Cut full = adaptErrorThreshold(w.h, makeViewParams(cam, 320, 240), all);
  EXPECT_LT(cut.nodes.size(), full.nodes.size());
  EXPECT_GT(st.culled, 0u);
}

TEST(Stitch, TablesForHandMadeCutAcrossCharts) {
  const World w = makeWorld(65, 2, 1, 4);  // L = 6, leaf level 3 -> leafLog2 = 3, 8 entries
  Cut cut;
  // Chart 0: root split; its child (1,0) split again; its child (1,0)'s child (3,1) split again.
  // Chart 1: root at res 3.
  const uint32_t L = w.h.params.intervalsLog2;
  cut.nodes.push_back({{1, 0, 0, 0}, 3, 0});
  for (uint32_t i : {0u, 2u, 3u}) cut.nodes.push_back({NodeId{0, 1, i & 1, i >> 1}, 2, 0});
  for (uint32_t i : {0u, 1u, 2u}) cut.nodes.push_back({NodeId{0, 2, 2 + (i & 1), i >> 1}, 2, 0});
  for (uint32_t i = 0; i < 4; ++i) cut.nodes.push_back({NodeId{0, 3, 6 + (i & 1), 2 + (i >> 1)}, 2, 0});
  cut.rebuildIndex();
  ASSERT_EQ(countStitchViolations(w.h, cut), 0u);  // chart 1's root has res 3 >= gap 3
  const StitchTables t = buildStitchTables(w.h, cut);
  EXPECT_EQ(t.leafLog2, 3u);
  EXPECT_EQ(t.entriesPerSide, 8u);
  // Chart 1 root (index 0), left side, along v: level-2 (3,0) covers 0..16, level-3 (7,2) and
  // (7,3) cover 16..24 and 24..32, level-1 (1,1) covers 32..64.
  const uint8_t* left = t.side(0, kEdgeLeft);
  const uint8_t s2 = uint8_t(L - 2 - 2), s3 = uint8_t(L - 3 - 2), s1 = uint8_t(L - 1 - 2);
  const uint8_t expected[8] = {s2, s2, s3, s3, s1, s1, s1, s1};
  for (int e = 0; e < 8; ++e) EXPECT_EQ(left[e], expected[e]) << "entry " << e;
  // Chart 0's node (0, 2, 3, 0) sees chart 1's root on its right: spacing L - 0 - 3.
  const int32_t i = cut.find({0, 2, 3, 0});
  ASSERT_GE(i, 0);
  EXPECT_EQ(t.side(size_t(i), kEdgeRight)[0], uint8_t(L - 3));
  EXPECT_EQ(t.side(size_t(i), kEdgeRight)[1], uint8_t(L - 3));
  // Open border: zeros.
  EXPECT_EQ(t.side(size_t(i), kEdgeBottom)[0], 0);
  // Lowering chart 1's root below the gap violates the constraint.
  cut.nodes[0].resLog2 = 2;
  EXPECT_GT(countStitchViolations(w.h, cut), 0u);
  EXPECT_TRUE(enforceStitchConstraint(w.h, cut, nullptr, 1.0));
  EXPECT_EQ(countStitchViolations(w.h, cut), 0u);
  EXPECT_EQ(cut.nodes[0].resLog2, 3u);
}

}  // namespace
}  // namespace gimlod

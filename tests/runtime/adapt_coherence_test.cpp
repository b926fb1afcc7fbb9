// The fast paths of the adaptation: the cut's key index, the stitching gaps computed from the
// coarser side, frustum classification, and the dual queue's reuse of split priorities across
// frames, each checked against the straightforward computation.
#include <gtest/gtest.h>

#include <random>

#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "tests/adapt_fixture.h"

namespace gimlod {
namespace {

using test::makeWorld;
using test::sortedNodes;
using test::viewAt;
using test::World;

TEST(NodeKeyIndex, FindsEveryKeyAndOnlyThose) {
  // Keys that differ only in the chart bits (a hash of the low bits alone would chain them all).
  Cut cut;
  for (uint32_t c = 0; c < 500; ++c)
    for (uint32_t l = 0; l < 3; ++l) cut.nodes.push_back({NodeId{c, l, l, 0}, 2, 0.f});
  cut.rebuildIndex();
  EXPECT_EQ(cut.index.size(), cut.nodes.size());
  for (uint32_t i = 0; i < cut.nodes.size(); ++i) ASSERT_EQ(cut.find(cut.nodes[i].id), int32_t(i));
  EXPECT_EQ(cut.find(NodeId{500, 0, 0, 0}), -1);
  EXPECT_EQ(cut.find(NodeId{3, 1, 0, 0}), -1);
  EXPECT_EQ(cut.find(NodeId{3, 3, 3, 0}), -1);
  // Rebuilding forgets the old keys.
  cut.nodes.resize(1);
  cut.rebuildIndex();
  EXPECT_EQ(cut.find(NodeId{0, 0, 0, 0}), 0);
  EXPECT_EQ(cut.find(NodeId{1, 0, 0, 0}), -1);
  Cut empty;
  EXPECT_EQ(empty.find(NodeId{0, 0, 0, 0}), -1);
}

// A random partition of the charts (random splits down to the leaves), random resolutions; with
// dropFraction > 0 some nodes are removed, as frustum culling does.
Cut randomCut(const Hierarchy& h, std::mt19937& rng, double splitP, double dropFraction) {
  std::uniform_real_distribution<double> u(0, 1);
  Cut cut;
  std::vector<NodeId> stack;
  for (uint32_t c = 0; c < h.chartCount(); ++c) stack.push_back({c, 0, 0, 0});
  while (!stack.empty()) {
    const NodeId n = stack.back();
    stack.pop_back();
    if (n.level + 1 < h.params.depth && u(rng) < splitP * (n.level == 0 ? 1.5 : 1.0)) {
      for (uint32_t i = 0; i < 4; ++i) stack.push_back(n.child(i));
      continue;
    }
    if (u(rng) < dropFraction) continue;
    const uint32_t lo = h.params.minNodeResLog2, hi = h.params.maxResLog2(n.level);
    cut.nodes.push_back({n, lo + uint32_t(u(rng) * (hi - lo + 1)) % (hi - lo + 1), 0.f});
  }
  cut.rebuildIndex();
  return cut;
}

void expectGapsMatch(const Hierarchy& h, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<uint32_t> gaps;
  std::vector<SideNeighbour> scratch;
  uint32_t nonZero = 0;
  for (int k = 0; k < 40; ++k) {
    const Cut cut = randomCut(h, rng, 0.55, k % 2 ? 0.2 : 0.0);
    stitchGaps(h, cut, gaps);
    ASSERT_EQ(gaps.size(), cut.nodes.size());
    for (uint32_t i = 0; i < cut.nodes.size(); ++i) {
      ASSERT_EQ(gaps[i], finestNeighbourGap(h, cut, i, scratch)) << "cut " << k << " node " << i;
      nonZero += gaps[i] > 1;
    }
  }
  EXPECT_GT(nonZero, 20u);  // the random cuts do have multi-level neighbours
}

TEST(StitchGaps, MatchFinestNeighbourGapOnRandomCuts) {
  const World w = makeWorld(129, 3, 2, 5);
  expectGapsMatch(w.h, 5);
}

TEST(StitchGaps, MatchAcrossRotatedChartEdges) {
  // Two charts meeting at 90 degrees (chart 0's right edge against chart 1's top edge) and a
  // third glued bottom to bottom, as mesh atlases have.
  World w = makeWorld(129, 3, 1, 5);
  for (auto& r : w.h.roots) r = {};
  w.h.roots[0][kEdgeRight] = {1, kEdgeTop, true};
  w.h.roots[1][kEdgeTop] = {0, kEdgeRight, true};
  w.h.roots[1][kEdgeBottom] = {2, kEdgeBottom, true};
  w.h.roots[2][kEdgeBottom] = {1, kEdgeBottom, true};
  expectGapsMatch(w.h, 9);
}

TEST(Frustum, ClassifyAgreesWithIntersectsAndNests) {
  const World w = makeWorld(129, 3, 2, 5);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ux(-50, 450), uz(-40, 80), us(0, 60);
  uint32_t counts[3] = {0, 0, 0};
  for (int v = 0; v < 20; ++v) {
    const ViewParams view = viewAt(w, {ux(rng), ux(rng), 30 + us(rng)}, {ux(rng), ux(rng), 0});
    for (int b = 0; b < 500; ++b) {
      const glm::dvec3 lo{ux(rng), ux(rng), uz(rng)};
      const glm::dvec3 hi = lo + glm::dvec3{us(rng), us(rng), us(rng)};
      const int c = view.frustum.classify(lo, hi);
      ASSERT_EQ(c != 0, view.frustum.intersects(lo, hi));
      ++counts[c];
      // A box inside an outside or inside box gets the same class.
      const glm::dvec3 m = 0.5 * (lo + hi);
      if (c != 1) {
        ASSERT_EQ(view.frustum.classify(lo, m), c);
        ASSERT_EQ(view.frustum.classify(m, hi), c);
      }
    }
  }
  EXPECT_GT(counts[0], 0u);
  EXPECT_GT(counts[1], 0u);
  EXPECT_GT(counts[2], 0u);
}

// Reused split priorities are exact: along a moving path the coherent adapter produces exactly
// the cuts of one that recomputes every priority every frame, and it does reuse some.
TEST(DualQueue, ReusedPrioritiesGiveTheSameCuts) {
  const World w = makeWorld(129, 3, 2, 5);
  std::vector<ViewParams> path;
  for (int i = 0; i <= 80; ++i) {
    const double t = i / 80.0;
    path.push_back(viewAt(w, {20 + 250 * t, 10 + 100 * t, 12 + 10 * std::sin(6 * t)}, {200 - 50 * t, 120, 0}));
  }
  for (uint32_t budget : {0u, 40u, 150u}) {
    for (double tol : {0.3, 1.5}) {
      AdaptOptions o;
      o.tolerancePx = tol;
      o.maxNodes = budget;
      DualQueueAdapter reuse(w.h, 64, true), recompute(w.h, 64, false);
      uint64_t reused = 0;
      for (size_t f = 0; f < path.size(); ++f) {
        const auto a = sortedNodes(reuse.update(path[f], o));
        const auto b = sortedNodes(recompute.update(path[f], o));
        ASSERT_EQ(a, b) << "budget " << budget << " tolerance " << tol << " frame " << f;
        reused += reuse.frameStats().priorityReuses;
        EXPECT_EQ(recompute.frameStats().priorityReuses, 0u);
      }
      EXPECT_GT(reused, 0u) << "budget " << budget << " tolerance " << tol;
    }
  }
}

// Paper 7.1: attribute texture resolutions from the projected size and the pixel-to-texel ratio.
TEST(AttributeResolution, FromProjectedDiagonalAndRatio) {
  const World w = makeWorld(129, 3, 2, 5);
  const NodeId n{1, 2, 1, 2};
  const auto& b = w.h.bounds(n);
  const glm::dvec3 lo{b[0], b[1], b[2]}, hi{b[3], b[4], b[5]};
  const double diag = glm::length(hi - lo);
  ViewParams v;
  v.pixelsPerRadian = 500.0;
  v.minDistance = 1e-3;
  const glm::dvec3 centre = 0.5 * (lo + hi);
  for (double dist : {40.0, 300.0, 5000.0})
    for (double ratio : {0.5, 1.0, 2.0}) {
      v.eye = glm::dvec3(centre.x, centre.y, hi.z + dist);  // straight above: distance = dist
      const double texels = diag * v.pixelsPerRadian / dist * ratio;
      const uint32_t expect = std::clamp(uint32_t(std::ceil(std::log2(std::max(texels, 4.0)))),
                                         w.h.params.minNodeResLog2, w.h.params.intervalsLog2 - n.level);
      EXPECT_EQ(attributeResolution(w.h, n, v, ratio), expect) << dist << " " << ratio;
    }
  // Inside the bounds: the finest data the pyramid has for the node.
  v.eye = centre;
  EXPECT_EQ(attributeResolution(w.h, n, v, 1.0), w.h.params.intervalsLog2 - n.level);
  // Never coarser when the ratio grows or the camera comes closer.
  v.eye = glm::dvec3(centre.x, centre.y, hi.z + 200.0);
  EXPECT_LE(attributeResolution(w.h, n, v, 1.0), attributeResolution(w.h, n, v, 4.0));
  Cut cut;
  cut.nodes = {{n, 3, 0.f}, {NodeId{0, 0, 0, 0}, 2, 0.f}};
  cut.rebuildIndex();
  const AttributeStats st = assignAttributeResolutions(w.h, cut, v, 1.0);
  EXPECT_EQ(cut.nodes[0].texRes, attributeResolution(w.h, n, v, 1.0));
  uint64_t texels = 0;
  for (const CutNode& c : cut.nodes) texels += ((1ull << c.texRes) + 1) * ((1ull << c.texRes) + 1);
  EXPECT_EQ(st.texels, texels);
}

// The attributes' mip, resolution and blend together (CutNode::texBlend): continuous as the camera
// moves away, where the resolution alone steps a whole mip; the blend in [0, 1), 0 where clamped.
TEST(AttributeResolution, TheBlendMakesTheMipContinuous) {
  const World w = makeWorld(129, 3, 2, 5);
  const NodeId n{1, 2, 1, 2};
  const auto& b = w.h.bounds(n);
  const glm::dvec3 centre{0.5 * (b[0] + b[3]), 0.5 * (b[1] + b[4]), b[5]};
  const uint32_t lo = w.h.params.minNodeResLog2, hi = w.h.params.intervalsLog2 - n.level;
  ViewParams v;
  v.pixelsPerRadian = 500.0;
  v.minDistance = 1e-3;
  uint32_t switches = 0, blended = 0;
  double lastLod = -1.0;
  uint32_t lastRes = 0;
  for (double dist = 1.0; dist < 1e5; dist *= 1.01) {
    v.eye = centre + glm::dvec3(0.0, 0.0, dist);
    float blend = -1.f;
    const uint32_t res = attributeResolution(w.h, n, v, 1.0, &blend);
    EXPECT_EQ(res, attributeResolution(w.h, n, v, 1.0));
    ASSERT_GE(blend, 0.f);
    ASSERT_LT(blend, 1.f);
    if (res == lo || res == hi) {
      // Clamped at either end, or exactly on a mip.
      EXPECT_TRUE(blend == 0.f || (res == hi && blend < 1.f)) << dist;
    }
    blended += blend > 0.f;
    // The mip sampled: below the finest (hi) by (hi - res) and the blend.
    const double lod = double(hi - res) + double(blend);
    if (lastLod >= 0.0) {
      switches += res != lastRes;
      // 1% farther: log2(1.01) = 0.0144 of a mip, never a whole one.
      EXPECT_NEAR(lod, lastLod, 0.02) << dist << ": resolution " << lastRes << " -> " << res;
      EXPECT_GE(lod, lastLod - 1e-9) << "the mip never gets finer as the camera goes away";
    }
    lastLod = lod;
    lastRes = res;
  }
  EXPECT_GE(switches, hi - lo) << "the path crosses every resolution";
  EXPECT_GT(blended, 0u);
}

}  // namespace
}  // namespace gimlod

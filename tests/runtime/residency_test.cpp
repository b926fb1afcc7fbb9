// Page residency on small hand-made cuts: which pages are requested, and the drawable cut with
// resident ancestors standing in for missing nodes (paper 7.2). No GL.
#include <gtest/gtest.h>

#include <algorithm>
#include <unordered_set>

#include "runtime/adapt.h"
#include "runtime/residency.h"
#include "tests/adapt_fixture.h"
#include "tests/synthetic_terrain.h"

namespace gimlod {
namespace {

// Two charts side by side (chart 1 right of chart 0), 64 intervals each, with a free choice of
// depth and resolutions.
test::World twoCharts(uint32_t depth, uint32_t maxResLog2, uint32_t minRes) {
  test::World w;
  w.m = test::syntheticManifest(65, 2, 1, depth, maxResLog2, minRes);
  w.h = buildTerrainHierarchy(w.m, [&](uint32_t c) { return test::syntheticChart(w.m, c); });
  w.lo = {0, 0, -30};
  w.hi = {double(w.m.samplesX), double(w.m.samplesY), 30};
  return w;
}

ViewParams overview(const test::World& w) { return test::viewAt(w, {64.0, -80.0, 90.0}, {64.0, 32.0, 0.0}); }

Cut makeCut(std::vector<CutNode> nodes) {
  Cut c;
  c.nodes = std::move(nodes);
  c.rebuildIndex();
  return c;
}

NodeId node(uint32_t chart, uint32_t level, uint32_t x, uint32_t y) { return {chart, level, x, y}; }

// The four children of n, at resolution res and screen error err.
std::vector<CutNode> children(const NodeId& n, uint32_t res, float err = 1.f) {
  std::vector<CutNode> out;
  for (uint32_t i = 0; i < 4; ++i) out.push_back({n.child(i), res, err});
  return out;
}

ResidentFn residentSet(const std::unordered_set<uint64_t>& keys) {
  return [&keys](uint64_t k) { return keys.count(k) != 0; };
}

// The order pages are served in: every request for a coarser level before every request for a
// finer one, whatever their screen errors; within a level, the larger error first.
void expectCoarserThenLargerErrorFirst(const PageRequestPlan& plan, const Cut& desired) {
  for (const PageRequest& a : plan.requests)
    for (const PageRequest& b : plan.requests) {
      if (a.id.level < b.id.level) {
        EXPECT_GT(a.priority, b.priority) << "level " << a.id.level << " after level " << b.id.level;
      }
      const int ia = desired.find(a.id), ib = desired.find(b.id);
      if (a.id.level == b.id.level && ia >= 0 && ib >= 0 &&
          desired.nodes[size_t(ia)].errorPx > desired.nodes[size_t(ib)].errorPx) {
        EXPECT_GT(a.priority, b.priority) << "a larger error after a smaller one on level " << a.id.level;
      }
    }
}

std::unordered_set<uint64_t> roots(const test::World& w) {
  std::unordered_set<uint64_t> r;
  for (uint32_t c = 0; c < w.h.chartCount(); ++c) r.insert(node(c, 0, 0, 0).key());
  return r;
}

TEST(Residency, AllResidentDrawsTheDesiredCutAndRequestsNothing) {
  const test::World w = twoCharts(3, 5, 2);
  std::vector<CutNode> nodes = children(node(0, 0, 0, 0), 3);
  nodes.push_back({node(1, 0, 0, 0), 2, 0.5f});
  const Cut desired = makeCut(nodes);
  std::unordered_set<uint64_t> all = roots(w);
  for (const CutNode& n : desired.nodes) all.insert(n.id.key());
  const PageRequestPlan plan = planPageRequests(w.h, desired, residentSet(all), {});
  EXPECT_TRUE(plan.requests.empty());
  EXPECT_TRUE(plan.wanted.empty());
  const ResidentCut r = substituteResident(w.h, desired, overview(w), residentSet(all));
  EXPECT_EQ(r.nodesSubstituted, 0u);
  EXPECT_EQ(r.stitchUnfixable, 0u);
  EXPECT_EQ(test::sortedNodes(r.cut), test::sortedNodes(desired));
  for (size_t i = 0; i < desired.nodes.size(); ++i) EXPECT_EQ(r.cut.nodes[i].errorPx, desired.nodes[i].errorPx);
}

TEST(Residency, MissingChildrenAreRequestedAndDrawnAsTheirRoot) {
  const test::World w = twoCharts(3, 5, 2);
  // Chart 0 split once (resolutions 3 and 4), chart 1 whole; only the roots are resident.
  std::vector<CutNode> nodes = children(node(0, 0, 0, 0), 3, 2.5f);
  nodes[2].resLog2 = 4;
  nodes[3].errorPx = 5000.f;  // capped at 999 in the priority
  nodes.push_back({node(1, 0, 0, 0), 2, 0.5f});
  const Cut desired = makeCut(nodes);
  const std::unordered_set<uint64_t> resident = roots(w);
  // One child is loaded already (waiting for upload): wanted, not requested again.
  const std::unordered_set<uint64_t> loaded = {nodes[1].id.key()};
  const PageRequestPlan plan = planPageRequests(w.h, desired, residentSet(resident), loaded);
  ASSERT_EQ(plan.requests.size(), 3u);
  EXPECT_EQ(plan.requests[0].id, nodes[0].id);
  EXPECT_EQ(plan.requests[1].id, nodes[2].id);
  EXPECT_EQ(plan.requests[2].id, nodes[3].id);
  EXPECT_DOUBLE_EQ(plan.requests[0].priority, 2e3 + 2.5);  // (depth - level) * 1e3 + error
  expectCoarserThenLargerErrorFirst(plan, desired);
  EXPECT_EQ(plan.wanted.size(), 4u);
  {
    // With chart 1's root missing too, it comes before the child whose error is far above the
    // others (5000 px): no error lifts a finer page ahead of a coarser one.
    std::unordered_set<uint64_t> chart0 = {node(0, 0, 0, 0).key()};
    const PageRequestPlan both = planPageRequests(w.h, desired, residentSet(chart0), loaded);
    ASSERT_EQ(both.requests.size(), 4u);
    EXPECT_EQ(both.requests.back().id, node(1, 0, 0, 0));
    expectCoarserThenLargerErrorFirst(both, desired);
  }
  for (uint32_t i = 0; i < 4; ++i) EXPECT_TRUE(plan.wanted.count(nodes[i].id.key()));

  const ViewParams view = overview(w);
  const ResidentCut r = substituteResident(w.h, desired, view, residentSet(resident));
  EXPECT_EQ(r.nodesSubstituted, 4u);
  EXPECT_EQ(r.stitchUnfixable, 0u);
  ASSERT_EQ(r.cut.nodes.size(), 2u);
  // The root stands in at the finest resolution of the nodes it replaces, in the first one's place.
  EXPECT_EQ(r.cut.nodes[0].id, node(0, 0, 0, 0));
  EXPECT_EQ(r.cut.nodes[0].resLog2, 4u);
  EXPECT_FLOAT_EQ(r.cut.nodes[0].errorPx, float(screenError(w.h, node(0, 0, 0, 0), 4, view)));
  EXPECT_EQ(r.cut.nodes[1].id, node(1, 0, 0, 0));
  EXPECT_EQ(r.cut.nodes[1].errorPx, 0.5f);
  EXPECT_EQ(r.cut.find(node(1, 0, 0, 0)), 1);
  test::expectPartition(w.h, r.cut);
}

TEST(Residency, MissingAncestorsAreRequestedOnceAndCoarserFirst) {
  const test::World w = twoCharts(3, 5, 2);
  // Chart 0: (1,0,0) split into level 2, its three siblings at level 1; chart 1 whole.
  std::vector<CutNode> nodes = children(node(0, 1, 0, 0), 3, 1.f);
  for (uint32_t i = 1; i < 4; ++i) nodes.push_back({node(0, 0, 0, 0).child(i), 3, 1.f});
  nodes.push_back({node(1, 0, 0, 0), 3, 1.f});
  const Cut desired = makeCut(nodes);
  std::unordered_set<uint64_t> resident = roots(w);
  resident.insert(node(0, 1, 1, 0).key());
  const PageRequestPlan plan = planPageRequests(w.h, desired, residentSet(resident), {});
  // First child, then its parent (once), then the other children, then the missing siblings.
  ASSERT_EQ(plan.requests.size(), 7u);
  EXPECT_EQ(plan.requests[0].id, nodes[0].id);
  EXPECT_EQ(plan.requests[1].id, node(0, 1, 0, 0));
  expectCoarserThenLargerErrorFirst(plan, desired);
  EXPECT_EQ(plan.requests[2].id, nodes[1].id);
  EXPECT_EQ(plan.requests[4].id, nodes[3].id);
  EXPECT_EQ(plan.requests[5].id, node(0, 1, 0, 1));
  EXPECT_EQ(plan.requests[6].id, node(0, 1, 1, 1));
  EXPECT_EQ(plan.wanted.size(), 7u);
  EXPECT_FALSE(plan.wanted.count(node(0, 1, 1, 0).key()));

  // The root stands in for chart 0's missing nodes and, to keep a partition, for the resident
  // (1,1,0) under it.
  const ResidentCut r = substituteResident(w.h, desired, overview(w), residentSet(resident));
  EXPECT_EQ(r.nodesSubstituted, 7u);
  ASSERT_EQ(r.cut.nodes.size(), 2u);
  EXPECT_EQ(r.cut.nodes[0].id, node(0, 0, 0, 0));
  EXPECT_EQ(r.cut.nodes[0].resLog2, 3u);
  test::expectPartition(w.h, r.cut);
}

TEST(Residency, InnerSubstitutesGiveWayToOuterOnes) {
  const test::World w = twoCharts(3, 5, 2);
  std::vector<CutNode> nodes = children(node(0, 1, 0, 0), 4);
  nodes.push_back({node(0, 1, 1, 0), 2});
  for (uint32_t i = 2; i < 4; ++i) nodes.push_back({node(0, 0, 0, 0).child(i), 2});
  nodes.push_back({node(1, 0, 0, 0), 2});
  const Cut desired = makeCut(nodes);
  // (1,0,0) resident: it would stand in for its children, but (1,1,0) needs the root, which
  // covers it.
  std::unordered_set<uint64_t> resident = roots(w);
  resident.insert(node(0, 1, 0, 0).key());
  resident.insert(node(0, 1, 0, 1).key());
  resident.insert(node(0, 1, 1, 1).key());
  const ResidentCut r = substituteResident(w.h, desired, overview(w), residentSet(resident));
  ASSERT_EQ(r.cut.nodes.size(), 2u);
  EXPECT_EQ(r.cut.nodes[0].id, node(0, 0, 0, 0));
  EXPECT_EQ(r.cut.nodes[0].resLog2, 4u);
  EXPECT_EQ(r.nodesSubstituted, 7u);
  // With (1,1,0) resident too, (1,0,0) stands in for its children alone.
  resident.insert(node(0, 1, 1, 0).key());
  const ResidentCut s = substituteResident(w.h, desired, overview(w), residentSet(resident));
  EXPECT_EQ(s.nodesSubstituted, 4u);
  ASSERT_EQ(s.cut.nodes.size(), 5u);
  EXPECT_EQ(s.cut.nodes[0].id, node(0, 1, 0, 0));
  EXPECT_EQ(s.cut.nodes[0].resLog2, 4u);
  test::expectPartition(w.h, s.cut);
  EXPECT_EQ(countStitchViolations(w.h, s.cut), 0u);
}

TEST(Residency, SubstitutesAreRaisedForTheStitchingConstraint) {
  // Resolutions from 2^0, so a coarse stand-in at its children's resolution violates the
  // constraint next to finer nodes; log2 R = depth - 1, so raising always fixes it.
  const test::World w = twoCharts(4, 3, 0);
  std::vector<CutNode> nodes;
  for (uint32_t y = 0; y < 4; ++y)
    for (uint32_t x = 0; x < 4; ++x) nodes.push_back({node(0, 2, x, y), 0});
  nodes.push_back({node(1, 0, 0, 0), 2});
  const Cut desired = makeCut(nodes);
  ASSERT_EQ(countStitchViolations(w.h, desired), 0u);
  // Everything resident but the children of the top-right level-1 node.
  std::unordered_set<uint64_t> resident = roots(w);
  for (const CutNode& n : desired.nodes) resident.insert(n.id.key());
  for (uint32_t i = 0; i < 4; ++i) {
    resident.insert(node(0, 0, 0, 0).child(i).key());
    resident.erase(node(0, 1, 1, 1).child(i).key());
  }
  const ViewParams view = overview(w);
  const ResidentCut r = substituteResident(w.h, desired, view, residentSet(resident));
  EXPECT_EQ(r.nodesSubstituted, 4u);
  EXPECT_EQ(r.stitchUnfixable, 0u);
  EXPECT_EQ(countStitchViolations(w.h, r.cut), 0u);
  const int32_t i = r.cut.find(node(0, 1, 1, 1));
  ASSERT_GE(i, 0);
  EXPECT_EQ(r.cut.nodes[i].resLog2, 1u);  // one level above its level-2 neighbours
  EXPECT_FLOAT_EQ(r.cut.nodes[i].errorPx, float(screenError(w.h, node(0, 1, 1, 1), 1, view)));
  test::expectPartition(w.h, r.cut);
}

TEST(Residency, UnfixableStitchingIsCounted) {
  // log2 R = 1 < depth - 1: a root standing in next to level-3 nodes cannot be raised enough.
  const test::World w = twoCharts(4, 1, 0);
  std::vector<CutNode> nodes;
  for (uint32_t c = 0; c < 2; ++c)
    for (uint32_t y = 0; y < 8; ++y)
      for (uint32_t x = 0; x < 8; ++x) nodes.push_back({node(c, 3, x, y), 0});
  const Cut desired = makeCut(nodes);
  std::unordered_set<uint64_t> resident = roots(w);
  for (uint32_t k = 0; k < 64; ++k) resident.insert(nodes[k].id.key());  // chart 0's leaves
  const ResidentCut r = substituteResident(w.h, desired, overview(w), residentSet(resident));
  EXPECT_EQ(r.nodesSubstituted, 64u);
  EXPECT_EQ(r.stitchUnfixable, 1u);
  ASSERT_EQ(r.cut.nodes.size(), 65u);
  EXPECT_EQ(r.cut.nodes[64].id, node(1, 0, 0, 0));
  EXPECT_EQ(r.cut.nodes[64].resLog2, 0u);  // left as it was: 2^1 is its finest
}

TEST(Residency, ARootOnItsStandInHoldsTheChartsBesideItCoarse) {
  // log2 R = depth - 1 and resolutions from 2^0. Chart 1's root wants 2^3 beside chart 0's level-3
  // leaves, but its page is missing and its stand-in holds it at 2^1 only: chart 0 is held to
  // level 1 (its resident level-1 nodes stand in for the leaves), and the root draws at 2^1.
  const test::World w = twoCharts(4, 3, 0);
  std::vector<CutNode> nodes;
  for (uint32_t y = 0; y < 8; ++y)
    for (uint32_t x = 0; x < 8; ++x) nodes.push_back({node(0, 3, x, y), 0});
  nodes.push_back({node(1, 0, 0, 0), 3});
  const Cut desired = makeCut(nodes);
  ASSERT_EQ(countStitchViolations(w.h, desired), 0u);
  std::unordered_set<uint64_t> resident;
  for (uint32_t level = 0; level < 4; ++level)
    for (uint32_t y = 0; y < (1u << level); ++y)
      for (uint32_t x = 0; x < (1u << level); ++x) resident.insert(node(0, level, x, y).key());
  const ViewParams view = overview(w);
  // Without a stand-in's limit the root would be drawn at its own resolution.
  RootStandIns standIns;
  standIns.resLog2 = {1, 1};
  const ResidentCut r = substituteResident(w.h, desired, view, residentSet(resident), standIns);
  EXPECT_EQ(r.stitchUnfixable, 0u);
  EXPECT_EQ(r.rootsOnStandIns, 1u);
  EXPECT_EQ(r.chartsCoarsened, 1u);
  EXPECT_EQ(countStitchViolations(w.h, r.cut), 0u);
  test::expectPartition(w.h, r.cut);
  ASSERT_EQ(r.cut.nodes.size(), 5u);  // chart 0's four level-1 nodes and chart 1's root
  for (const CutNode& n : r.cut.nodes) {
    if (n.id.chart == 0) {
      EXPECT_EQ(n.id.level, 1u);
    } else {
      EXPECT_EQ(n.id, node(1, 0, 0, 0));
      EXPECT_EQ(n.resLog2, 1u);  // raised to its stand-in's resolution, no further
      EXPECT_FLOAT_EQ(n.errorPx, float(screenError(w.h, n.id, 1, view)));
    }
  }
  // A stand-in as fine as the gap needs leaves chart 0 alone.
  standIns.resLog2 = {3, 3};
  const ResidentCut fine = substituteResident(w.h, desired, view, residentSet(resident), standIns);
  EXPECT_EQ(fine.chartsCoarsened, 0u);
  EXPECT_EQ(fine.cut.nodes.size(), desired.nodes.size());
  EXPECT_EQ(countStitchViolations(w.h, fine.cut), 0u);
}

TEST(Residency, RootsOnStandInsCoarsenInTurn) {
  // Both roots missing, stand-ins of 2^1, chart 0 desired at level 3 and chart 1 at level 2 with
  // no page resident: each chart falls to its root, on its stand-in, and nothing is left unstitched.
  const test::World w = twoCharts(4, 3, 0);
  std::vector<CutNode> nodes;
  for (uint32_t y = 0; y < 8; ++y)
    for (uint32_t x = 0; x < 8; ++x) nodes.push_back({node(0, 3, x, y), 0});
  for (uint32_t y = 0; y < 4; ++y)
    for (uint32_t x = 0; x < 4; ++x) nodes.push_back({node(1, 2, x, y), 1});
  const Cut desired = makeCut(nodes);
  std::unordered_set<uint64_t> resident;
  for (uint32_t y = 0; y < 8; ++y)
    for (uint32_t x = 0; x < 8; ++x) resident.insert(node(0, 3, x, y).key());  // chart 0's leaves only
  RootStandIns standIns;
  standIns.resLog2 = {1, 1};
  const ResidentCut r = substituteResident(w.h, desired, overview(w), residentSet(resident), standIns);
  EXPECT_EQ(r.stitchUnfixable, 0u);
  EXPECT_EQ(countStitchViolations(w.h, r.cut), 0u);
  test::expectPartition(w.h, r.cut);
  ASSERT_EQ(r.cut.nodes.size(), 2u);
  EXPECT_EQ(r.rootsOnStandIns, 2u);
  for (const CutNode& n : r.cut.nodes) {
    EXPECT_EQ(n.id.level, 0u);
    EXPECT_LE(n.resLog2, 1u);
  }
}

}  // namespace
}  // namespace gimlod

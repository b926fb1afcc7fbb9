// The nodes above the charts: chart roots gathered into groups (hierarchy/root_groups.h), and
// every adapter holding its node budget below the chart count by keeping groups closed
// (runtime/group_select.h), on hand-made forests.
#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <map>
#include <random>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "hierarchy/root_groups.h"
#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/baselines.h"
#include "runtime/group_select.h"
#include "tests/adapt_fixture.h"

namespace gimlod {
namespace {

using test::makeWorld;
using test::viewAt;
using test::World;

// 64 charts (8 x 8) of 129 samples, three levels, gathered into at most 4 top groups.
World groupedWorld(uint32_t maxRoots = 4) {
  World w = makeWorld(129, 8, 8, 3);
  w.h.groups = buildRootGroups(w.h, maxRoots);
  return w;
}

bool boxContains(const std::array<float, 6>& outer, const std::array<float, 6>& inner) {
  for (int k = 0; k < 3; ++k)
    if (inner[k] < outer[k] || inner[k + 3] > outer[k + 3]) return false;
  return true;
}

TEST(RootGroups, ATreeOverEveryChartWithFewTops) {
  const World w = groupedWorld();
  const RootGroups& g = w.h.groups;
  ASSERT_FALSE(g.empty());
  EXPECT_LE(g.tops.size(), 4u);
  EXPECT_GE(g.tops.size(), 1u);
  ASSERT_EQ(g.order.size(), 64u);
  EXPECT_EQ(std::set<uint32_t>(g.order.begin(), g.order.end()).size(), 64u) << "each chart once";
  std::vector<uint32_t> firstLevelOf(64, UINT32_MAX);
  for (uint32_t i = 0; i < g.groups.size(); ++i) {
    const RootGroups::Group& gr = g.groups[i];
    SCOPED_TRACE("group " + std::to_string(i));
    ASSERT_LT(gr.begin, gr.end);
    float errMin = 0.f, errMax = 0.f;
    for (uint32_t k = gr.begin; k < gr.end; ++k) {
      const NodeId root{g.order[k], 0, 0, 0};
      EXPECT_TRUE(boxContains(gr.bounds, w.h.bounds(root)));
      errMin = std::max(errMin, w.h.error(root, w.h.params.minNodeResLog2));
      errMax = std::max(errMax, w.h.error(root, w.h.maxResLog2(root)));
      if (gr.level == 0) firstLevelOf[g.order[k]] = i;
    }
    EXPECT_EQ(gr.errorMin, errMin);
    EXPECT_EQ(gr.errorMax, errMax);
    const uint32_t children = gr.childEnd - gr.childBegin;
    EXPECT_GE(children, 1u);
    EXPECT_LE(children, kGroupFanout);
    if (gr.level > 0) {  // the children's charts, in order, are the group's
      EXPECT_EQ(g.groups[gr.childBegin].begin, gr.begin);
      EXPECT_EQ(g.groups[gr.childEnd - 1].end, gr.end);
      for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c) {
        EXPECT_EQ(g.groups[c].parent, int32_t(i));
        EXPECT_EQ(g.groups[c].level + 1, gr.level);
        if (c > gr.childBegin) {
          EXPECT_EQ(g.groups[c - 1].end, g.groups[c].begin);
        }
      }
    }
    EXPECT_EQ(gr.parent < 0, std::count(g.tops.begin(), g.tops.end(), i) == 1);
  }
  for (uint32_t c = 0; c < 64; ++c) EXPECT_EQ(g.chartGroup[c], int32_t(firstLevelOf[c])) << "chart " << c;
  // Deterministic.
  const RootGroups again = buildRootGroups(w.h, 4);
  EXPECT_EQ(again.order, g.order);
  EXPECT_EQ(again.tops, g.tops);
}

TEST(RootGroups, NoGroupsWhereTheRootsAreFewOrCouldNotStitch) {
  World w = makeWorld(129, 4, 4, 3);  // 16 charts
  EXPECT_TRUE(buildRootGroups(w.h, 16).empty()) << "no more charts than roots allowed";
  EXPECT_FALSE(buildRootGroups(w.h, 15).empty());
  EXPECT_TRUE(buildRootGroups(w.h, 0).empty()) << "0: no groups";
  // maxResLog2(root) 4 < depth - 1 = 5: a closed group's root could need a split to stitch.
  World deep;
  deep.m = test::syntheticManifest(129, 8, 8, 6, 4, 2);
  deep.h = buildTerrainHierarchy(deep.m, [&](uint32_t c) { return test::syntheticChart(deep.m, c); });
  EXPECT_TRUE(buildRootGroups(deep.h, 4).empty());
}

using test::allAdapters;
using test::Outcome;

// The visible top groups, by the frustum test itself.
uint32_t visibleTops(const Hierarchy& h, const ViewParams& v, bool cull) {
  uint32_t n = 0;
  for (uint32_t t : h.groups.tops) {
    const auto& b = h.groups.groups[t].bounds;
    n += !cull || v.frustum.intersects({b[0], b[1], b[2]}, {b[3], b[4], b[5]});
  }
  return n;
}

// A cut's groups: every grouped node a root, each closed group drawing all of its drawable roots,
// and the counts the stats give.
void expectGroupsWhole(const Hierarchy& h, const ViewParams& v, bool cull, const Outcome& o) {
  std::map<int32_t, std::set<uint32_t>> drawn;
  uint32_t grouped = 0;
  for (const CutNode& n : o.cut.nodes) {
    if (n.group < 0) continue;
    ++grouped;
    EXPECT_EQ(n.id.level, 0u) << "a closed group's chart was split";
    drawn[n.group].insert(n.id.chart);
  }
  for (const auto& [g, charts] : drawn) {
    ASSERT_LT(uint32_t(g), h.groups.groups.size());
    const RootGroups::Group& gr = h.groups.groups[size_t(g)];
    std::set<uint32_t> want;
    for (uint32_t k = gr.begin; k < gr.end; ++k)
      if (nodeDrawable(h, {h.groups.order[k], 0, 0, 0}, v, cull)) want.insert(h.groups.order[k]);
    EXPECT_EQ(charts, want) << "group " << g;
    for (uint32_t c : want) EXPECT_EQ(o.cut.find({c, 0, 0, 0}) >= 0, true);
  }
  EXPECT_EQ(o.groupedRoots, grouped);
  EXPECT_EQ(o.closedGroups, uint32_t(drawn.size()));
  EXPECT_EQ(o.nodes, o.cut.nodeCount());
  EXPECT_EQ(o.cut.nodeCount(), uint32_t(o.cut.nodes.size()) - grouped + uint32_t(drawn.size()));
}

TEST(RootGroups, EveryAdapterHoldsABudgetBelowTheChartCount) {
  const World w = groupedWorld();
  const ViewParams all = viewAt(w, {512, -320, 640}, {512, 512, 0});
  for (bool cull : {true, false}) {
    SCOPED_TRACE(cull ? "culled" : "not culled");
    ASSERT_EQ(countVisibleRoots(w.h, all, cull), 64u) << "the view sees every chart";
    const uint32_t tops = visibleTops(w.h, all, cull);
    for (auto& [name, run, coherent] : allAdapters(w.h, 0.05, 1000000, cull)) {
      SCOPED_TRACE(name);
      const Outcome unlimited = run(all, 0);
      EXPECT_GT(unlimited.cut.nodes.size(), 64u) << "the tolerance asks for splits";
      EXPECT_EQ(unlimited.closedGroups, 0u) << "no limit: every group open";
      EXPECT_EQ(unlimited.rootFloor, tops);
      for (uint32_t budget : {2u, 4u, 10u, 24u, 40u, 63u, 100u}) {
        SCOPED_TRACE("budget " + std::to_string(budget));
        const Outcome o = run(all, budget);
        EXPECT_EQ(o.rootFloor, tops);
        EXPECT_EQ(o.budgetBelowRoots, budget < tops);
        EXPECT_LE(o.cut.nodeCount(), std::max(budget, tops));
        EXPECT_EQ(countStitchViolations(w.h, o.cut), 0u);
        if (!cull) test::expectPartition(w.h, o.cut);
        expectGroupsWhole(w.h, all, cull, o);
        if (budget < 64) {
          EXPECT_GT(o.closedGroups, 0u) << "fewer nodes than charts need closed groups";
        }
      }
    }
  }
}

// Close over one corner: the groups there open and split, the far ones stay closed.
TEST(RootGroups, GroupsOpenWhereTheErrorIs) {
  const World w = groupedWorld();
  const ViewParams corner = viewAt(w, {20, 20, 40}, {300, 300, 0});
  for (auto& [name, run, coherent] : allAdapters(w.h, 0.5, 200000, true)) {
    SCOPED_TRACE(name);
    const Outcome o = run(corner, 40);
    EXPECT_LE(o.cut.nodeCount(), 40u);
    EXPECT_EQ(countStitchViolations(w.h, o.cut), 0u);
    expectGroupsWhole(w.h, corner, true, o);
    // The chart under the eye (chart 0) is split; some chart far away is in a closed group.
    bool nearSplit = false, farClosed = false;
    for (const CutNode& n : o.cut.nodes) {
      nearSplit |= n.id.chart == 0 && n.id.level > 0;
      farClosed |= n.group >= 0;
    }
    EXPECT_TRUE(nearSplit);
    EXPECT_TRUE(farClosed);
  }
}

// With room for every root in a quarter of the budget, every group opens: the cut is the one the
// same forest gives without groups.
TEST(RootGroups, ARoomyBudgetGivesTheCutWithoutGroups) {
  const World grouped = groupedWorld();
  World plain = makeWorld(129, 8, 8, 3);
  const ViewParams v = viewAt(plain, {300, -100, 200}, {400, 400, 0});
  auto a = allAdapters(grouped.h, 0.3, 300000, true);
  auto b = allAdapters(plain.h, 0.3, 300000, true);
  for (size_t i = 0; i < a.size(); ++i) {
    SCOPED_TRACE(a[i].name);
    for (uint32_t budget : {256u, 1000u}) {
      const Outcome x = a[i].run(v, budget), y = b[i].run(v, budget);
      EXPECT_EQ(x.closedGroups, 0u);
      EXPECT_EQ(test::sortedNodes(x.cut), test::sortedNodes(y.cut));
    }
  }
}

// Along a moving camera with a changing budget, the coherent adapters collapse the charts of a
// group that closes, and keep the budget in every frame.
TEST(RootGroups, CoherentAdaptersAlongAPath) {
  const World w = groupedWorld();
  DualQueueAdapter dq(w.h);
  QuadQueueAdapter qq(w.h);
  for (int i = 0; i < 40; ++i) {
    const double t = double(i) / 39.0;
    const ViewParams v = viewAt(w, {20 + 900 * t, 40 + 300 * t, 30 + 200 * t}, {512, 512, 0});
    const uint32_t budget = (i / 5) % 2 ? 12 : 60;
    SCOPED_TRACE("frame " + std::to_string(i) + ", budget " + std::to_string(budget));
    AdaptOptions ao;
    ao.tolerancePx = 0.3;
    ao.maxNodes = budget;
    AdaptStats as;
    const Cut& a = dq.update(v, ao, &as);
    EXPECT_LE(a.nodeCount(), std::max(budget, as.rootFloor));
    EXPECT_EQ(countStitchViolations(w.h, a), 0u);
    expectGroupsWhole(w.h, v, true, test::outcomeOf(a, as));
    BudgetOptions bo;
    bo.maxTriangles = 150000;
    bo.maxNodes = budget;
    BudgetStats bs;
    const Cut& b = qq.update(v, bo, &bs);
    EXPECT_LE(b.nodeCount(), std::max(budget, bs.rootFloor));
    EXPECT_LE(b.triangles(), bo.maxTriangles);
    EXPECT_EQ(countStitchViolations(w.h, b), 0u);
    expectGroupsWhole(w.h, v, true, test::outcomeOf(b, bs));
  }
}

// Random views, budgets, tolerances and group trees: every adapter keeps its budget (or draws the
// floor when the budget is below it), a partition without stitching violations, whole closed groups,
// and counts that agree with the cut; the coherent adapters carry their state from view to view.
TEST(RootGroups, RandomViewsAndBudgetsKeepTheInvariants) {
  std::mt19937 rng(20261129);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (uint32_t maxRoots : {2u, 5u, 16u}) {
    const World w = groupedWorld(maxRoots);
    ASSERT_FALSE(w.h.groups.empty());
    for (bool cull : {true, false}) {
      const double tol = 0.1 + 2.0 * unit(rng);
      auto adapters = allAdapters(w.h, tol, 20000 + uint64_t(400000 * unit(rng)), cull);
      for (int i = 0; i < 40; ++i) {
        const glm::dvec3 eye{-200 + 1400 * unit(rng), -200 + 1400 * unit(rng), 10 + 600 * unit(rng)};
        const glm::dvec3 target{1024 * unit(rng), 1024 * unit(rng), 0};
        const ViewParams v = viewAt(w, eye, target);
        const uint32_t budget = uint32_t(1 + 150 * unit(rng) * unit(rng));
        for (auto& [name, run, coherent] : adapters) {
          SCOPED_TRACE(name + ", max roots " + std::to_string(maxRoots) + (cull ? ", culled" : "") + ", view " +
                       std::to_string(i) + ", budget " + std::to_string(budget));
          const Outcome o = run(v, budget);
          EXPECT_EQ(o.rootFloor, visibleTops(w.h, v, cull));
          EXPECT_EQ(o.budgetBelowRoots, budget < o.rootFloor);
          EXPECT_LE(o.cut.nodeCount(), std::max(budget, o.rootFloor));
          EXPECT_EQ(countStitchViolations(w.h, o.cut), 0u);
          if (!cull) test::expectPartition(w.h, o.cut);
          expectGroupsWhole(w.h, v, cull, o);
        }
      }
    }
  }
}

}  // namespace
}  // namespace gimlod

// Shared fixtures for the adaptation tests: a small synthetic world, views into it, and cut
// checks.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/baselines.h"
#include "runtime/stitch.h"
#include "runtime/camera.h"
#include "tests/synthetic_terrain.h"

namespace gimlod::test {

struct World {
  AtlasManifest m;
  Hierarchy h;
  glm::dvec3 lo, hi;
};

// A cx x cy grid of synthetic charts with max node resolution 2^5 and min 2^2.
inline World makeWorld(uint32_t chartSize, uint32_t cx, uint32_t cy, uint32_t depth) {
  World w;
  w.m = syntheticManifest(chartSize, cx, cy, depth, 5, 2);
  w.h = buildTerrainHierarchy(w.m, [&](uint32_t c) { return syntheticChart(w.m, c); });
  w.lo = {0, 0, -30};
  w.hi = {double(w.m.samplesX), double(w.m.samplesY), 30};
  return w;
}

// A 320x240 view from eye towards target, clip planes fitted to the world.
inline ViewParams viewAt(const World& w, glm::dvec3 eye, glm::dvec3 target) {
  Camera c;
  c.eye = eye;
  c.target = target;
  c.nearPlane = 0.0;
  c.farPlane = 0.0;
  fitClipPlanes(c, w.lo, w.hi);
  return makeViewParams(c, 320, 240);
}

// No node together with an ancestor; when full (no culling, no empty nodes), the cut's area is
// all chart area.
inline void expectPartition(const Hierarchy& h, const Cut& cut, bool full = true) {
  const uint32_t L = h.params.intervalsLog2;
  uint64_t area = 0;
  for (const CutNode& n : cut.nodes) {
    area += 1ull << (2 * (L - n.id.level));
    for (NodeId a = n.id; a.level > 0;) {
      a = a.parent();
      ASSERT_LT(cut.find(a), 0) << "node and its ancestor both in the cut";
    }
  }
  if (full) {
    EXPECT_EQ(area, uint64_t(h.chartCount()) << (2 * L));
  }
}

// (key, resolution) of every cut node, sorted: equal for equal cuts.
inline std::vector<std::pair<uint64_t, uint32_t>> sortedNodes(const Cut& cut) {
  std::vector<std::pair<uint64_t, uint32_t>> v;
  for (const CutNode& n : cut.nodes) v.push_back({n.id.key(), n.resLog2});
  std::sort(v.begin(), v.end());
  return v;
}

// Updates until a frame ends without hitting the operation cap.
inline const Cut& converge(DualQueueAdapter& a, const ViewParams& v, const AdaptOptions& o, AdaptStats* st) {
  for (int i = 0; i < 1000; ++i) {
    const Cut& c = a.update(v, o, st);
    if (!a.frameStats().opCapBound) return c;
  }
  ADD_FAILURE() << "did not converge";
  return a.update(v, o, st);
}

inline bool withinToleranceOrFinest(const Hierarchy& h, const CutNode& n, double tol) {
  const bool finest = n.resLog2 == h.params.maxResLog2(n.id.level) && n.id.level + 1 == h.params.depth;
  return finest || n.errorPx <= tol + 1e-9;
}

// Within the triangle and node budgets (constraint splits merged back), the stats agree with the
// cut, stitched.
inline void expectWithinBudget(const Hierarchy& h, const Cut& cut, const BudgetOptions& o, const BudgetStats& st) {
  EXPECT_LE(cut.triangles(), o.maxTriangles);
  EXPECT_EQ(st.triangles, cut.triangles());
  EXPECT_EQ(countStitchViolations(h, cut), 0u);
  EXPECT_LE(cut.nodeCount(), o.maxNodes) << st.constraintSplits << " constraint splits";
  EXPECT_EQ(st.nodes, cut.nodeCount());
}

// One adapter under test: adapts to a view with a node budget; returns the cut with its counts.
struct Outcome {
  Cut cut;
  uint32_t rootFloor = 0;
  bool budgetBelowRoots = false;
  uint32_t constraintSplits = 0;
  uint32_t nodes = 0, closedGroups = 0, groupedRoots = 0;  // the adapter's stats
};
using Run = std::function<Outcome(const ViewParams&, uint32_t maxNodes)>;
struct NamedAdapter {
  std::string name;
  Run run;
  bool coherent = false;  // keeps its cut across calls
};

inline Outcome outcomeOf(Cut cut, const AdaptStats& st) {
  return {std::move(cut), st.rootFloor,    st.budgetBelowRoots, st.constraintSplits,
          st.nodes,       st.closedGroups, st.groupedRoots};
}
inline Outcome outcomeOf(Cut cut, const BudgetStats& st) {
  return {std::move(cut), st.rootFloor,    st.budgetBelowRoots, st.constraintSplits,
          st.nodes,       st.closedGroups, st.groupedRoots};
}

// Every adapter, in error-threshold mode at tolerancePx and in triangle-budget mode at
// maxTriangles. The coherent adapters keep their state across calls (a camera path).
inline std::vector<NamedAdapter> allAdapters(const Hierarchy& h, double tolerancePx, uint64_t maxTriangles, bool cull) {
  auto dq = std::make_shared<DualQueueAdapter>(h);
  auto qq = std::make_shared<QuadQueueAdapter>(h);
  auto adaptOpts = [=](uint32_t maxNodes) {
    AdaptOptions o;
    o.tolerancePx = tolerancePx;
    o.maxNodes = maxNodes;
    o.frustumCull = cull;
    return o;
  };
  auto budgetOpts = [=](uint32_t maxNodes) {
    BudgetOptions o;
    o.maxTriangles = maxTriangles;
    o.maxNodes = maxNodes;
    o.frustumCull = cull;
    return o;
  };
  const Hierarchy* hp = &h;
  return {
      {"dual queue",
       [=](const ViewParams& v, uint32_t n) {
         AdaptStats st;
         Cut cut = dq->update(v, adaptOpts(n), &st);
         return outcomeOf(std::move(cut), st);
       },
       true},
      {"top-down greedy",
       [=](const ViewParams& v, uint32_t n) {
         AdaptStats st;
         Cut cut = adaptTopDownGreedy(*hp, v, tolerancePx, n, &st, cull);
         return outcomeOf(std::move(cut), st);
       }},
      {"fixed granularity",
       [=](const ViewParams& v, uint32_t n) {
         AdaptStats st;
         Cut cut = adaptFixedGranularity(*hp, v, tolerancePx, n, &st, cull);
         return outcomeOf(std::move(cut), st);
       }},
      {"quad queue",
       [=](const ViewParams& v, uint32_t n) {
         BudgetStats st;
         Cut cut = qq->update(v, budgetOpts(n), &st);
         return outcomeOf(std::move(cut), st);
       },
       true},
      {"fixed granularity (triangle budget)",
       [=](const ViewParams& v, uint32_t n) {
         BudgetStats st;
         Cut cut = adaptFixedGranularityBudget(*hp, v, budgetOpts(n), &st);
         return outcomeOf(std::move(cut), st);
       }},
      {"greedy (triangle budget)",
       [=](const ViewParams& v, uint32_t n) {
         BudgetStats st;
         Cut cut = adaptGreedyBudget(*hp, v, budgetOpts(n), &st);
         return outcomeOf(std::move(cut), st);
       }},
  };
}

}  // namespace gimlod::test

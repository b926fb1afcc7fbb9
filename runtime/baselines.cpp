// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (traditional fixed-granularity LOD as
// the comparison point, and the simple top-down algorithm); section 7.4 (stitching constraint).
#include "runtime/baselines.h"

#include <algorithm>
#include <cmath>
#include <queue>
#include <unordered_map>

#include "runtime/adapt_dual_queue.h"
#include "runtime/group_select.h"

namespace gimlod {

Cut adaptFixedGranularity(const Hierarchy& h, const ViewParams& view, double tolerancePx, uint32_t maxNodes,
                          AdaptStats* stats, bool frustumCull) {
  AdaptStats st;
  GroupSelection groups;
  selectRootGroups(h, {view, tolerancePx, frustumCull}, maxNodes, groups);
  const uint32_t chartBudget = groups.chartBudget(maxNodes);  // every root a node (group_select.h)
  const uint32_t budget = chartBudget == 0 ? UINT32_MAX : chartBudget;
  struct Candidate {
    double errorPx;
    NodeId id;
  };
  auto byError = [](const Candidate& a, const Candidate& b) { return a.errorPx < b.errorPx; };
  std::priority_queue<Candidate, std::vector<Candidate>, decltype(byError)> queue(byError);
  auto candidate = [&](const NodeId& n) { return Candidate{screenError(h, n, h.maxResLog2(n), view), n}; };
  std::vector<NodeId> done;
  uint32_t count = 0;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    if (!nodeDrawable(h, root, view, frustumCull)) {
      ++st.culled;
      continue;
    }
    queue.push(candidate(root));
    ++count;
  }
  st.rootFloor = groups.rootFloor;
  st.budgetBelowRoots = budgetBelowRoots(maxNodes, st.rootFloor);
  while (!queue.empty()) {
    const Candidate c = queue.top();
    queue.pop();
    if (c.errorPx <= tolerancePx || c.id.level + 1 >= h.params.depth) {
      done.push_back(c.id);
      continue;
    }
    if (groups.frozen(c.id.chart)) {  // a closed group's root: held for the node budget
      st.nodeBudgetBound = true;
      done.push_back(c.id);
      continue;
    }
    uint32_t children = 0;
    for (uint32_t i = 0; i < 4; ++i) children += nodeDrawable(h, c.id.child(i), view, frustumCull);
    if (count - 1 + children > budget) {
      st.nodeBudgetBound = true;
      done.push_back(c.id);
      continue;
    }
    ++st.splits;
    count = count - 1 + children;
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = c.id.child(i);
      if (nodeDrawable(h, ch, view, frustumCull))
        queue.push(candidate(ch));
      else
        ++st.culled;
    }
  }
  Cut cut;
  cut.nodes.reserve(done.size());
  for (const NodeId& n : done) cut.nodes.push_back({n, h.maxResLog2(n), 0.f});
  cut.rebuildIndex();
  enforceStitchConstraint(h, cut, &view, tolerancePx, &st);
  if (st.constraintSplits > 0) holdNodeBudget(h, cut, view, chartBudget);
  // Constraint splits give children their needed resolution: back to the fixed one (only raises,
  // so the constraint still holds).
  for (CutNode& n : cut.nodes) {
    n.resLog2 = h.maxResLog2(n.id);
    n.errorPx = float(screenError(h, n.id, n.resLog2, view));
    st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
  }
  markGroupedRoots(groups, cut);
  setCutCounts(cut, st);
  st.triangles = cut.triangles();
  if (stats) *stats = st;
  return cut;
}

Cut adaptTopDownGreedy(const Hierarchy& h, const ViewParams& view, double tolerancePx, uint32_t maxNodes,
                       AdaptStats* stats, bool frustumCull) {
  AdaptOptions o;
  o.tolerancePx = tolerancePx;
  o.maxNodes = maxNodes;
  o.frustumCull = frustumCull;
  return adaptErrorThreshold(h, view, o, stats);
}

namespace {

uint64_t budgetTris(uint32_t res) { return 2ull << (2 * res); }

// Sets every node's errorPx and the cut's nodes, triangles and max/mean error in st.
void measureBudgetCut(const Hierarchy& h, const ViewParams& view, Cut& cut, BudgetStats& st) {
  AdaptStats counts;
  setCutCounts(cut, counts);
  st.nodes = counts.nodes;
  st.closedGroups = counts.closedGroups;
  st.groupedRoots = counts.groupedRoots;
  st.triangles = cut.triangles();
  double sum = 0.0;
  for (CutNode& n : cut.nodes) {
    n.errorPx = float(screenError(h, n.id, n.resLog2, view));
    st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
    sum += n.errorPx;
  }
  st.meanErrorPx = cut.nodes.empty() ? 0.0 : sum / double(cut.nodes.size());
}

// One top-down operation: split id (children at childRes) or raise id's resolution by one.
struct BudgetOp {
  NodeId id;
  bool split = false;
  uint32_t childRes = 0;
};

// A top-down pass's cut as operations: the roots at rootRes, then the operations in order.
struct BudgetOps {
  uint32_t rootRes = 0;
  std::vector<BudgetOp> ops;
};

// Roots (drawable) at plan.rootRes, then the first `count` operations.
Cut replayOps(const Hierarchy& h, const ViewParams& view, bool cull, const BudgetOps& plan, size_t count) {
  const uint32_t rootRes = plan.rootRes;
  const std::vector<BudgetOp>& ops = plan.ops;
  std::unordered_map<uint64_t, CutNode> live;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    if (nodeDrawable(h, root, view, cull)) live[root.key()] = {root, std::min(rootRes, h.maxResLog2(root)), 0.f};
  }
  for (size_t i = 0; i < count; ++i) {
    const BudgetOp& op = ops[i];
    if (!op.split) {
      ++live[op.id.key()].resLog2;
      continue;
    }
    live.erase(op.id.key());
    for (uint32_t k = 0; k < 4; ++k) {
      const NodeId ch = op.id.child(k);
      if (nodeDrawable(h, ch, view, cull)) live[ch.key()] = {ch, std::min(op.childRes, h.maxResLog2(ch)), 0.f};
    }
  }
  Cut cut;
  for (const auto& [k, n] : live) cut.nodes.push_back(n);
  std::sort(cut.nodes.begin(), cut.nodes.end(),
            [](const CutNode& a, const CutNode& b) { return a.id.key() < b.id.key(); });
  cut.rebuildIndex();
  return cut;
}

// Replays the operations, enforces the stitching constraint, and backs off (1, 2, 4, ...
// operations) until the budgets hold. fixedRes: constraint-split children back to maxResLog2(level).
Cut finishBudgetCut(const Hierarchy& h, const ViewParams& view, const BudgetOptions& o, const BudgetOps& plan,
                    bool fixedRes, BudgetStats& st) {
  const std::vector<BudgetOp>& ops = plan.ops;
  const uint64_t nodeBudget = o.maxNodes == 0 ? UINT64_MAX : o.maxNodes;
  size_t count = ops.size(), step = 1;
  Cut cut;
  for (;;) {
    cut = replayOps(h, view, o.frustumCull, plan, count);
    AdaptStats as;
    enforceStitchConstraint(h, cut, &view, 1.0, &as);
    if (fixedRes && as.constraintSplits > 0)
      for (CutNode& n : cut.nodes) n.resLog2 = std::max(n.resLog2, h.maxResLog2(n.id));
    if (!fixedRes) fitTriangleBudget(h, cut, view, o.maxTriangles);
    st.constraintRaises = as.constraintRaises;
    st.constraintSplits = as.constraintSplits;
    if ((cut.triangles() <= o.maxTriangles && cut.nodes.size() <= nodeBudget) || count == 0) break;
    count -= std::min(count, step);
    step *= 2;
  }
  st.refines = st.splits = 0;
  for (size_t i = 0; i < count; ++i) (ops[i].split ? st.splits : st.refines)++;
  measureBudgetCut(h, view, cut, st);
  return cut;
}

struct ErrorItem {
  double errorPx;
  NodeId id;
  uint32_t resLog2;
  bool operator<(const ErrorItem& b) const {
    return errorPx < b.errorPx || (errorPx == b.errorPx && id.key() > b.id.key());
  }
};

}  // namespace

Cut adaptFixedGranularityBudget(const Hierarchy& h, const ViewParams& view, const BudgetOptions& options,
                                BudgetStats* stats) {
  BudgetStats st;
  GroupSelection groups;
  selectRootGroups(h, {view, 0.0, options.frustumCull}, options.maxNodes, groups, options.maxTriangles);
  BudgetOptions o = options;
  o.maxNodes = groups.chartBudget(options.maxNodes);  // every root a node (group_select.h)
  const uint64_t nodeBudget = o.maxNodes == 0 ? UINT64_MAX : o.maxNodes;
  std::priority_queue<ErrorItem> queue;
  uint64_t count = 0;
  for (uint32_t c = 0; c < h.chartCount(); ++c) count += nodeDrawable(h, {c, 0, 0, 0}, view, options.frustumCull);
  st.rootFloor = groups.rootFloor;
  st.budgetBelowRoots = budgetBelowRoots(options.maxNodes, st.rootFloor);
  // The roots' common resolution (each within its chart's finest).
  auto rootTriangles = [&](uint32_t res) {
    uint64_t t = 0;
    for (uint32_t c = 0; c < h.chartCount(); ++c) {
      const NodeId root{c, 0, 0, 0};
      if (nodeDrawable(h, root, view, options.frustumCull)) t += budgetTris(std::min(res, h.maxResLog2(root)));
    }
    return t;
  };
  uint32_t rootRes = h.params.maxResLog2(0);
  while (rootRes > h.params.minNodeResLog2 && rootTriangles(rootRes) > options.maxTriangles) --rootRes;
  uint64_t triangles = rootTriangles(rootRes);
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    const uint32_t res = std::min(rootRes, h.maxResLog2(root));
    if (nodeDrawable(h, root, view, options.frustumCull)) queue.push({screenError(h, root, res, view), root, res});
  }
  BudgetOps plan;
  plan.rootRes = rootRes;
  std::vector<BudgetOp>& ops = plan.ops;
  while (!queue.empty()) {
    const ErrorItem it = queue.top();
    queue.pop();
    if (it.id.level + 1 >= h.params.depth || it.resLog2 != h.maxResLog2(it.id)) continue;
    if (it.id.level == 0 && groups.frozen(it.id.chart)) continue;  // a closed group's root
    const uint32_t cres = h.maxResLog2(it.id.child(0));
    uint64_t children = 0;
    for (uint32_t i = 0; i < 4; ++i) children += nodeDrawable(h, it.id.child(i), view, options.frustumCull);
    const uint64_t t = triangles - budgetTris(it.resLog2) + children * budgetTris(cres);
    if (t > options.maxTriangles || count - 1 + children > nodeBudget) continue;
    triangles = t;
    count = count - 1 + children;
    ops.push_back({it.id, true, cres});
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = it.id.child(i);
      if (nodeDrawable(h, ch, view, options.frustumCull)) queue.push({screenError(h, ch, cres, view), ch, cres});
    }
  }
  Cut cut = finishBudgetCut(h, view, o, plan, true, st);
  markGroupedRoots(groups, cut);
  measureBudgetCut(h, view, cut, st);
  if (stats) *stats = st;
  return cut;
}

Cut adaptGreedyBudget(const Hierarchy& h, const ViewParams& view, const BudgetOptions& options, BudgetStats* stats) {
  BudgetStats st;
  AdaptOptions ao;
  ao.maxNodes = options.maxNodes;
  ao.frustumCull = options.frustumCull;
  AdaptStats as;
  auto run = [&](double tolPx) {
    ao.tolerancePx = tolPx;
    ++st.rounds;
    return adaptErrorThreshold(h, view, ao, &as);
  };
  const uint64_t budget = options.maxTriangles;
  // Bisection in log(tolerance) between 1e-4 and 1e4 px: the finest cut found that fits.
  double lo = 1e-4, hi = 1e4;
  Cut best = run(hi);
  AdaptStats bestStats = as;
  if (best.triangles() > budget) {
    // Not even the coarsest cut fits: lower resolutions as far as the constraint allows.
    fitTriangleBudget(h, best, view, budget);
  } else {
    Cut fine = run(lo);
    if (fine.triangles() <= budget) {
      best = std::move(fine);
      bestStats = as;
    } else {
      for (int i = 0; i < 18; ++i) {
        const double mid = std::sqrt(lo * hi);
        Cut c = run(mid);
        if (c.triangles() <= budget) {
          best = std::move(c);
          bestStats = as;
          hi = mid;
        } else {
          lo = mid;
        }
      }
    }
  }
  st.splits = bestStats.splits;
  st.rootFloor = bestStats.rootFloor;
  st.budgetBelowRoots = bestStats.budgetBelowRoots;
  st.constraintRaises = bestStats.constraintRaises;
  st.constraintSplits = bestStats.constraintSplits;
  measureBudgetCut(h, view, best, st);
  if (stats) *stats = st;
  return best;
}

}  // namespace gimlod

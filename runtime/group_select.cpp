#include "runtime/group_select.h"

#include <algorithm>
#include <queue>

#include "runtime/adapt_dual_queue.h"

namespace gimlod {
namespace {

bool boxVisible(const std::array<float, 6>& b, const ViewParams& v, bool cull) {
  return !cull || v.frustum.intersects({b[0], b[1], b[2]}, {b[3], b[4], b[5]});
}

bool rootDrawable(const Hierarchy& h, uint32_t chart, const ViewParams& v, bool cull) {
  return nodeDrawable(h, {chart, 0, 0, 0}, v, cull);
}

// The children of group g drawn for the view: chart roots of a first-level group, else groups.
uint32_t visibleChildren(const Hierarchy& h, uint32_t g, const ViewParams& v, bool cull) {
  const RootGroups& rg = h.groups;
  const RootGroups::Group& gr = rg.groups[g];
  uint32_t k = 0;
  if (gr.level == 0) {
    for (uint32_t i = gr.begin; i < gr.end; ++i) k += rootDrawable(h, rg.order[i], v, cull);
  } else {
    for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c) k += boxVisible(rg.groups[c].bounds, v, cull);
  }
  return k;
}

// Calls visit(g) for every group that is a top or a child of an open group, each after the group
// above it (groups above lie later in RootGroups::groups).
template <typename Visit>
void forEachReached(const RootGroups& rg, const std::vector<uint8_t>& open, Visit&& visit) {
  std::vector<uint8_t> reached(rg.groups.size(), 0);
  for (uint32_t t : rg.tops) reached[t] = 1;
  for (uint32_t g = uint32_t(rg.groups.size()); g-- > 0;) {
    if (!reached[g]) continue;
    const RootGroups::Group& gr = rg.groups[g];
    if (open[g] && gr.level > 0)
      for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c) reached[c] = 1;
    visit(g);
  }
}

struct Candidate {
  double priority;
  uint32_t group;
  bool operator<(const Candidate& o) const {
    return priority < o.priority || (priority == o.priority && group > o.group);
  }
};

// Opens the closed groups of the frontier that a top-down pass opens with groups as nodes. An item
// is a closed group or a node of an open chart, and the best goes first while the cut's nodes fit
// maxNodes (and, in budget mode, their triangles at the minimum resolution fit maxTriangles); the
// chart nodes are split only to spend the budget as the adapters will. view.tolerancePx > 0: the
// top-down greedy (adaptErrorThreshold): a closed group goes only when it holds a chart root over
// tolerance even at its maxResLog2 (overTolerancePriority of that error seen from its box), a node by
// topDownSplitPriority. Else (triangle budget): the worst error first, groups and nodes alike, each
// drawn at the resolution the budgets leave a node (maxTriangles / maxNodes triangles).
void openGroupsTopDown(const Hierarchy& h, const AdaptView& view, uint32_t maxNodes, uint64_t maxTriangles,
                       std::vector<uint8_t>& open) {
  const ViewParams& v = view.view;
  const double tolerancePx = view.tolerancePx;
  const bool cull = view.cull;
  const bool threshold = tolerancePx > 0.0;
  // Budget mode: the cut's nodes at the minimum resolution stay within the triangle budget.
  const uint64_t maxCount =
      threshold ? maxNodes : std::min<uint64_t>(maxNodes, maxTriangles / (2ull << (2 * h.params.minNodeResLog2)));
  const RootGroups& rg = h.groups;
  struct Item {
    double priority;
    int64_t group;  // >= 0: a group; else the chart node `node`
    NodeId node;
    bool operator<(const Item& o) const { return priority < o.priority; }
  };
  // Budget mode: errors at the resolution a node of the budgets gets, maxTriangles / maxCount
  // triangles, within the nodes' resolutions.
  uint32_t budgetRes = h.params.minNodeResLog2;
  while (budgetRes < h.params.maxNodeResLog2 && maxCount > 0 &&
         (2ull << (2 * (budgetRes + 1))) * maxCount <= maxTriangles)
    ++budgetRes;
  std::priority_queue<Item> queue;
  uint64_t count = 0;
  uint32_t groupItems = 0;  // groups in the queue: the pass ends when none is left
  auto pushGroup = [&](uint32_t g) {
    const RootGroups::Group& gr = rg.groups[g];
    if (!boxVisible(gr.bounds, v, cull)) return;
    ++count;
    if (threshold) {
      const double px = boxScreenError(gr.bounds, double(gr.errorMax), v);
      if (!(px > tolerancePx)) return;
      queue.push({overTolerancePriority(px), g, {}});
    } else {
      queue.push({boxScreenError(gr.bounds, double(rg.error(g, budgetRes)), v), g, {}});
    }
    ++groupItems;
  };
  // Whether closed group g enters the queue (pushGroup): without one, nothing can open.
  auto mayOpen = [&](uint32_t g) {
    const RootGroups::Group& gr = rg.groups[g];
    return boxVisible(gr.bounds, v, cull) &&
           (!threshold || boxScreenError(gr.bounds, double(gr.errorMax), v) > tolerancePx);
  };
  auto pushNode = [&](const NodeId& n) {
    if (!nodeDrawable(h, n, v, cull)) return;
    ++count;
    if (!threshold) {  // the worst error first
      if (n.level + 1 < h.params.depth) queue.push({screenError(h, n, std::min(budgetRes, h.maxResLog2(n)), v), -1, n});
      return;
    }
    uint32_t res = 0;
    bool over = false;
    const double p = topDownSplitPriority(h, n, view, false, &res, &over);
    if (p > 0.0) queue.push({p, -1, n});
  };
  // The frontier: its closed groups, and the open charts' roots. No group to open: nothing to do
  // (a roomy budget opened them all), and the open charts' priorities are not computed.
  bool any = false;
  forEachReached(rg, open, [&](uint32_t g) { any = any || (!open[g] && mayOpen(g)); });
  if (!any) return;
  forEachReached(rg, open, [&](uint32_t g) {
    const RootGroups::Group& gr = rg.groups[g];
    if (!open[g]) {
      pushGroup(g);
    } else if (gr.level == 0) {
      for (uint32_t i = gr.begin; i < gr.end; ++i) pushNode({rg.order[i], 0, 0, 0});
    }
  });
  while (!queue.empty() && groupItems > 0) {
    const Item it = queue.top();
    queue.pop();
    uint64_t k = 0;  // visible children
    if (it.group >= 0) {
      --groupItems;
      const RootGroups::Group& gr = rg.groups[size_t(it.group)];
      k = visibleChildren(h, uint32_t(it.group), v, cull);
      if (count - 1 + k > maxCount) continue;
      open[size_t(it.group)] = 1;
      --count;
      if (gr.level == 0) {
        for (uint32_t i = gr.begin; i < gr.end; ++i) pushNode({rg.order[i], 0, 0, 0});
      } else {
        for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c) pushGroup(c);
      }
      continue;
    }
    for (uint32_t i = 0; i < 4; ++i) k += nodeDrawable(h, it.node.child(i), v, cull);
    // A node none of whose children is drawn stays: the coherent adapters keep it in the cut.
    if (k == 0 || count - 1 + k > maxCount) continue;
    --count;
    for (uint32_t i = 0; i < 4; ++i) pushNode(it.node.child(i));
  }
}

}  // namespace

void selectRootGroups(const Hierarchy& h, const AdaptView& view, uint32_t maxNodes, GroupSelection& out,
                      uint64_t maxTriangles) {
  const ViewParams& v = view.view;
  const bool cull = view.cull;
  const RootGroups& rg = h.groups;
  out.closedGroups = out.frozenRoots = out.rootFloor = 0;
  out.active = !rg.empty() && maxNodes != 0;
  out.closedOf.clear();
  if (rg.empty()) {
    out.rootFloor = countVisibleRoots(h, v, cull);
    return;
  }
  for (uint32_t t : rg.tops) out.rootFloor += boxVisible(rg.groups[t].bounds, v, cull);
  if (!out.active) return;  // every group open
  // First every group, the largest error at the minimum resolution first, while the cut's roots
  // (closed groups and open charts) and three nodes for a split of each open chart fit the budget:
  // with four nodes a chart within it, every group opens, and the cut is the one the forest gives
  // without groups.
  std::vector<uint8_t> open(rg.groups.size(), 0);
  auto errorMinPx = [&](uint32_t g) { return boxScreenError(rg.groups[g].bounds, double(rg.groups[g].errorMin), v); };
  std::priority_queue<Candidate> queue;
  uint64_t count = 0, openCharts = 0;
  for (uint32_t t : rg.tops)
    if (boxVisible(rg.groups[t].bounds, v, cull)) {
      ++count;
      queue.push({errorMinPx(t), t});
    }
  while (!queue.empty()) {
    const uint32_t g = queue.top().group;
    queue.pop();
    const RootGroups::Group& gr = rg.groups[g];
    const uint64_t k = visibleChildren(h, g, v, cull), charts = gr.level == 0 ? k : 0;
    if (count - 1 + k + 3 * (openCharts + charts) > maxNodes) continue;
    count = count - 1 + k;
    openCharts += charts;
    open[g] = 1;
    if (gr.level > 0)
      for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c)
        if (boxVisible(rg.groups[c].bounds, v, cull)) queue.push({errorMinPx(c), c});
  }
  // Then the groups a top-down pass opens for their errors.
  openGroupsTopDown(h, view, maxNodes, maxTriangles, open);
  // A group is closed when it is not open and every group above it is.
  out.closedOf.assign(h.chartCount(), -1);
  forEachReached(rg, open, [&](uint32_t g) {
    if (open[g]) return;
    const RootGroups::Group& gr = rg.groups[g];
    for (uint32_t k = gr.begin; k < gr.end; ++k) {
      out.closedOf[rg.order[k]] = int32_t(g);
      out.frozenRoots += rootDrawable(h, rg.order[k], v, cull);
    }
    out.closedGroups += boxVisible(gr.bounds, v, cull) ? 1u : 0u;
  });
}

void markGroupedRoots(const GroupSelection& s, Cut& cut) {
  for (CutNode& n : cut.nodes) n.group = s.frozen(n.id.chart) && n.id.level == 0 ? s.closedOf[n.id.chart] : -1;
}

}  // namespace gimlod

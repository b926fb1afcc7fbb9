// Which groups above the charts (hierarchy/root_groups.h) stay closed for a view: a closed group is
// one node of the cut and draws its charts' roots, which do not split; an open one gives way to its
// children. Every adapter starts its frame here, so that its node budget holds however many charts
// the atlas has.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "runtime/adapt.h"

namespace gimlod {

struct GroupSelection {
  std::vector<int32_t> closedOf;  // per chart: the closed group that draws its root, or -1
  uint32_t closedGroups = 0;      // closed groups whose box meets the view: a node each
  uint32_t frozenRoots = 0;       // drawable roots of the charts in closed groups
  uint32_t rootFloor = 0;         // the smallest cut: visible top groups, or visible chart roots
  bool active = false;            // the hierarchy has groups and the budget is limited
  bool frozen(uint32_t chart) const { return active && closedOf[chart] >= 0; }
  // The budget of a cut that counts every root (closed groups' roots included) as a node: that
  // many nodes of it hold maxNodes once each closed group's roots count as one.
  uint32_t chartBudget(uint32_t maxNodes) const {
    if (!active || maxNodes == 0) return maxNodes;
    const int64_t n = int64_t(maxNodes) - int64_t(closedGroups) + int64_t(frozenRoots);
    return uint32_t(std::max<int64_t>(n, 1));
  }
};

// Chooses the closed groups for a view (view.view, culling with view.cull; tolerancePx:
// view.tolerancePx) and a node budget. With no groups or no limit (maxNodes 0) every group is open
// (active false). Otherwise, from the visible top groups, closed:
// - it opens groups, the largest error at the minimum resolution first, while the cut's roots
//   (closed groups and open charts) and three nodes for a split of each open chart fit maxNodes:
//   with four nodes a chart within the budget every group opens, and the cut is the forest's;
// - then it opens the groups that a top-down pass with groups as nodes opens. With tolerancePx > 0
//   (the error-threshold adapters) that is the paper's top-down greedy: a closed group that holds a
//   chart root over tolerance even at its maxResLog2 competes, by that error, with the split priorities
//   of the open charts' nodes (topDownSplitPriority), the best first while the cut fits maxNodes.
//   Else (triangle-budget adapters, tolerancePx <= 0) the worst error goes first, groups and nodes
//   alike, each drawn at the resolution the budgets leave a node (maxTriangles / maxNodes
//   triangles), while the cut fits maxNodes and its nodes at the minimum resolution fit
//   maxTriangles.
// A closed group's roots within tolerance at their maxResLog2 need no split: they raise their
// resolution, which costs no node. Errors of a group are its roots' largest, seen from its box.
void selectRootGroups(const Hierarchy& h, const AdaptView& view, uint32_t maxNodes, GroupSelection& out,
                      uint64_t maxTriangles = 0);

// Marks the cut's nodes that are roots of closed groups (CutNode::group), which Cut::nodeCount then
// counts once per group.
void markGroupedRoots(const GroupSelection& s, Cut& cut);

}  // namespace gimlod

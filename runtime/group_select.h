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
  uint32_t opened = 0;            // groups opened for this view
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

// Chooses the closed groups for a view and a node budget. With no groups or no limit (maxNodes 0)
// every group is open (active false). Otherwise it starts from the visible top groups, closed, and
// opens groups while the roots of the cut (closed groups and open charts), plus three nodes for one
// split of each open chart that may need one, fit maxNodes:
// - tolerancePx > 0 (error threshold) first opens the groups holding a chart root over tolerance
//   even at its maxRes, the worst first; only such charts keep room for a split;
// - then any group, the largest error at the minimum resolution first, every open chart keeping
//   room for a split. With four nodes a chart within the budget, every group opens.
// Errors are a group's largest root errors seen from the group's box. A closed group's roots need
// no split to hold the tolerance when they are within it at their maxRes: they raise their
// resolution instead, which costs no node.
void selectRootGroups(const Hierarchy& h, const ViewParams& v, uint32_t maxNodes, double tolerancePx, bool cull,
                      GroupSelection& out);

// Marks the cut's nodes that are roots of closed groups (CutNode::group), which Cut::nodeCount then
// counts once per group.
void markGroupedRoots(const GroupSelection& s, Cut& cut);

}  // namespace gimlod

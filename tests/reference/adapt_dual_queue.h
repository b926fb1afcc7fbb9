// The reference for DualQueueAdapter (runtime/adapt_dual_queue.h): the adapter as it was before its per-frame work
// was made incremental, kept unchanged so that the equivalence tests and bench_adapt compare
// the runtime's adapter with it (same cuts, or equal or lower error within the same budgets).
// Coherent error-threshold adaptation with a node budget: a split/merge dual queue over a cut that
// persists across frames.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (the coherent dual-queue variant for the
// error-threshold problem with a maximum node count), after Duchaineau et al. 1997 (ROAM split and
// merge queues, frame coherence); section 7.4 for the stitching constraint.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/group_select.h"

namespace gimlod::reference {

// The persistent-cut adapter. The internal cut is a partition of all non-empty chart area (every
// non-empty chart root or descendants of it); nodes outside the frustum stay in it at minRes, count
// 0 triangles and are not counted against the budget nor returned, so culling never breaks the
// partition and culled regions collapse by zero-cost merges. Per frame every node's resolution and
// priorities are recomputed (O(cut) + O(ops log cut), never from the roots), then: merge while the
// cheapest merge adds <= 0 triangles or the drawn node count exceeds maxNodes; split the best split
// while it saves > 0 triangles (or its node is over tolerance) and the budget allows, or a cheaper
// merge can pay for it (a trade; an over-tolerance group is merged only to split a node with a
// larger error); repeat until neither helps. A node split this frame is never
// merged this frame and vice versa, and at most maxOpsPerFrame operations run per frame, apart
// from the merges that bring the drawn nodes within maxNodes (never capped). The drawn cut has at
// most max(maxNodes, rootFloor) nodes (constraint splits merged back, holdNodeBudget); with maxNodes below
// the root floor, the visible roots or fewer (a chart whose kept nodes are all culled draws none).
// note: the root box of such a chart meets the frustum while its descendants' boxes do not.
class DualQueueAdapter {
 public:
  // h must outlive the adapter. reusePriorities: keep split priorities across frames while they
  // provably cannot change (see Entry); false recomputes them every frame (same cuts, slower).
  explicit DualQueueAdapter(const Hierarchy& h, uint32_t maxOpsPerFrame = 1024, bool reusePriorities = true);

  // Adapts the persistent cut to the view and returns the drawn cut (frustum-culled nodes removed,
  // stitching constraint enforced on a copy, errorPx set). Valid until the next update/reset.
  const Cut& update(const ViewParams& view, const AdaptOptions& options, AdaptStats* stats = nullptr);

  // Back to the chart roots (the state before the first update).
  void reset();

  const DualQueueFrameStats& frameStats() const { return frame_; }
  // The persistent cut before culling and the stitching constraint (res = needed, clamped).
  Cut partition() const;
  // The priorities the adapter computes from its own per-node evaluation for the last update's
  // view (what its queues hold; -1 for a node not in the partition): they equal
  // dualQueueSplitPriority and dualQueueMergeCost, which tests check.
  double splitPriorityOf(const NodeId& n) const;
  double mergeCostOf(const NodeId& parent, bool* parentOverTol) const;

 private:
  // One partition node. Lives in entries_; slot_[g] is its position (swap-removed).
  struct Entry {
    NodeId id;
    uint32_t g = 0;  // dense forest index (see globalIndex)
    uint8_t resLog2 = 0;
    bool drawn = false;
    bool inside = false;  // bounds entirely inside the frustum (so are the children's)
    bool overTol = false;
    double errorPx = 0.0;      // screen error at res (drawn nodes)
    uint32_t splitFrame = 0;   // frame in which a split created this node
    uint32_t mergedFrame = 0;  // frame in which a merge created this node
    // Coherence (paper 7.1, after ROAM's deferred priority updates): the split priority of a
    // node that is not over tolerance depends on its own resolution and its children's needed
    // resolutions, which are step functions of the eye distance; the distance to a box moves
    // no more than the eye does. The cached priority stays exact while the eye is within
    // `slack` of `cacheEye`, the resolution and frustum class are unchanged and the class is
    // not partial (a partial node's children may change visibility).
    std::array<float, 6> box{};  // copies of the hierarchy's bounds and errors (when copied)
    std::array<float, 8> err{};
    bool copied = false;
    glm::dvec3 cacheEye{0.0};
    double cacheSlack = -1.0;  // < 0: no valid cache
    double cachePriority = 0.0;
    int32_t cacheDelta = 0;
    uint8_t cacheRes = 0;
    uint32_t cacheEpoch = 0;
  };
  struct Item {
    double priority;
    uint32_t g;     // split: the node; merge: the parent
    bool overTol;   // merge items: the parent cannot meet tolerance
    int32_t nodes;  // split: drawn-node change of the split; merge: drawn nodes it frees
  };
  struct Less {
    bool operator()(const Item& a, const Item& b) const { return a.priority < b.priority; }
  };
  struct Greater {
    bool operator()(const Item& a, const Item& b) const { return a.priority > b.priority; }
  };
  // Per-view evaluation of one node: drawn, fully inside, needed resolution (clamped).
  struct Eval {
    bool drawn = false, inside = false, overTol = false;
    uint8_t resLog2 = 0;
    double errorPx = 0.0;
    double slack = 0.0;  // eye movement before the (clamped) resolution can change
  };

  uint32_t globalIndex(const NodeId& n) const { return n.chart * perChart_ + nodeIndex(n.level, n.x, n.y); }
  NodeId nodeOf(uint32_t g) const;
  // parentInside: the parent is known to lie entirely inside the frustum (skips the test).
  Eval evalNode(const NodeId& n, bool parentInside) const;
  Eval evalBox(const float* bounds, const float* errors, uint32_t maxResLog2, bool parentInside) const;
  void evaluate(Entry& e);
  // slack (optional): lowered to the smallest eye movement that may change a child's resolution.
  double splitPriority(const Entry& e, int32_t* delta, double* slack = nullptr) const;
  double cachedSplitPriority(Entry& e, int32_t* delta);
  bool childDrawn(const Entry& e, uint32_t i) const;
  double mergeCost(const NodeId& parent, bool* overTol, int32_t* freed) const;
  bool groupInCut(const NodeId& parent) const;
  void pushSplit(Entry& e);
  void pushMerge(const NodeId& parent);
  void addEntry(const Entry& e);
  void removeEntry(uint32_t g);
  void doSplit(const NodeId& n);
  void doMerge(const NodeId& parent);
  bool validMergeTop();

  const Hierarchy& h_;
  uint32_t maxOps_;
  bool reuse_;
  uint32_t perChart_;
  uint32_t frameNo_ = 0;
  std::vector<NodeId> local_;   // chart-local node of each level-order index
  std::vector<int32_t> slot_;   // per forest node: position in entries_, or -1
  std::vector<Entry> entries_;  // the persistent cut (a partition of the non-empty area)
  std::vector<Item> splitHeap_, mergeHeap_;
  // Per-frame context.
  ViewParams view_;
  AdaptOptions opt_;
  uint32_t epoch_ = 0;  // bumped when the tolerance, projection or culling changes
  double epochTol_ = -1.0, epochPpr_ = -1.0, epochMinDist_ = -1.0;
  bool epochCull_ = true;
  uint32_t drawn_ = 0;
  DualQueueFrameStats frame_;
  Cut out_;
  // Per forest node: 0 not in the partition, 1 in it but culled, 2 drawn; and the stitching level
  // gap to the finest drawn neighbour (valid for partition nodes after update).
  std::vector<uint8_t> drawnState_, gaps_;
  GroupSelection groups_;  // this frame's closed groups (their roots never split)
  // Replaces the kept nodes of every chart in a closed group by the chart's root.
  void collapseClosedCharts();
  uint32_t opsSinceSort_ = 0;
};

}  // namespace gimlod::reference

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

namespace gimlod {

// True when node n is drawn for this view: not empty, and (when cull) its bounds meet the frustum.
bool nodeDrawable(const Hierarchy& h, const NodeId& n, const ViewParams& v, bool cull);

// Split priority of n (paper 7.1): triangles saved by replacing n, at its needed resolution, with
// its children each at theirs (undrawn nodes count 0 triangles). 1e30 + screen error at maxRes when
// n is drawn and cannot meet tolerance even at maxRes; -1 at the leaf level.
double dualQueueSplitPriority(const Hierarchy& h, const NodeId& n, const ViewParams& v,
                              double tolerancePx, bool cull);

// Merge cost of the sibling group under `parent` (paper 7.1): triangles added by replacing the
// non-empty children, each at its needed resolution, with the parent at its needed resolution.
// Sets *parentOverTol when the drawn parent cannot meet tolerance even at maxRes (then the group
// is merged only to get back under the node budget). Returns the cost.
double dualQueueMergeCost(const Hierarchy& h, const NodeId& parent, const ViewParams& v,
                          double tolerancePx, bool cull, bool* parentOverTol);

// What one update did, beyond AdaptStats.
struct DualQueueFrameStats {
  uint32_t splits = 0;
  uint32_t merges = 0;
  uint32_t trades = 0;        // merges done to make room for a better split under the budget
  uint32_t partitionNodes = 0;  // nodes of the persistent cut, drawn or not
  uint32_t drawnNodes = 0;      // before the stitching constraint
  bool opCapBound = false;    // stopped at maxOpsPerFrame before converging
};

// The persistent-cut adapter. The internal cut is a partition of all non-empty chart area (every
// non-empty chart root or descendants of it); nodes outside the frustum stay in it at minRes, count
// 0 triangles and are not counted against the budget nor returned, so culling never breaks the
// partition and culled regions collapse by zero-cost merges. Per frame every node's resolution and
// priorities are recomputed (O(cut) + O(ops log cut), never from the roots), then: merge while the
// cheapest merge adds <= 0 triangles or the drawn node count exceeds maxNodes; split the best split
// while it saves > 0 triangles (or its node is over tolerance) and the budget allows, or a cheaper
// merge can pay for it (a trade; an over-tolerance group is merged only to split a node with a
// larger error); repeat until neither helps. A node split this frame is never
// merged this frame and vice versa, and at most maxOpsPerFrame operations run per frame.
class DualQueueAdapter {
 public:
  // h must outlive the adapter.
  explicit DualQueueAdapter(const Hierarchy& h, uint32_t maxOpsPerFrame = 1024);

  // Adapts the persistent cut to the view and returns the drawn cut (frustum-culled nodes removed,
  // stitching constraint enforced on a copy, errorPx set). Valid until the next update/reset.
  const Cut& update(const ViewParams& view, const AdaptOptions& options, AdaptStats* stats = nullptr);

  // Back to the chart roots (the state before the first update).
  void reset();

  const DualQueueFrameStats& frameStats() const { return frame_; }
  // The persistent cut before culling and the stitching constraint (res = needed, clamped).
  Cut partition() const;

 private:
  struct Entry {
    NodeId id;
    uint32_t res = 0;
    bool drawn = false;
    bool overTol = false;
    uint32_t splitFrame = 0;   // frame in which a split created this node
    uint32_t mergedFrame = 0;  // frame in which a merge created this node
  };
  struct Item {
    double priority;
    uint64_t key;
    bool overTol;  // merge items: the parent cannot meet tolerance
  };
  struct Less {
    bool operator()(const Item& a, const Item& b) const { return a.priority < b.priority; }
  };
  struct Greater {
    bool operator()(const Item& a, const Item& b) const { return a.priority > b.priority; }
  };

  void evaluate(Entry& e);
  bool groupInCut(const NodeId& parent) const;
  void pushSplit(const Entry& e);
  void pushMerge(const NodeId& parent);
  int32_t drawnDelta(const NodeId& parent) const;  // drawn-count change of splitting parent
  void doSplit(const NodeId& n);
  void doMerge(const NodeId& parent);
  bool validMergeTop();
  static NodeId keyToNode(uint64_t key);

  const Hierarchy& h_;
  uint32_t maxOps_;
  uint32_t frameNo_ = 0;
  std::unordered_map<uint64_t, Entry> cut_;
  std::vector<Item> splitHeap_, mergeHeap_;
  // Per-frame context.
  ViewParams view_;
  AdaptOptions opt_;
  uint32_t drawn_ = 0;
  DualQueueFrameStats frame_;
  Cut out_;
};

}  // namespace gimlod

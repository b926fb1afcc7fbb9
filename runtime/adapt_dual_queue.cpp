// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (coherent dual-queue error-threshold
// adaptation with a node budget; merge, then split, until nothing more is gained), after
// Duchaineau et al. 1997 (ROAM split/merge queues); section 7.4 (stitching constraint).
#include "runtime/adapt_dual_queue.h"

#include <algorithm>
#include <cmath>

namespace gimlod {
namespace {

constexpr double kOverTolPriority = 1e30;

uint64_t tris(uint32_t res) { return 2ull << (2 * res); }

// Needed resolution clamped to maxRes, and whether even maxRes is over tolerance.
uint32_t clampedRes(const Hierarchy& h, const NodeId& n, const ViewParams& v, double tol, bool* overTol) {
  const uint32_t need = neededResolution(h, n, v, tol);
  const uint32_t rmax = h.params.maxRes(n.level);
  if (overTol) *overTol = need > rmax;
  return std::min(need, rmax);
}

// Triangles drawn for the non-empty children of n, each at its needed resolution.
double childTriangles(const Hierarchy& h, const NodeId& n, const ViewParams& v, double tol, bool cull) {
  double t = 0.0;
  for (uint32_t i = 0; i < 4; ++i) {
    const NodeId ch = n.child(i);
    if (nodeDrawable(h, ch, v, cull)) t += double(tris(clampedRes(h, ch, v, tol, nullptr)));
  }
  return t;
}

double splitPriorityOf(const Hierarchy& h, const NodeId& n, uint32_t res, bool drawn, bool overTol,
                       const ViewParams& v, double tol, bool cull) {
  if (n.level + 1 >= h.params.depth) return -1.0;
  if (drawn && overTol) return kOverTolPriority + screenError(h, n, h.params.maxRes(n.level), v);
  const double own = drawn ? double(tris(res)) : 0.0;
  return own - childTriangles(h, n, v, tol, cull);
}

}  // namespace

bool nodeDrawable(const Hierarchy& h, const NodeId& n, const ViewParams& v, bool cull) {
  if (h.flags(n) & kNodeEmpty) return false;
  if (!cull) return true;
  const auto& b = h.bounds(n);
  return v.frustum.intersects({b[0], b[1], b[2]}, {b[3], b[4], b[5]});
}

double dualQueueSplitPriority(const Hierarchy& h, const NodeId& n, const ViewParams& v,
                              double tolerancePx, bool cull) {
  bool over = false;
  const uint32_t res = clampedRes(h, n, v, tolerancePx, &over);
  return splitPriorityOf(h, n, res, nodeDrawable(h, n, v, cull), over, v, tolerancePx, cull);
}

double dualQueueMergeCost(const Hierarchy& h, const NodeId& parent, const ViewParams& v,
                          double tolerancePx, bool cull, bool* parentOverTol) {
  bool over = false;
  const uint32_t res = clampedRes(h, parent, v, tolerancePx, &over);
  const bool drawn = nodeDrawable(h, parent, v, cull);
  if (parentOverTol) *parentOverTol = drawn && over;
  if (drawn && over) return kOverTolPriority + screenError(h, parent, h.params.maxRes(parent.level), v);
  const double own = drawn ? double(tris(res)) : 0.0;
  return own - childTriangles(h, parent, v, tolerancePx, cull);
}

DualQueueAdapter::DualQueueAdapter(const Hierarchy& h, uint32_t maxOpsPerFrame)
    : h_(h), maxOps_(std::max(maxOpsPerFrame, 1u)) {}

void DualQueueAdapter::reset() {
  cut_.clear();
  out_ = Cut{};
  frame_ = {};
}

Cut DualQueueAdapter::partition() const {
  Cut c;
  c.nodes.reserve(cut_.size());
  for (const auto& [k, e] : cut_) c.nodes.push_back({e.id, e.res, 0.f});
  c.rebuildIndex();
  return c;
}

void DualQueueAdapter::evaluate(Entry& e) {
  e.drawn = nodeDrawable(h_, e.id, view_, opt_.frustumCull);
  bool over = false;
  const uint32_t r = clampedRes(h_, e.id, view_, opt_.tolerancePx, &over);
  e.overTol = e.drawn && over;
  e.res = e.drawn ? r : h_.params.minNodeResLog2;
}

bool DualQueueAdapter::groupInCut(const NodeId& parent) const {
  bool any = false;
  for (uint32_t i = 0; i < 4; ++i) {
    const NodeId ch = parent.child(i);
    if (h_.flags(ch) & kNodeEmpty) continue;
    auto it = cut_.find(ch.key());
    if (it == cut_.end()) return false;
    if (it->second.splitFrame == frameNo_) return false;  // created by a split this frame
    any = true;
  }
  return any;
}

void DualQueueAdapter::pushSplit(const Entry& e) {
  if (e.mergedFrame == frameNo_) return;  // merged this frame: not split again this frame
  const double p = splitPriorityOf(h_, e.id, e.res, e.drawn, e.overTol, view_, opt_.tolerancePx,
                                   opt_.frustumCull);
  if (p <= 0.0) return;  // never useful this frame: the view is fixed within a frame
  splitHeap_.push_back({p, e.id.key(), false});
  std::push_heap(splitHeap_.begin(), splitHeap_.end(), Less{});
}

void DualQueueAdapter::pushMerge(const NodeId& parent) {
  bool over = false;
  const double c = dualQueueMergeCost(h_, parent, view_, opt_.tolerancePx, opt_.frustumCull, &over);
  mergeHeap_.push_back({c, parent.key(), over});
  std::push_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
}

int32_t DualQueueAdapter::drawnDelta(const NodeId& parent) const {
  int32_t d = -int32_t(nodeDrawable(h_, parent, view_, opt_.frustumCull));
  for (uint32_t i = 0; i < 4; ++i) d += int32_t(nodeDrawable(h_, parent.child(i), view_, opt_.frustumCull));
  return d;
}

void DualQueueAdapter::doSplit(const NodeId& n) {
  auto it = cut_.find(n.key());
  drawn_ -= uint32_t(it->second.drawn);
  cut_.erase(it);
  for (uint32_t i = 0; i < 4; ++i) {
    const NodeId ch = n.child(i);
    if (h_.flags(ch) & kNodeEmpty) continue;
    Entry e;
    e.id = ch;
    e.splitFrame = frameNo_;
    evaluate(e);
    drawn_ += uint32_t(e.drawn);
    cut_[ch.key()] = e;
    pushSplit(e);
  }
  ++frame_.splits;
}

void DualQueueAdapter::doMerge(const NodeId& parent) {
  for (uint32_t i = 0; i < 4; ++i) {
    auto it = cut_.find(parent.child(i).key());
    if (it == cut_.end()) continue;
    drawn_ -= uint32_t(it->second.drawn);
    cut_.erase(it);
  }
  Entry e;
  e.id = parent;
  e.mergedFrame = frameNo_;
  evaluate(e);
  drawn_ += uint32_t(e.drawn);
  cut_[parent.key()] = e;
  if (parent.level > 0 && groupInCut(parent.parent())) pushMerge(parent.parent());
  ++frame_.merges;
}

// Pops stale merge items; leaves a valid top in place. False when the merge queue is empty.
bool DualQueueAdapter::validMergeTop() {
  while (!mergeHeap_.empty()) {
    const Item& top = mergeHeap_.front();
    const NodeId p = keyToNode(top.key);
    if (!cut_.count(top.key) && groupInCut(p)) return true;
    std::pop_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
    mergeHeap_.pop_back();
  }
  return false;
}

NodeId DualQueueAdapter::keyToNode(uint64_t key) { return NodeId::fromKey(key); }

const Cut& DualQueueAdapter::update(const ViewParams& view, const AdaptOptions& options, AdaptStats* stats) {
  AdaptStats st;
  frame_ = {};
  view_ = view;
  opt_ = options;
  ++frameNo_;
  const uint32_t budget = options.maxNodes == 0 ? UINT32_MAX : options.maxNodes;

  if (cut_.empty())
    for (uint32_t c = 0; c < h_.chartCount(); ++c) {
      const NodeId root{c, 0, 0, 0};
      if (h_.flags(root) & kNodeEmpty) continue;
      Entry e;
      e.id = root;
      cut_[root.key()] = e;
    }

  // Re-evaluate the persistent cut for this view; rebuild both queues in O(cut).
  drawn_ = 0;
  splitHeap_.clear();
  mergeHeap_.clear();
  for (auto& [k, e] : cut_) {
    evaluate(e);
    drawn_ += uint32_t(e.drawn);
  }
  for (auto& [k, e] : cut_) {
    const double p = splitPriorityOf(h_, e.id, e.res, e.drawn, e.overTol, view_, options.tolerancePx,
                                     options.frustumCull);
    if (p > 0.0) splitHeap_.push_back({p, k, false});
    if (e.id.level == 0) continue;
    // One merge item per group: pushed by its first non-empty child.
    const NodeId par = e.id.parent();
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = par.child(i);
      if (h_.flags(ch) & kNodeEmpty) continue;
      if (ch == e.id && groupInCut(par)) {
        bool over = false;
        const double c = dualQueueMergeCost(h_, par, view_, options.tolerancePx, options.frustumCull, &over);
        mergeHeap_.push_back({c, par.key(), over});
      }
      break;
    }
  }
  std::make_heap(splitHeap_.begin(), splitHeap_.end(), Less{});
  std::make_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});

  uint32_t ops = 0;
  auto capped = [&]() {
    if (ops < maxOps_) return false;
    frame_.opCapBound = true;
    return true;
  };
  std::vector<Item> deferred;  // splits that did not fit the budget in this round
  bool changed = true;
  while (changed && !capped()) {
    changed = false;
    // Merge phase: free merges, and any merges needed to get back under the budget.
    while (validMergeTop() && !capped()) {
      const Item top = mergeHeap_.front();
      if (!(top.priority <= 0.0 || drawn_ > budget)) break;
      std::pop_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
      mergeHeap_.pop_back();
      if (top.overTol) st.nodeBudgetBound = true;
      doMerge(keyToNode(top.key));
      ++ops;
      changed = true;
    }
    // Split phase.
    for (const Item& d : deferred) {
      splitHeap_.push_back(d);
      std::push_heap(splitHeap_.begin(), splitHeap_.end(), Less{});
    }
    deferred.clear();
    while (!splitHeap_.empty() && !capped()) {
      std::pop_heap(splitHeap_.begin(), splitHeap_.end(), Less{});
      const Item top = splitHeap_.back();
      splitHeap_.pop_back();
      auto it = cut_.find(top.key);
      if (it == cut_.end() || it->second.mergedFrame == frameNo_) continue;  // stale
      const NodeId n = it->second.id;
      const int32_t delta = drawnDelta(n);
      if (int64_t(drawn_) + delta <= int64_t(budget)) {
        doSplit(n);
        ++ops;
        changed = true;
        continue;
      }
      // Over budget: trade a cheaper merge (one that meets tolerance and frees enough nodes)
      // for this split. Look at a few queue tops: the group holding n itself is not eligible.
      bool traded = false;
      std::vector<Item> held;
      for (int tries = 0; tries < 4 && validMergeTop(); ++tries) {
        std::pop_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
        const Item m = mergeHeap_.back();
        mergeHeap_.pop_back();
        // Over-tolerance merges trade only for a worse over-tolerance split (both keyed 1e30 +
        // error), so the largest errors are fixed first, as in the top-down greedy.
        if (m.priority >= top.priority || (m.overTol && top.priority < kOverTolPriority)) {
          held.push_back(m);
          break;
        }
        const NodeId p = keyToNode(m.key);
        if (n.level > 0 && p == n.parent()) {
          held.push_back(m);
          continue;
        }
        const int32_t freed = -drawnDelta(p);
        if (int64_t(drawn_) - freed + delta > int64_t(budget) || ops + 2 > maxOps_) {
          held.push_back(m);
          continue;
        }
        if (m.overTol) st.nodeBudgetBound = true;
        doMerge(p);
        doSplit(n);
        ops += 2;
        ++frame_.trades;
        traded = changed = true;
        break;
      }
      for (const Item& m : held) {
        mergeHeap_.push_back(m);
        std::push_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
      }
      if (!traded) deferred.push_back(top);
    }
  }

  for (const Item& d : deferred) {
    auto it = cut_.find(d.key);
    if (it != cut_.end() && it->second.overTol) st.nodeBudgetBound = true;
  }

  // The drawn cut.
  out_.nodes.clear();
  out_.nodes.reserve(drawn_);
  for (const auto& [k, e] : cut_)
    if (e.drawn)
      out_.nodes.push_back({e.id, e.res, 0.f});
    else
      ++st.culled;
  out_.rebuildIndex();
  frame_.partitionNodes = uint32_t(cut_.size());
  frame_.drawnNodes = uint32_t(out_.nodes.size());
  enforceStitchConstraint(h_, out_, &view_, options.tolerancePx, &st);
  for (CutNode& n : out_.nodes) {
    n.errorPx = float(screenError(h_, n.id, n.res, view_));
    st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
  }
  st.splits = frame_.splits;
  st.triangles = out_.triangles();
  if (stats) *stats = st;
  return out_;
}

}  // namespace gimlod

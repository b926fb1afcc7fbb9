// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (coherent dual-queue error-threshold
// adaptation with a node budget; merge, then split, until nothing more is gained), after
// Duchaineau et al. 1997 (ROAM split/merge queues); section 7.4 (stitching constraint).
#include "runtime/adapt_dual_queue.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "runtime/parallel_pass.h"

namespace gimlod {
namespace {

constexpr double kOverTolPriority = kOverTolerancePriority;
uint64_t tris(uint32_t res) { return 2ull << (2 * res); }

// Needed resolution clamped to maxResLog2, and whether even maxResLog2 is over tolerance.
uint32_t clampedRes(const Hierarchy& h, const NodeId& n, const ViewParams& v, double tol, bool* overTol) {
  const uint32_t need = neededResolution(h, n, v, tol);
  const uint32_t rmax = h.maxResLog2(n);
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

// The split priority of n at resolution res, drawn or not (culled), over tolerance or not, for `view`.
double splitPriorityOf(const Hierarchy& h, const NodeId& n, uint32_t res, bool drawn, bool overTol,
                       const AdaptView& view) {
  if (n.level + 1 >= h.params.depth) return -1.0;
  if (drawn && overTol) return overTolerancePriority(screenError(h, n, h.maxResLog2(n), view.view));
  const double own = drawn ? double(tris(res)) : 0.0;
  return own - childTriangles(h, n, view.view, view.tolerancePx, view.cull);
}

}  // namespace

bool nodeDrawable(const Hierarchy& h, const NodeId& n, const ViewParams& v, bool cull) {
  if (h.flags(n) & kNodeEmpty) return false;
  if (!cull) return true;
  const auto& b = h.bounds(n);
  return v.frustum.intersects({b[0], b[1], b[2]}, {b[3], b[4], b[5]});
}

double dualQueueSplitPriority(const Hierarchy& h, const NodeId& n, const ViewParams& v, double tolerancePx, bool cull) {
  bool over = false;
  const uint32_t res = clampedRes(h, n, v, tolerancePx, &over);
  return splitPriorityOf(h, n, res, nodeDrawable(h, n, v, cull), over, {v, tolerancePx, cull});
}

double dualQueueMergeCost(const Hierarchy& h, const NodeId& parent, const ViewParams& v, double tolerancePx, bool cull,
                          bool* parentOverTol) {
  bool over = false;
  const uint32_t res = clampedRes(h, parent, v, tolerancePx, &over);
  const bool drawn = nodeDrawable(h, parent, v, cull);
  if (parentOverTol) *parentOverTol = drawn && over;
  if (drawn && over) return overTolerancePriority(screenError(h, parent, h.maxResLog2(parent), v));
  const double own = drawn ? double(tris(res)) : 0.0;
  return own - childTriangles(h, parent, v, tolerancePx, cull);
}

DualQueueAdapter::DualQueueAdapter(const Hierarchy& h, uint32_t maxOpsPerFrame, bool reusePriorities,
                                   uint32_t parallelMin)
    : h_(h),
      maxOps_(std::max(maxOpsPerFrame, 1u)),
      reuse_(reusePriorities),
      parallelMin_(parallelMin),
      perChart_(nodesPerChart(h.params.depth)) {
  local_.resize(perChart_);
  for (uint32_t l = 0; l < h.params.depth; ++l)
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x) local_[nodeIndex(l, x, y)] = {0, l, x, y};
  slot_.assign(size_t(perChart_) * h.chartCount(), -1);
  drawnState_.assign(slot_.size(), 0);
  gaps_.assign(slot_.size(), 0);
  dirtyMark_.assign(slot_.size(), 0);
  belowRoot_.assign(h.chartCount(), 0);
}

void DualQueueAdapter::reset() {
  gapsValid_ = false;
  changed_.clear();
  for (const Entry& e : entries_) slot_[e.g] = -1, drawnState_[e.g] = 0;
  entries_.clear();
  std::fill(belowRoot_.begin(), belowRoot_.end(), 0u);
  out_ = Cut{};
  frame_ = {};
}

Cut DualQueueAdapter::partition() const {
  Cut c;
  c.nodes.reserve(entries_.size());
  for (const Entry& e : entries_) c.nodes.push_back({e.id, e.resLog2, 0.f});
  c.rebuildIndex();
  return c;
}

double DualQueueAdapter::splitPriorityOf(const NodeId& n) const {
  const int32_t s = slot_[globalIndex(n)];
  if (s < 0) return -1.0;
  int32_t delta = 0;
  return splitPriority(entries_[s], &delta);
}

double DualQueueAdapter::mergeCostOf(const NodeId& parent, bool* parentOverTol) const {
  int32_t freed = 0;
  return mergeCost(parent, parentOverTol, &freed);
}

NodeId DualQueueAdapter::nodeOf(uint32_t g) const {
  NodeId n = local_[g % perChart_];
  n.chart = g / perChart_;
  return n;
}

DualQueueAdapter::Eval DualQueueAdapter::evalNode(const NodeId& n, bool parentInside) const {
  const Hierarchy::ChartNodes& cn = h_.charts[n.chart];
  const uint32_t i = nodeIndex(n.level, n.x, n.y);
  if (cn.flags[i] & kNodeEmpty) return Eval{};
  return evalBox(cn.bounds[i].data(), &cn.errors[size_t(i) * h_.params.resCount()], h_.maxResLog2(n), parentInside);
}

DualQueueAdapter::Eval DualQueueAdapter::evalBox(const float* b, const float* err, uint32_t maxResLog2,
                                                 bool parentInside) const {
  Eval ev;
  const glm::dvec3 lo{b[0], b[1], b[2]}, hi{b[3], b[4], b[5]};
  if (parentInside || !opt_.frustumCull) {
    ev.inside = true;
  } else {
    const int c = view_.frustum.classify(lo, hi);
    if (c == 0) return ev;
    ev.inside = c == 2;
  }
  ev.drawn = true;
  // Same arithmetic as neededResolution and screenError.
  const glm::dvec3 q = glm::clamp(view_.eye, lo, hi) - view_.eye;
  const double d = std::max(std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z), view_.minDistance);
  const double tolWorld = opt_.tolerancePx * d / view_.pixelsPerRadian;
  const uint32_t rmin = h_.params.minNodeResLog2, rmax = maxResLog2;
  uint32_t r = rmin;
  while (r <= rmax && !(double(err[r - rmin]) <= tolWorld)) ++r;
  ev.overTol = r > rmax;
  ev.resLog2 = uint8_t(std::min(r, rmax));
  ev.errorPx = double(err[ev.resLog2 - rmin]) * view_.pixelsPerRadian / d;
  // The clamped resolution holds for distances in [lower, upper): lower = where err[res] stops
  // meeting the tolerance (none at rmax), upper = where err[res - 1] starts to (none at rmin).
  const double k = view_.pixelsPerRadian / opt_.tolerancePx;
  double slack = std::numeric_limits<double>::infinity();
  if (ev.resLog2 < rmax) slack = d - double(err[ev.resLog2 - rmin]) * k;
  if (ev.resLog2 > rmin) slack = std::min(slack, double(err[ev.resLog2 - 1 - rmin]) * k - d);
  ev.slack = slack - 1e-9 * d;  // margin for rounding
  return ev;
}

void DualQueueAdapter::evaluate(Entry& e) {
  // The entry keeps a copy of its bounds and errors: the per-frame pass then streams through
  // entries_ instead of gathering from the hierarchy's arrays.
  const Eval ev = e.copied ? evalBox(e.box.data(), e.err.data(), h_.maxResLog2(e.id), false) : evalNode(e.id, false);
  e.drawnFlipped = e.drawn != ev.drawn;
  e.drawn = ev.drawn;
  e.inside = ev.inside;
  e.overTol = ev.drawn && ev.overTol;
  e.resLog2 = ev.drawn ? ev.resLog2 : uint8_t(h_.params.minNodeResLog2);
  e.errorPx = ev.drawn ? ev.errorPx : 0.0;
}

// Paper 7.1 split priority (see dualQueueSplitPriority), from the entry's evaluation; *delta is
// the drawn-node change of the split.
double DualQueueAdapter::cachedSplitPriority(Entry& e, int32_t* delta, bool* reused) {
  if (e.id.level == 0 && groups_.frozen(e.id.chart)) {  // a closed group's root: never split
    *delta = 0;
    return -1.0;
  }
  if (!e.drawn || e.overTol || e.id.level + 1 >= h_.params.depth) return splitPriority(e, delta);
  if (reuse_ && e.cacheSlack >= 0.0 && e.cacheEpoch == epoch_ && e.cacheRes == e.resLog2 && e.inside) {
    const glm::dvec3 m = view_.eye - e.cacheEye;
    if (m.x * m.x + m.y * m.y + m.z * m.z < e.cacheSlack * e.cacheSlack) {
      *reused = true;
      *delta = e.cacheDelta;
      return e.cachePriority;
    }
  }
  // Recompute, and cache when the children's visibility cannot change under this class.
  double slack = std::numeric_limits<double>::infinity();
  const double t = splitPriority(e, delta, &slack);
  e.cacheSlack = e.inside ? std::max(slack, 0.0) : -1.0;
  e.cacheEye = view_.eye;
  e.cachePriority = t;
  e.cacheDelta = *delta;
  e.cacheRes = e.resLog2;
  e.cacheEpoch = epoch_;
  return t;
}

double DualQueueAdapter::splitPriority(const Entry& e, int32_t* delta, double* slack) const {
  *delta = 0;
  if (e.id.level + 1 >= h_.params.depth || !e.drawn) return -1.0;  // undrawn: children are too
  *delta = -1;
  if (e.overTol) {
    for (uint32_t i = 0; i < 4; ++i) *delta += int32_t(childDrawn(e, i));
    return overTolerancePriority(e.errorPx);  // errorPx is at maxResLog2 here
  }
  double t = double(tris(e.resLog2));
  for (uint32_t i = 0; i < 4; ++i) {
    const Eval c = evalNode(e.id.child(i), e.inside);
    if (!c.drawn) continue;
    t -= double(tris(c.resLog2));
    ++*delta;
    if (slack) *slack = std::min(*slack, c.slack);
  }
  return t;
}

bool DualQueueAdapter::childDrawn(const Entry& e, uint32_t i) const {
  const NodeId c = e.id.child(i);
  if (h_.flags(c) & kNodeEmpty) return false;
  if (e.inside || !opt_.frustumCull) return true;
  const auto& b = h_.bounds(c);
  return view_.frustum.classify({b[0], b[1], b[2]}, {b[3], b[4], b[5]}) != 0;
}

double DualQueueAdapter::mergeCost(const NodeId& parent, bool* overTol, int32_t* freed) const {
  const Eval p = evalNode(parent, false);
  *freed = -int32_t(p.drawn);
  double t = 0.0;
  for (uint32_t i = 0; i < 4; ++i) {
    const int32_t s = slot_[globalIndex(parent.child(i))];
    if (s < 0 || !entries_[s].drawn) continue;
    t -= double(tris(entries_[s].resLog2));
    ++*freed;
  }
  *overTol = p.drawn && p.overTol;
  if (*overTol) return overTolerancePriority(p.errorPx);
  return t + (p.drawn ? double(tris(p.resLog2)) : 0.0);
}

bool DualQueueAdapter::groupInCut(const NodeId& parent) const {
  bool any = false;
  for (uint32_t i = 0; i < 4; ++i) {
    const NodeId ch = parent.child(i);
    if (h_.flags(ch) & kNodeEmpty) continue;
    const int32_t s = slot_[globalIndex(ch)];
    if (s < 0) return false;
    if (entries_[s].splitFrame == frameNo_) return false;  // created by a split this frame
    any = true;
  }
  return any;
}

void DualQueueAdapter::pushSplit(Entry& e) {
  if (e.mergedFrame == frameNo_) return;  // merged this frame: not split again this frame
  int32_t delta = 0;
  bool reused = false;
  const double p = cachedSplitPriority(e, &delta, &reused);
  frame_.priorityReuses += uint32_t(reused);
  if (p <= 0.0) return;  // never useful this frame: the view is fixed within a frame
  splitHeap_.push_back({p, e.g, false, delta});
  std::push_heap(splitHeap_.begin(), splitHeap_.end(), Less{});
}

void DualQueueAdapter::pushMerge(const NodeId& parent) {
  bool over = false;
  int32_t freed = 0;
  const double c = mergeCost(parent, &over, &freed);
  mergeHeap_.push_back({c, globalIndex(parent), over, freed});
  std::push_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
}

void DualQueueAdapter::addEntry(const Entry& e) {
  belowRoot_[e.id.chart] += uint32_t(e.id.level > 0);
  if (gapsValid_) changed_.push_back(e.id);
  slot_[e.g] = int32_t(entries_.size());
  entries_.push_back(e);
  Entry& a = entries_.back();
  const uint32_t rc = h_.params.resCount();
  if (rc <= a.err.size()) {
    const Hierarchy::ChartNodes& cn = h_.charts[a.id.chart];
    const uint32_t i = nodeIndex(a.id.level, a.id.x, a.id.y);
    a.box = cn.bounds[i];
    std::copy_n(&cn.errors[size_t(i) * rc], rc, a.err.begin());
    a.copied = true;
  }
  drawn_ += uint32_t(e.drawn);
}

void DualQueueAdapter::removeEntry(uint32_t g) {
  const int32_t s = slot_[g];
  belowRoot_[entries_[s].id.chart] -= uint32_t(entries_[s].id.level > 0);
  if (gapsValid_) changed_.push_back(entries_[s].id);
  drawn_ -= uint32_t(entries_[s].drawn);
  slot_[g] = -1;
  drawnState_[g] = 0;
  if (size_t(s) + 1 != entries_.size()) {
    entries_[s] = entries_.back();
    slot_[entries_[s].g] = s;
  }
  entries_.pop_back();
}

void DualQueueAdapter::doSplit(const NodeId& n) {
  removeEntry(globalIndex(n));
  for (uint32_t i = 0; i < 4; ++i) {
    const NodeId ch = n.child(i);
    if (h_.flags(ch) & kNodeEmpty) continue;
    Entry e;
    e.id = ch;
    e.g = globalIndex(ch);
    e.splitFrame = frameNo_;
    evaluate(e);
    addEntry(e);
    pushSplit(entries_.back());
  }
  ++frame_.splits;
}

void DualQueueAdapter::doMerge(const NodeId& parent) {
  for (uint32_t i = 0; i < 4; ++i) {
    const uint32_t g = globalIndex(parent.child(i));
    if (slot_[g] >= 0) removeEntry(g);
  }
  Entry e;
  e.id = parent;
  e.g = globalIndex(parent);
  e.mergedFrame = frameNo_;
  evaluate(e);
  addEntry(e);
  if (parent.level > 0 && groupInCut(parent.parent())) pushMerge(parent.parent());
  ++frame_.merges;
}

// Pops stale merge items; leaves a valid top in place. False when the merge queue is empty.
bool DualQueueAdapter::validMergeTop() {
  while (!mergeHeap_.empty()) {
    const Item& top = mergeHeap_.front();
    if (slot_[top.g] < 0 && groupInCut(nodeOf(top.g))) return true;
    std::pop_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
    mergeHeap_.pop_back();
  }
  return false;
}

void DualQueueAdapter::collapseClosedCharts() {
  if (!groups_.active) return;
  bool any = false;  // a closed chart that keeps nodes below its root
  for (uint32_t c = 0; c < h_.chartCount() && !any; ++c) any = groups_.frozen(c) && belowRoot_[c] > 0;
  if (!any) return;
  std::vector<uint32_t> drop, charts;
  for (const Entry& e : entries_)
    if (e.id.level > 0 && groups_.frozen(e.id.chart)) drop.push_back(e.g);
  for (uint32_t g : drop) {
    charts.push_back(nodeOf(g).chart);
    removeEntry(g);
  }
  std::sort(charts.begin(), charts.end());
  charts.erase(std::unique(charts.begin(), charts.end()), charts.end());
  for (uint32_t c : charts) {
    Entry e;
    e.id = {c, 0, 0, 0};
    e.g = globalIndex(e.id);
    if (slot_[e.g] < 0) addEntry(e);
  }
  opsSinceSort_ += uint32_t(drop.size());
}

void DualQueueAdapter::updateGaps() {
  // The update costs a few walks per change, the full pass a walk per entry: past a quarter of
  // the partition in changes, the full pass is cheaper.
  if (!gapsValid_ || changed_.size() * 4 > entries_.size()) {
    for (const Entry& e : entries_) {
      drawnState_[e.g] = e.drawn ? 2 : 1;
      gaps_[e.g] = 0;
    }
    for (const Entry& m : entries_) {
      if (!m.drawn || m.id.level == 0) continue;
      walkToCoarserNeighbours(h_, m.id, [&](const NodeId& a, uint32_t up) {
        const uint32_t g = globalIndex(a);
        if (!drawnState_[g]) return false;
        if (drawnState_[g] == 2) gaps_[g] = std::max<uint8_t>(gaps_[g], uint8_t(up));
        return true;
      });
    }
    gapsValid_ = true;
    changed_.clear();
    return;
  }
  // Only the entries beside a node that joined or left the partition, or was culled or uncovered,
  // can have a new gap.
  if (++dirtyRound_ == 0) {
    std::fill(dirtyMark_.begin(), dirtyMark_.end(), 0u);
    dirtyRound_ = 1;
  }
  dirty_.clear();
  auto mark = [&](const Entry& e) {
    if (dirtyMark_[e.g] != dirtyRound_) dirtyMark_[e.g] = dirtyRound_, dirty_.push_back(e.g);
  };
  auto find = [&](const NodeId& n) -> const Entry* {
    const int32_t at = slot_[globalIndex(n)];
    return at < 0 ? nullptr : &entries_[size_t(at)];
  };
  for (const NodeId& x : changed_) {
    if (const Entry* e = find(x)) mark(*e);
    keptBeside(h_, x, find, mark);
  }
  changed_.clear();
  for (uint32_t g : dirty_) {
    const Entry& e = entries_[size_t(slot_[g])];
    gaps_[g] = e.drawn ? uint8_t(keptGap(h_, e.id, find)) : 0;
  }
}

void DualQueueAdapter::queueItems(Entry& e, PassItems& q) {
  q = PassItems{};
  q.split = cachedSplitPriority(e, &q.delta, &q.reused);
  if (e.id.level == 0) return;
  // One merge item per group: listed by its first non-empty child.
  const NodeId par = e.id.parent();
  for (uint32_t i = 0; i < 4; ++i) {
    const NodeId ch = par.child(i);
    if (h_.flags(ch) & kNodeEmpty) continue;
    if (ch == e.id && groupInCut(par)) {
      q.hasMerge = true;
      q.merge = mergeCost(par, &q.mergeOverTol, &q.freed);
    }
    break;
  }
}

// The split and merge phases of one update (merge, then split, until neither changes the
// partition or the operation cap is reached), from queues filled for this view.
void DualQueueAdapter::runQueues(uint32_t budget, AdaptStats& st) {
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
    // Merge phase: free merges, and any merges needed to get back under the budget. note: the
    // latter are not capped (as the quad queue's mandatory merges), so the budget holds every
    // frame, also right after it drops or the view uncovers split culled regions.
    while (validMergeTop()) {
      const Item top = mergeHeap_.front();
      if (drawn_ <= budget && (capped() || !(top.priority <= 0.0))) break;
      std::pop_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
      mergeHeap_.pop_back();
      if (top.overTol) st.nodeBudgetBound = true;
      doMerge(nodeOf(top.g));
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
      const int32_t slot = slot_[top.g];
      if (slot < 0 || entries_[slot].mergedFrame == frameNo_) continue;  // stale
      const NodeId n = entries_[slot].id;
      const int32_t delta = top.nodes;
      if (int64_t(drawn_) + delta <= int64_t(budget)) {
        doSplit(n);
        ++ops;
        changed = true;
        continue;
      }
      // Over budget: trade a cheaper merge (one that meets tolerance and frees enough nodes)
      // for this split. Look at a few queue tops: the group holding n itself is not eligible.
      bool traded = false, unpaid = false;
      Item held[4];
      int heldCount = 0;
      for (int tries = 0; tries < 4 && validMergeTop(); ++tries) {
        std::pop_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
        const Item m = mergeHeap_.back();
        mergeHeap_.pop_back();
        // Over-tolerance merges trade only for a worse over-tolerance split (both in the
        // over-tolerance tier), so the largest errors are fixed first, as in the top-down greedy.
        if (m.priority >= top.priority || (m.overTol && top.priority < kOverTolPriority)) {
          held[heldCount++] = m;
          unpaid = true;  // the cheapest merge costs more than this split saves
          break;
        }
        const NodeId p = nodeOf(m.g);
        if (n.level > 0 && p == n.parent()) {
          held[heldCount++] = m;
          continue;
        }
        const int32_t freed = m.nodes;
        if (int64_t(drawn_) - freed + delta > int64_t(budget) || ops + 2 > maxOps_) {
          held[heldCount++] = m;
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
      for (int k = 0; k < heldCount; ++k) {
        mergeHeap_.push_back(held[k]);
        std::push_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});
      }
      if (!traded) {
        deferred.push_back(top);
        // Every later split saves less, and the merges are cost-ordered: none can be paid for
        // either, so the split phase is over (the round repeats only if something changed).
        if (unpaid) break;
      }
    }
  }

  for (const Item& d : deferred) {
    const int32_t s = slot_[d.g];
    if (s >= 0 && entries_[s].overTol) st.nodeBudgetBound = true;
  }
}

const Cut& DualQueueAdapter::update(const ViewParams& view, const AdaptOptions& options, AdaptStats* stats) {
  AdaptStats st;
  frame_ = {};
  view_ = view;
  opt_ = options;
  ++frameNo_;
  selectRootGroups(h_, {view, options.tolerancePx, options.frustumCull}, options.maxNodes, groups_);
  // Every root counts as a node in the partition; the closed groups' roots count once a group in
  // the returned cut.
  const uint32_t chartBudget = groups_.chartBudget(options.maxNodes);
  const uint32_t budget = chartBudget == 0 ? UINT32_MAX : chartBudget;

  if (entries_.empty())
    for (uint32_t c = 0; c < h_.chartCount(); ++c) {
      const NodeId root{c, 0, 0, 0};
      if (h_.flags(root) & kNodeEmpty) continue;
      Entry e;
      e.id = root;
      e.g = globalIndex(root);
      addEntry(e);
    }

  collapseClosedCharts();
  // Partition order follows the forest order, so the per-frame pass reads the hierarchy's
  // arrays nearly sequentially; re-sorted once the operations since the last sort reach 1/8.
  if (opsSinceSort_ * 8 > entries_.size()) {
    std::sort(entries_.begin(), entries_.end(), [](const Entry& a, const Entry& b) { return a.g < b.g; });
    for (uint32_t i = 0; i < entries_.size(); ++i) slot_[entries_[i].g] = int32_t(i);
    opsSinceSort_ = 0;
  }
  // Re-evaluate the persistent cut for this view; rebuild both queues in O(cut). Each entry is
  // evaluated on its own (in parallel), then the queues are filled in partition order, so the
  // queues, and the cut, do not depend on the thread count.
  const size_t n = entries_.size();
  parallelPass(n, parallelMin_, [&](size_t i) { evaluate(entries_[i]); });
  if (options.tolerancePx != epochTol_ || view.pixelsPerRadian != epochPpr_ || view.minDistance != epochMinDist_ ||
      options.frustumCull != epochCull_) {
    ++epoch_;
    epochTol_ = options.tolerancePx;
    epochPpr_ = view.pixelsPerRadian;
    epochMinDist_ = view.minDistance;
    epochCull_ = options.frustumCull;
  }
  pass_.resize(n);
  parallelPass(n, parallelMin_, [&](size_t i) { queueItems(entries_[i], pass_[i]); });
  splitHeap_.clear();
  mergeHeap_.clear();
  drawn_ = 0;
  for (size_t i = 0; i < n; ++i) {
    drawn_ += uint32_t(entries_[i].drawn);
    if (gapsValid_ && entries_[i].drawnFlipped) changed_.push_back(entries_[i].id);
    const PassItems& q = pass_[i];
    frame_.priorityReuses += uint32_t(q.reused);
    if (q.split > 0.0) splitHeap_.push_back({q.split, entries_[i].g, false, q.delta});
    if (q.hasMerge) mergeHeap_.push_back({q.merge, globalIndex(entries_[i].id.parent()), q.mergeOverTol, q.freed});
  }
  std::make_heap(splitHeap_.begin(), splitHeap_.end(), Less{});
  std::make_heap(mergeHeap_.begin(), mergeHeap_.end(), Greater{});

  runQueues(budget, st);
  if (groups_.active)  // a closed group's root over tolerance even at its maxResLog2
    for (const Entry& e : entries_)
      if (e.overTol && e.id.level + 1 < h_.params.depth && groups_.frozen(e.id.chart)) st.nodeBudgetBound = true;

  // The drawn cut (in partition order, which the operation history determines), with the
  // stitching constraint: gaps from the dense partition index (no hashing), raising resolutions
  // in place; only when a node would need more than its maxResLog2 does the generic pass split it.
  updateGaps();
  out_.nodes.clear();
  out_.nodes.reserve(drawn_);
  bool needSplit = false;
  for (size_t i = 0; i < entries_.size(); ++i) {
    const Entry& e = entries_[i];
    if (!e.drawn) {
      ++st.culled;
      continue;
    }
    const uint8_t gap = gaps_[e.g];
    if (gap <= e.resLog2) {
      out_.nodes.push_back({e.id, e.resLog2, float(e.errorPx)});
    } else if (gap <= h_.maxResLog2(e.id)) {
      ++st.constraintRaises;
      out_.nodes.push_back({e.id, gap, float(screenError(h_, e.id, gap, view_))});
    } else {
      needSplit = true;
      out_.nodes.push_back({e.id, e.resLog2, float(e.errorPx)});
    }
  }
  out_.rebuildIndex();
  frame_.partitionNodes = uint32_t(entries_.size());
  frame_.drawnNodes = uint32_t(out_.nodes.size());
  if (needSplit) {
    enforceStitchConstraint(h_, out_, &view_, options.tolerancePx, &st);
    holdNodeBudget(h_, out_, view_, chartBudget);
    for (CutNode& n : out_.nodes) n.errorPx = float(screenError(h_, n.id, n.resLog2, view_));
  }
  for (const CutNode& n : out_.nodes) st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
  opsSinceSort_ += frame_.splits + frame_.merges;
  st.rootFloor = groups_.rootFloor;
  st.budgetBelowRoots = budgetBelowRoots(options.maxNodes, st.rootFloor);
  markGroupedRoots(groups_, out_);
  setCutCounts(out_, st);
  st.splits = frame_.splits;
  st.triangles = out_.triangles();
  if (stats) *stats = st;
  return out_;
}

}  // namespace gimlod

// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (the quad-queue algorithm for the
// triangle-budget problem with a node budget: refine/coarsen and split/merge dual-queue pairs,
// undo-based termination); section 7.4 (stitching constraint).
#include "runtime/adapt_quad_queue.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "runtime/adapt_dual_queue.h"
#include "runtime/group_select.h"
#include "runtime/parallel_pass.h"

namespace gimlod {
namespace {

// Tier bases. A tier value is base * (1 + err): adding err to 1e30 would be lost to rounding (all
// tier members would tie and fall back to key order), scaling keeps the order by err.
constexpr double kStuckPriority = 1e30;  // split priority base of a drawn node already at maxResLog2
constexpr double kOverCost = 1e30;       // merge cost base when the parent cannot hold the error
constexpr double kEps = 1e-9;

uint64_t tris(uint32_t res) { return 2ull << (2 * res); }

NodeId keyToNode(uint64_t key) { return NodeId::fromKey(key); }

struct Entry {
  NodeId id;
  uint32_t resLog2 = 0;
  uint32_t floor = 0;  // lowest allowed resolution: minRes, or the stitching gap
  uint32_t gap = 0;    // stitching level gap to the finest drawn neighbour (computeFloors)
  uint32_t maxResLog2 = 0;
  bool drawn = false;
  bool drawnFlipped = false;  // drawn changed in this frame's evaluation
  bool inside = false;        // drawn and its bounds inside the frustum (from the frame's evaluation)
  bool prioValid = false;     // splitPrio holds this frame's split priority at res and err
  double err = 0.0;           // screen error at res; 0 when not drawn
  double dist = 1.0;          // eye distance to the bounds this frame (as screenError clamps it)
  double splitPrio = 0.0;
  const float* errs = nullptr;  // the node's errors, [res - minRes] (Hierarchy::error)
  uint32_t splitRound = 0, mergedRound = 0;
};

// A node's view-dependent data: cached for the frame by NodeCache, or computed directly.
struct NodeEval {
  double dist = 1.0;  // eye distance to the bounds, at least the view's minDistance
  const float* errs = nullptr;
  uint32_t maxResLog2 = 0;
  bool drawable = false;  // nodeDrawable
  bool inside = false;    // drawable and inside every plane (evaluated with classify)
};

// Heap item; all heaps are max-heaps on priority, ties broken by key (deterministic).
struct Item {
  double priority;
  uint64_t key;
  uint32_t resLog2;  // resolution when pushed (stale when it changed)
};
struct ItemLess {
  bool operator()(const Item& a, const Item& b) const {
    return a.priority < b.priority || (a.priority == b.priority && a.key < b.key);
  }
};
void heapPush(std::vector<Item>& h, const Item& it) {
  h.push_back(it);
  std::push_heap(h.begin(), h.end(), ItemLess{});
}
Item heapPop(std::vector<Item>& h) {
  std::pop_heap(h.begin(), h.end(), ItemLess{});
  const Item it = h.back();
  h.pop_back();
  return it;
}

// The kept cut: entries in a vector, found through a dense per-forest-node slot array (no
// hashing). Erasing moves the last entry into the hole, so iterators and pointers are valid only
// until the next change. While a round runs, every change is logged so that undo() puts the
// entries back exactly (values and order) in the time the round took, not in O(cut).
class EntryMap {
 public:
  using value_type = std::pair<uint64_t, Entry>;
  using iterator = std::vector<value_type>::iterator;
  using const_iterator = std::vector<value_type>::const_iterator;

  void init(const Hierarchy& h) {
    perChart_ = nodesPerChart(h.params.depth);
    const size_t n = size_t(perChart_) * h.chartCount();
    if (slot_.size() != n) {
      slot_.assign(n, -1);
      items_.clear();
    }
  }
  iterator begin() { return items_.begin(); }
  iterator end() { return items_.end(); }
  const_iterator begin() const { return items_.begin(); }
  const_iterator end() const { return items_.end(); }
  bool empty() const { return items_.empty(); }
  size_t size() const { return items_.size(); }
  size_t index(const NodeId& n) const { return size_t(n.chart) * perChart_ + nodeIndex(n.level, n.x, n.y); }
  size_t forestSize() const { return slot_.size(); }
  Entry* find(const NodeId& n) {
    const int32_t s = slot_[index(n)];
    return s < 0 ? nullptr : &items_[size_t(s)].second;
  }
  const Entry* find(const NodeId& n) const {
    const int32_t s = slot_[index(n)];
    return s < 0 ? nullptr : &items_[size_t(s)].second;
  }
  Entry* find(uint64_t key) { return find(NodeId::fromKey(key)); }
  bool count(const NodeId& n) const { return slot_[index(n)] >= 0; }
  int32_t slotOf(const NodeId& n) const { return slot_[index(n)]; }
  // Adds e (its node must not be in the map).
  Entry& insert(const Entry& e) {
    const size_t i = index(e.id);
    slot_[i] = int32_t(items_.size());
    items_.push_back({e.id.key(), e});
    if (logging_) log_.push_back({Op::kInsert, 0, {}});
    return items_.back().second;
  }
  void erase(const NodeId& n) {
    const int32_t s = slot_[index(n)];
    if (s >= 0) eraseAt(size_t(s));
  }
  // Call before changing an entry in place while logging.
  void willModify(const Entry& e) {
    if (logging_) log_.push_back({Op::kModify, 0, e});
  }
  void clear() {
    for (const value_type& v : items_) slot_[index(v.second.id)] = -1;
    items_.clear();
  }
  void beginLog() {
    log_.clear();
    logging_ = true;
  }
  void endLog() { logging_ = false; }
  // Reverts the logged changes, newest first.
  void undo() {
    logging_ = false;
    for (size_t k = log_.size(); k-- > 0;) {
      const Logged& l = log_[k];
      switch (l.op) {
        case Op::kInsert:
          slot_[index(items_.back().second.id)] = -1;
          items_.pop_back();
          break;
        case Op::kErase: {
          if (l.slot < items_.size()) {  // the last entry had moved into the hole
            items_.push_back(std::move(items_[l.slot]));
            slot_[index(items_.back().second.id)] = int32_t(items_.size() - 1);
            items_[l.slot] = {l.entry.id.key(), l.entry};
          } else {
            items_.push_back({l.entry.id.key(), l.entry});
          }
          slot_[index(l.entry.id)] = int32_t(l.slot);
          break;
        }
        case Op::kModify: *find(l.entry.id) = l.entry; break;
      }
    }
    log_.clear();
  }

 private:
  enum class Op : uint8_t { kInsert, kErase, kModify };
  struct Logged {
    Op op;
    uint32_t slot;
    Entry entry;
  };
  void eraseAt(size_t s) {
    if (logging_) log_.push_back({Op::kErase, uint32_t(s), items_[s].second});
    slot_[index(items_[s].second.id)] = -1;
    if (s + 1 != items_.size()) {
      items_[s] = std::move(items_.back());
      slot_[index(items_[s].second.id)] = int32_t(s);
    }
    items_.pop_back();
  }
  uint32_t perChart_ = 0;
  std::vector<int32_t> slot_;
  std::vector<value_type> items_;
  bool logging_ = false;
  std::vector<Logged> log_;
};

// How a node's evaluation meets the frustum: intersects, classify (sets NodeEval::inside), or
// not at all for a node known to lie inside it.
enum class FrustumTest : uint8_t { kIntersects, kClassify, kInside };

// Per-frame cache of NodeEval, found through dense per-forest-node stamps.
class NodeCache {
 public:
  void init(const Hierarchy& h) {
    perChart_ = nodesPerChart(h.params.depth);
    const size_t n = size_t(perChart_) * h.chartCount();
    if (slot_.size() != n) {
      slot_.assign(n, {});
      frame_ = 0;
    }
  }
  void newFrame(const Hierarchy& h, const ViewParams& v, bool cull, size_t expected) {
    h_ = &h;
    view_ = &v;
    cull_ = cull;
    evals_.clear();
    evals_.reserve(expected);
    if (++frame_ == 0) {  // wrapped: forget every stamp
      std::fill(slot_.begin(), slot_.end(), Slot{});
      frame_ = 1;
    }
  }
  // note: every node's planes are tested, even below a node inside the frustum: a node's bounds
  // need not lie in its parent's (a terrain's nodes past the raster's edge lie flat at the lowest
  // height; see nestedChildren).
  // cull: how the frustum is met; kInside for a non-empty node known to lie inside it (a child
  // of a node inside it that holds its children's bounds, nestedChildren).
  NodeEval operator()(const NodeId& n, FrustumTest cull = FrustumTest::kIntersects) {
    const uint32_t i = nodeIndex(n.level, n.x, n.y);
    Slot& s = slot_[size_t(n.chart) * perChart_ + i];
    if (s.frame == frame_) return evals_[s.at];
    s = {frame_, uint32_t(evals_.size())};
    return evals_.emplace_back(evaluate(n, i, cull));
  }
  // The node's NodeEval, not cached; withInside: classified, so that inside is set.
  NodeEval evaluate(const NodeId& n, uint32_t i, FrustumTest cull = FrustumTest::kIntersects) const {
    NodeEval e;
    const Hierarchy::ChartNodes& cn = h_->charts[n.chart];
    const auto& b = cn.bounds[i];
    const glm::dvec3 lo{b[0], b[1], b[2]}, hi{b[3], b[4], b[5]};
    // The same arithmetic as nodeDrawable, neededResolution and screenError.
    if (cn.flags[i] & kNodeEmpty) {
      e.drawable = false;
    } else if (cull == FrustumTest::kInside) {
      e.drawable = e.inside = true;
    } else if (cull == FrustumTest::kClassify) {
      const int c = cull_ ? view_->frustum.classify(lo, hi) : 2;
      e.drawable = c != 0;
      e.inside = c == 2;
    } else {
      e.drawable = !cull_ || view_->frustum.intersects(lo, hi);
    }
    e.dist = std::max(glm::length(glm::clamp(view_->eye, lo, hi) - view_->eye), view_->minDistance);
    e.errs = &cn.errors[size_t(i) * h_->params.resCount()];
    e.maxResLog2 = h_->maxResLog2(n);
    return e;
  }

 private:
  const Hierarchy* h_ = nullptr;
  const ViewParams* view_ = nullptr;
  bool cull_ = true;
  uint32_t perChart_ = 0, frame_ = 0;
  struct Slot {
    uint32_t frame = 0, at = 0;  // evals_[at] is the node's when frame is this frame's
  };
  std::vector<Slot> slot_;
  std::vector<NodeEval> evals_;
};

}  // namespace

struct QuadQueueAdapter::State {
  EntryMap cut;    // partition of the non-empty chart area
  NodeCache node;  // this frame's view-dependent node data
  uint32_t drawn = 0;
  uint64_t triangles = 0;  // drawn
  uint64_t floorTris = 0;  // drawn, each at its floor
  uint32_t round = 0;      // increasing round id (split/merge marks)
  bool needsConstraintSplit = false;
  // Per-frame context.
  const Hierarchy* h = nullptr;
  ViewParams view;
  BudgetOptions opt;
  uint32_t ops = 0;
  BudgetStats st;
  Cut out;
  GroupSelection groups;  // this frame's closed groups (their roots never split)
  // Per forest node: the round in which phase 2 reserved its split (reserveMark), and the phase-2
  // scratch heaps, kept from frame to frame (no allocation once warm).
  std::vector<uint32_t> reserved;
  uint32_t reserveMark = 0;
  std::vector<Item> splitH, mergeH, coarsenH, errH;
  struct Listed {  // one entry's phase-2 items (listMerges)
    double split = -1.0, cost = 0.0;
    bool merge = false;
    bool bounded = false;  // the split priority was settled by splitPriorityBound
  };
  std::vector<Listed> listed;
  uint32_t parallelMin = kDefaultParallelMin;
  std::vector<uint8_t> nested;  // nestedChildren, per forest node
  std::vector<std::vector<Item>> refineB;
  // Phase 1's queues are built once a frame and then kept up to date from round to round: the
  // entries phase 2 added (fresh), those whose floor changed (refloored), those below their floor
  // (raise), and the coarsenings the balance set aside (parked) are what a fresh build would
  // have that the kept queues lack. Stale items are skipped as they surface.
  bool phase1Ready = false;
  std::vector<NodeId> fresh, refloored, raise;
  // Coarsenings the balance passed over because they would reach the max error, in a min-heap
  // on the error they would give (parkedLess): in a balanced cut that is nearly every node, so
  // they wait here instead of being popped again by each later balance. The ones below a later
  // max error go back to coarsenH when a balance starts; all of them when the cut is over the
  // triangle budget (which coarsens by loss alone).
  struct Parked {
    double coarsenedErr;
    Item item;
  };
  std::vector<Parked> parked;
  // The floors likewise, from the first computeFloors of a frame on: the nodes that joined or left
  // the cut since (cutChanged) mark the entries beside them, whose gaps are found again.
  bool floorsReady = false;
  uint32_t overMaxRes = 0;  // drawn entries whose gap is above their maxResLog2
  std::vector<NodeId> cutChanged, dirty;
  std::vector<uint32_t> newGap;  // scratch of the full pass, per entry
  // After a frame's evaluation, until its first computeFloors: the floors are last frame's, and
  // the mandatory merges count every drawn node at minRes (as a fresh set of floors would).
  bool floorsStale = false;
  std::vector<uint32_t> dirtyMark;
  uint32_t dirtyRound = 1;
  // Phase 2's queues likewise, from the first round of a frame on: the splits a round popped but
  // did not do (splitAside), the nodes whose split priority is new (splitRecheck: a changed
  // resolution, a merge's parent) and the groups whose cost or mergeability may be new
  // (groupRecheck), each listed once a round (listedSplit, listedGroup == listMark).
  bool phase2Ready = false;
  // A group's merge items carry a number (Item::res) and only the one of its latest is valid: the
  // kept queue then holds one item per group, as a fresh listing does (an item set aside must
  // leave no copy behind in the queue).
  std::vector<uint32_t> mergeSeq;
  uint32_t mergeSeqNext = 0;
  Item mergeItem(const NodeId& p, double priority) {
    uint32_t& q = mergeSeq[cut.index(p)];
    q = ++mergeSeqNext;
    return {priority, p.key(), q};
  }
  std::vector<Item> splitAside;
  std::vector<NodeId> splitRecheck, groupRecheck;
  std::vector<uint32_t> listedSplit, listedGroup;
  uint32_t listMark = 1;

  uint32_t minResLog2() const { return h->params.minNodeResLog2; }
  uint32_t nodeBudget() const { return opt.maxNodes == 0 ? UINT32_MAX : opt.maxNodes; }
  bool capped() {
    if (ops < opt.maxOpsPerFrame) return false;
    st.opCapBound = true;
    return true;
  }
  // screenError(h, e.id, r, view) with the distance evaluated once per frame.
  double errAt(const Entry& e, uint32_t r) const {
    return double(e.errs[r - minResLog2()]) * view.pixelsPerRadian / e.dist;
  }
  // Resolution a node needs to hold `tolPx`, clamped to its maxResLog2 (neededResolution's arithmetic).
  uint32_t resFor(const NodeEval& n, double tolPx) const {
    const double tolWorld = tolPx * n.dist / view.pixelsPerRadian;
    for (uint32_t r = minResLog2(); r <= n.maxResLog2; ++r)
      if (double(n.errs[r - minResLog2()]) <= tolWorld) return r;
    return n.maxResLog2;
  }
  bool reservedNow(const NodeId& n) const { return reserved[cut.index(n)] == reserveMark; }

  void recheckSplit(const NodeId& n) {
    uint32_t& l = listedSplit[cut.index(n)];
    if (l != listMark) l = listMark, splitRecheck.push_back(n);
  }
  void recheckGroup(const NodeId& p) {
    uint32_t& l = listedGroup[cut.index(p)];
    if (l != listMark) l = listMark, groupRecheck.push_back(p);
  }
  void setRes(Entry& e, uint32_t r) {
    if (phase2Ready) {
      recheckSplit(e.id);
      if (e.id.level > 0) recheckGroup(e.id.parent());
    }
    cut.willModify(e);
    if (e.drawn) triangles = triangles - tris(e.resLog2) + tris(r);
    e.resLog2 = r;
    e.err = e.drawn ? errAt(e, r) : 0.0;
    e.prioValid = false;
  }
  void evaluate(Entry& e) {
    evaluateWith(e, node.evaluate(e.id, nodeIndex(e.id.level, e.id.x, e.id.y), FrustumTest::kClassify));
  }
  // How e's children meet the frustum: not at all when e is inside it and holds their bounds.
  FrustumTest childTest(const Entry& e) const {
    return e.inside && nested[cut.index(e.id)] ? FrustumTest::kInside : FrustumTest::kIntersects;
  }
  void evaluateWith(Entry& e, const NodeEval& n) {
    e.drawnFlipped = e.drawn != n.drawable;
    e.drawn = n.drawable;
    e.inside = n.inside;
    e.dist = n.dist;
    e.errs = n.errs;
    e.maxResLog2 = n.maxResLog2;
    e.resLog2 = e.drawn ? std::clamp(e.resLog2, minResLog2(), e.maxResLog2) : minResLog2();
    e.err = e.drawn ? errAt(e, e.resLog2) : 0.0;
    e.prioValid = false;
  }
  void recount() {
    drawn = overMaxRes = 0;
    triangles = floorTris = 0;
    for (const auto& [k, e] : cut)
      if (e.drawn) {
        ++drawn;
        triangles += tris(e.resLog2);
        floorTris += tris(e.floor);
        overMaxRes += uint32_t(e.gap > e.maxResLog2);
      }
  }
  Cut drawnCut() const {
    Cut c;
    c.nodes.reserve(drawn);
    for (const auto& [k, e] : cut)
      if (e.drawn) c.nodes.push_back({e.id, e.resLog2, float(e.err)});
    c.rebuildIndex();
    return c;
  }
  void addCounts(const Entry& e) {
    if (floorsReady) cutChanged.push_back(e.id);
    if (!e.drawn) return;
    ++drawn;
    triangles += tris(e.resLog2);
    floorTris += tris(e.floor);
  }
  void removeCounts(const Entry& e) {
    if (floorsReady) cutChanged.push_back(e.id);
    if (!e.drawn) return;
    --drawn;
    triangles -= tris(e.resLog2);
    floorTris -= tris(e.floor);
    if (e.gap > e.maxResLog2) --overMaxRes;
  }
  // Stitching floors of the drawn nodes (paper 7.4): resolution >= level gap to finer neighbours.
  // As stitchGaps: each drawn node raises the gap of its equal-or-coarser drawn neighbours.
  void computeFloors() {
    floorsStale = false;
    // The update costs a few walks per change, the full pass a walk per entry: past a quarter of
    // the cut in changes, the full pass is cheaper (bench_adapt on the shared scans).
    if (floorsReady && cutChanged.size() * 4 < cut.size()) return updateFloors();
    floorsReady = true;
    cutChanged.clear();
    auto* items = &*cut.begin();
    newGap.assign(cut.size(), 0);
    for (size_t i = 0; i < cut.size(); ++i) {
      const Entry& m = items[i].second;
      if (!m.drawn || m.id.level == 0) continue;
      walkToCoarserNeighbours(*h, m.id, [&](const NodeId& a, uint32_t up) {
        const int32_t at = cut.slotOf(a);
        if (at < 0) return false;
        if (items[at].second.drawn) newGap[size_t(at)] = std::max(newGap[size_t(at)], up);
        return true;
      });
    }
    floorTris = 0;
    overMaxRes = 0;
    raise.clear();
    for (size_t i = 0; i < cut.size(); ++i) setGap(items[i].second, newGap[i]);
    needsConstraintSplit = overMaxRes > 0;
  }
  // Sets an entry's gap and floor (an undrawn entry: 0 and minRes), logged while a round runs;
  // counts a drawn entry in floorTris and overMaxRes, and lists it to raise or to refloor.
  void setGap(Entry& e, uint32_t gap) {
    const uint32_t floor = e.drawn ? std::clamp(gap, minResLog2(), e.maxResLog2) : minResLog2();
    if (gap != e.gap || floor != e.floor) {
      cut.willModify(e);
      if (phase1Ready && e.drawn && floor != e.floor) refloored.push_back(e.id);
      e.gap = gap;
      e.floor = floor;
    }
    if (!e.drawn) return;
    floorTris += tris(floor);
    overMaxRes += uint32_t(gap > e.maxResLog2);
    if (e.resLog2 < floor) raise.push_back(e.id);
  }

  void updateFloors() {
    if (++dirtyRound == 0) {
      std::fill(dirtyMark.begin(), dirtyMark.end(), 0u);
      dirtyRound = 1;
    }
    dirty.clear();
    auto mark = [&](const Entry& e) {
      uint32_t& m = dirtyMark[cut.index(e.id)];
      if (m != dirtyRound) m = dirtyRound, dirty.push_back(e.id);
    };
    auto find = [&](const NodeId& n) { return cut.find(n); };
    for (const NodeId& x : cutChanged) {
      if (const Entry* e = cut.find(x)) mark(*e);
      keptBeside(*h, x, find, mark);
    }
    cutChanged.clear();
    raise.clear();
    for (const NodeId& n : dirty) {
      Entry& e = *cut.find(n);
      if (e.drawn) {  // out of the counts, back in by setGap
        floorTris -= tris(e.floor);
        overMaxRes -= uint32_t(e.gap > e.maxResLog2);
      }
      setGap(e, e.drawn ? keptGap(*h, e.id, find) : 0);
    }
    needsConstraintSplit = overMaxRes > 0;
  }

  // ---- Phase 1: refine/coarsen dual queue. False when the floors exceed the triangle budget.
  void pushPhase1(const Entry& e, bool heapify) {
    if (!e.drawn) return;
    const uint64_t k = e.id.key();
    if (e.resLog2 < e.maxResLog2) {
      const double gain = (e.err - errAt(e, e.resLog2 + 1)) / double(tris(e.resLog2 + 1) - tris(e.resLog2));
      std::vector<Item>& b = refineB[e.resLog2];
      b.push_back({gain, k, e.resLog2});
      if (heapify) std::push_heap(b.begin(), b.end(), ItemLess{});
    }
    if (e.resLog2 > e.floor) {
      const double loss = (errAt(e, e.resLog2 - 1) - e.err) / double(tris(e.resLog2) - tris(e.resLog2 - 1));
      coarsenH.push_back({-loss, k, e.resLog2});
      if (heapify) std::push_heap(coarsenH.begin(), coarsenH.end(), ItemLess{});
    }
    errH.push_back({e.err, k, e.resLog2});
    if (heapify) std::push_heap(errH.begin(), errH.end(), ItemLess{});
  }
  Entry* validPhase1(const Item& it) {
    Entry* f = cut.find(it.key);
    if (!f || !f->drawn || f->resLog2 != it.resLog2) return nullptr;
    return f;
  }
  Entry* validCoarsen(const Item& it) {
    Entry* f = validPhase1(it);
    return f && f->resLog2 > f->floor ? f : nullptr;
  }
  // The largest error of the cut (0 without a drawn node), from the top of phase 1's error queue.
  double maxErrorNow() {
    while (!errH.empty() && !validPhase1(errH.front())) heapPop(errH);
    return errH.empty() ? 0.0 : std::max(0.0, errH.front().priority);
  }
  // (c) Balance: lower the max error by coarsening others (each staying below it), least error
  // increase per removed triangle first. Every trade lowers the sorted error vector
  // lexicographically, so this ends. Returns whether anything changed.
  bool balance(uint64_t budget) {
    unpark(maxErrorNow());
    bool progress = false;
    std::vector<Item> popped;
    std::vector<Entry*> chosen;
    while (!capped()) {
      Entry* m = nullptr;
      while (!errH.empty() && !(m = validPhase1(errH.front()))) heapPop(errH);
      if (!m || m->resLog2 >= m->maxResLog2) break;
      const uint64_t need = tris(m->resLog2 + 1) - tris(m->resLog2);
      const uint64_t free = budget - triangles;
      popped.clear();
      chosen.clear();
      uint64_t freed = 0;
      while (free + freed < need && !coarsenH.empty()) {
        const Item it = heapPop(coarsenH);
        Entry* c = validCoarsen(it);
        if (!c) continue;
        if (c == m || std::find(chosen.begin(), chosen.end(), c) != chosen.end()) {
          popped.push_back(it);
          continue;
        }
        // note: parked for this balance: the max error only falls during it, so a node whose
        // coarsening would reach it now never qualifies later (its own refinement pushes a new
        // item).
        const double coarsened = errAt(*c, c->resLog2 - 1);
        if (coarsened >= m->err - kEps) {
          parked.push_back({coarsened, it});
          std::push_heap(parked.begin(), parked.end(), parkedLess);
          continue;
        }
        popped.push_back(it);
        chosen.push_back(c);
        freed += tris(c->resLog2) - tris(c->resLog2 - 1);
      }
      if (free + freed < need) {
        for (const Item& it : popped) heapPush(coarsenH, it);
        break;
      }
      // note: the items popped are not pushed back: each is for m or a chosen node at the
      // resolution it leaves now (pushPhase1 queues its new ones).

      // note: setRes logs, but never moves an entry, so the pointers stay valid.
      for (Entry* c : chosen) {
        setRes(*c, c->resLog2 - 1);
        ++st.coarsens, ++ops;
        pushPhase1(*c, true);
      }
      setRes(*m, m->resLog2 + 1);
      ++st.refines, ++ops;
      pushPhase1(*m, true);
      progress = true;
    }
    return progress;
  }
  static bool parkedLess(const Parked& a, const Parked& b) { return a.coarsenedErr > b.coarsenedErr; }
  // Back to coarsenH: every parked coarsening (one heap build), or those that stay below maxErr.
  void unparkAll() {
    for (const Parked& p : parked) coarsenH.push_back(p.item);
    parked.clear();
    std::make_heap(coarsenH.begin(), coarsenH.end(), ItemLess{});
  }
  void unpark(double maxErr) {
    while (!parked.empty() && parked.front().coarsenedErr < maxErr - kEps) {
      heapPush(coarsenH, parked.front().item);
      std::pop_heap(parked.begin(), parked.end(), parkedLess);
      parked.pop_back();
    }
  }
  // The queues as a fresh build would have them: built once a frame, then brought up to date.
  void phase1Queues() {
    for (const NodeId& n : raise) {
      Entry* e = cut.find(n);
      if (!e || e->resLog2 >= e->floor) continue;
      setRes(*e, e->floor);
      ++st.constraintRaises;
      if (phase1Ready) pushPhase1(*e, true);
    }
    raise.clear();
    if (phase1Ready) {
      for (const NodeId& n : fresh)
        if (const Entry* e = cut.find(n)) pushPhase1(*e, true);
      for (const NodeId& n : refloored) {
        const Entry* e = cut.find(n);
        if (!e || !e->drawn || e->resLog2 <= e->floor) continue;
        const double loss = (errAt(*e, e->resLog2 - 1) - e->err) / double(tris(e->resLog2) - tris(e->resLog2 - 1));
        heapPush(coarsenH, {-loss, n.key(), e->resLog2});
      }
    } else {
      // The refine queue is kept per resolution: a refinement's cost (added triangles) depends
      // on the resolution alone, so the refinements that fit the remaining budget are whole
      // buckets, and the best fitting one is the best of their tops (no popping of the ones that
      // don't fit).
      refineB.resize(h->params.maxNodeResLog2 + 1);
      for (auto& b : refineB) b.clear();
      coarsenH.clear();
      parked.clear();
      errH.clear();
      for (const auto& [k, e] : cut) pushPhase1(e, false);
      for (auto& b : refineB) std::make_heap(b.begin(), b.end(), ItemLess{});
      std::make_heap(coarsenH.begin(), coarsenH.end(), ItemLess{});
      std::make_heap(errH.begin(), errH.end(), ItemLess{});
      phase1Ready = true;
    }
    fresh.clear();
    refloored.clear();
  }
  bool phase1() {
    phase1Queues();
    const uint64_t budget = opt.maxTriangles;
    // (a) Within the triangle budget (never capped).
    if (triangles > budget) unparkAll();
    while (triangles > budget) {
      Entry* e = nullptr;
      while (!coarsenH.empty() && !(e = validCoarsen(coarsenH.front()))) heapPop(coarsenH);
      if (!e) return false;
      heapPop(coarsenH);
      setRes(*e, e->resLog2 - 1);
      ++st.coarsens, ++ops;
      pushPhase1(*e, true);
    }
    for (;;) {
      bool progress = false;
      // (b) Refine, best error reduction per added triangle first, while anything fits.
      while (!capped()) {
        std::vector<Item>* best = nullptr;
        for (uint32_t r = 0; r < refineB.size(); ++r) {
          std::vector<Item>& b = refineB[r];
          if (triangles + tris(r + 1) - tris(r) > budget) continue;
          while (!b.empty() && !validPhase1(b.front())) heapPop(b);
          if (!b.empty() && (!best || ItemLess{}(best->front(), b.front()))) best = &b;
        }
        if (!best) break;
        Entry* e = validPhase1(heapPop(*best));
        setRes(*e, e->resLog2 + 1);
        ++st.refines, ++ops;
        pushPhase1(*e, true);
        progress = true;
      }
      progress = balance(budget) || progress;
      if (!progress || capped()) break;
    }
    return true;
  }

  // ---- Phase 2: split/merge proposals (an error-threshold adaptation with each node's current
  // error as its local threshold). mandatoryOnly: only the merges needed for the node budget and
  // the triangle floor, and zero-effect merges of culled groups. Returns whether anything changed.
  // cached: the children's view data through the frame's cache (single-threaded callers; a child
  // split or listed later in the frame finds it there), else computed directly.
  // bounded (optional): set when splitPriorityBound settled it.
  double splitPriority(Entry& e, bool cached = true, bool* bounded = nullptr) {
    if (e.prioValid) return e.splitPrio;
    e.prioValid = true;
    return e.splitPrio = splitPriorityNow(e, cached, bounded);
  }
  double splitPriorityNow(const Entry& e, bool cached, bool* bounded = nullptr) {
    if (!e.drawn || e.id.level + 1 >= h->params.depth) return -1.0;
    if (e.id.level == 0 && groups.frozen(e.id.chart)) return -1.0;  // a closed group's root
    if (e.resLog2 >= e.maxResLog2) return kStuckPriority * (1.0 + e.err);
    bool exact = false;
    const double bound = splitPriorityBound(e, &exact);
    if (exact || bound <= 0.0) {
      if (bounded) *bounded = true;
      return bound;
    }
    double t = double(tris(e.resLog2));
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId c = e.id.child(i);
      const NodeEval ch = cached ? node(c, childTest(e)) : node.evaluate(c, nodeIndex(c.level, c.x, c.y), childTest(e));
      if (ch.drawable) t -= double(tris(resFor(ch, e.err)));
    }
    return t;
  }
  // Without the children's view data: for a node inside the frustum whose children lie within
  // it, every non-empty child is drawn, at an eye distance in [dist, dist + extent]; each child's
  // resolution at the node's error is then known to within the resolutions at the two ends. The
  // split priority at the children's coarsest is returned, an upper bound: *exact when every
  // child's resolution is known. Without the conditions, +infinity. The ends are widened by 1e-9
  // (relative), far beyond the rounding of the arithmetic resFor does, so the bound holds for it.
  double splitPriorityBound(const Entry& e, bool* exact) const {
    *exact = false;
    if (!e.inside || !nested[cut.index(e.id)]) return std::numeric_limits<double>::infinity();
    const Hierarchy::ChartNodes& cn = h->charts[e.id.chart];
    const auto& b = cn.bounds[nodeIndex(e.id.level, e.id.x, e.id.y)];
    const double extent = double(b[3] - b[0]) + double(b[4] - b[1]) + double(b[5] - b[2]);  // >= the diagonal
    const double errWorld = double(e.errs[e.resLog2 - minResLog2()]);
    const double tolNear = errWorld * (1.0 - 1e-9), tolFar = errWorld * (1.0 + extent / e.dist) * (1.0 + 1e-9);
    const uint32_t rc = h->params.resCount();
    double t = double(tris(e.resLog2));
    bool known = true;
    for (uint32_t k = 0; k < 4; ++k) {
      const NodeId c = e.id.child(k);
      const uint32_t i = nodeIndex(c.level, c.x, c.y);
      if (cn.flags[i] & kNodeEmpty) continue;
      const float* errs = &cn.errors[size_t(i) * rc];
      const uint32_t maxRes = h->maxResLog2(c);
      const uint32_t coarsest = firstWithin(errs, minResLog2(), maxRes, tolFar);
      t -= double(tris(coarsest));
      known = known && coarsest == firstWithin(errs, minResLog2(), maxRes, tolNear);
    }
    *exact = known;
    return t;
  }
  // Merge cost (added triangles) of the group under p, and the parent's resolution.
  double mergeCost(const NodeId& p, uint32_t* parentRes) { return mergeCostWith(p, node(p), parentRes); }
  // The same with the parent's view data pe given.
  double mergeCostWith(const NodeId& p, const NodeEval& pe, uint32_t* parentRes) const {
    double tol = -1.0, childTris = 0.0;
    for (uint32_t i = 0; i < 4; ++i) {
      const Entry* f = cut.find(p.child(i));
      if (!f || !f->drawn) continue;
      tol = std::max(tol, f->err);
      childTris += double(tris(f->resLog2));
    }
    *parentRes = minResLog2();
    if (!pe.drawable) return -childTris;
    if (tol < 0.0) return double(tris(minResLog2()));
    const double tolWorld = tol * pe.dist / view.pixelsPerRadian;
    uint32_t need = minResLog2();
    while (need <= pe.maxResLog2 && !(double(pe.errs[need - minResLog2()]) <= tolWorld)) ++need;
    if (need > pe.maxResLog2) {
      *parentRes = pe.maxResLog2;
      return kOverCost * (1.0 + parentErrorAtMax(pe));
    }
    *parentRes = need;
    return double(tris(need)) - childTris;
  }
  double parentErrorAtMax(const NodeEval& pe) const {
    return double(pe.errs[pe.maxResLog2 - minResLog2()]) * view.pixelsPerRadian / pe.dist;
  }
  // The drawn-node change of splitting e: its non-empty children, without their view data when e
  // is inside the frustum and holds their bounds (nestedChildren), less e.
  int64_t drawnDelta(const Entry& e) {
    if (!e.inside || !nested[cut.index(e.id)]) return drawnDelta(e.id);
    int64_t d = -1;
    for (uint32_t i = 0; i < 4; ++i) d += int64_t(!(h->flags(e.id.child(i)) & kNodeEmpty));
    return d;
  }
  int64_t drawnDelta(const NodeId& n) {
    const NodeEval ne = node(n);
    int64_t d = -int64_t(ne.drawable);
    for (uint32_t i = 0; i < 4; ++i) d += int64_t(node(n.child(i)).drawable);
    return d;
  }
  bool groupMergeable(const NodeId& p, uint32_t r) const {
    bool any = false;
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = p.child(i);
      if (h->flags(ch) & kNodeEmpty) continue;
      const Entry* f = cut.find(ch);
      if (!f || f->splitRound == r || reservedNow(ch)) return false;
      any = true;
    }
    return any;
  }
  // Whether e is the first non-empty child of its parent: the one that lists the parent's group.
  bool firstOfGroup(const Entry& e) const {
    const NodeId par = e.id.parent();
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = par.child(i);
      if (!(h->flags(ch) & kNodeEmpty)) return ch == e.id;
    }
    return false;
  }
  void doSplit(NodeId n, uint32_t r, std::vector<Item>* splitHeap) {
    if (phase2Ready) recheckGroup(n);  // its children: mergeable again from the next round
    Entry* it = cut.find(n);
    const double tol = it->err;
    const FrustumTest test = childTest(*it);
    removeCounts(*it);
    cut.erase(n);
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = n.child(i);
      if (h->flags(ch) & kNodeEmpty) continue;
      Entry e;
      e.id = ch;
      e.splitRound = r;
      e.floor = minResLog2();
      const NodeEval ne = node(ch, test);
      evaluateWith(e, ne);
      if (e.drawn) {
        e.resLog2 = resFor(ne, tol);
        e.err = errAt(e, e.resLog2);
      }
      addCounts(e);
      Entry& added = cut.insert(e);
      if (phase1Ready) fresh.push_back(ch);
      if (splitHeap) {
        const double p = splitPriority(added);
        if (p > 0.0) heapPush(*splitHeap, {p, ch.key(), added.resLog2});
      }
    }
    ++st.splits, ++ops;
  }
  void doMerge(const NodeId& p, uint32_t r) {
    uint32_t pres = 0;
    mergeCost(p, &pres);
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = p.child(i);
      const Entry* f = cut.find(ch);
      if (!f) continue;
      removeCounts(*f);
      cut.erase(ch);
    }
    Entry e;
    e.id = p;
    e.mergedRound = r;
    e.resLog2 = pres;
    e.floor = minResLog2();
    evaluateWith(e, node(p));
    addCounts(e);
    cut.insert(e);
    if (phase1Ready) fresh.push_back(p);
    if (phase2Ready) {
      recheckSplit(p);  // splittable again from the next round
      if (p.level > 0) recheckGroup(p.parent());
    }
    ++st.merges, ++ops;
  }

  // The groups of phase 2's merge queue at the start of round r: one item per mergeable group.
  // Each entry's items are found on their own (in parallel: entry-local writes, reads of the
  // cut), then gathered in entry order.
  void listMerges(uint32_t r, bool splits) {
    splitH.clear();
    mergeH.clear();
    const size_t n = cut.size();
    listed.resize(n);
    auto* items = &*cut.begin();
    // On one thread the children's and parents' view data go through the frame's cache, where the
    // rest of the frame finds them; the threads of a parallel pass compute their own.
    const bool serial = parallelMin == 0 || n < parallelMin;
    parallelPass(n, parallelMin, [&](size_t i) {
      Entry& e = items[i].second;
      Listed& q = listed[i];
      q.bounded = false;
      q.split = splits ? splitPriority(e, serial, &q.bounded) : -1.0;
      q.merge = false;
      if (e.id.level == 0 || !firstOfGroup(e)) return;
      const NodeId par = e.id.parent();
      if (!groupMergeable(par, r)) return;
      uint32_t pres = 0;
      q.merge = true;
      q.cost = mergeCostWith(par, serial ? node(par) : node.evaluate(par, nodeIndex(par.level, par.x, par.y)), &pres);
    });
    for (size_t i = 0; i < n; ++i) {
      const Entry& e = items[i].second;
      st.boundedPriorities += uint32_t(listed[i].bounded);
      if (listed[i].split > 0.0) splitH.push_back({listed[i].split, items[i].first, e.resLog2});
      if (listed[i].merge) mergeH.push_back(mergeItem(e.id.parent(), -listed[i].cost));
    }
    std::make_heap(splitH.begin(), splitH.end(), ItemLess{});
    std::make_heap(mergeH.begin(), mergeH.end(), ItemLess{});
  }
  void startRecheckLists() {
    splitAside.clear();
    splitRecheck.clear();
    groupRecheck.clear();
    if (++listMark == 0) {  // wrapped: forget every mark
      std::fill(listedSplit.begin(), listedSplit.end(), 0u);
      std::fill(listedGroup.begin(), listedGroup.end(), 0u);
      listMark = 1;
    }
  }
  // Phase 2's queues at the start of round r as listMerges would build them, from the kept ones.
  void refreshPhase2(uint32_t r) {
    for (const Item& it : splitAside) heapPush(splitH, it);
    for (const NodeId& n : splitRecheck) {
      Entry* e = cut.find(n);
      if (!e) continue;
      const double p = splitPriority(*e);
      if (p > 0.0) heapPush(splitH, {p, n.key(), e->resLog2});
    }
    for (const NodeId& p : groupRecheck) {
      if (cut.count(p) || !groupMergeable(p, r)) continue;
      uint32_t pres = 0;
      heapPush(mergeH, mergeItem(p, -mergeCost(p, &pres)));
    }
    startRecheckLists();
  }
  // The mandatory phase when the budgets hold: only groups with every node culled collapse (no
  // drawn node changes). As phase2(true) would, in its order (by key, their costs are all 0),
  // found from the culled nodes alone. Returns whether anything changed.
  bool collapseCulled(uint32_t r) {
    std::vector<Item>& heap = mergeH;
    heap.clear();
    auto collapsible = [&](const NodeId& p) { return !node(p).drawable && groupMergeable(p, r) && groupUndrawn(p); };
    for (const auto& [k, e] : cut)
      if (!e.drawn && e.id.level > 0 && firstOfGroup(e) && collapsible(e.id.parent()))
        heap.push_back({0.0, e.id.parent().key(), 0});
    std::make_heap(heap.begin(), heap.end(), ItemLess{});
    bool changed = false;
    while (!heap.empty()) {
      const NodeId p = keyToNode(heapPop(heap).key);
      if (cut.count(p) || !collapsible(p)) continue;
      doMerge(p, r);
      --st.merges, --ops;  // free bookkeeping, not an adaptation operation
      changed = true;
      if (p.level > 0 && collapsible(p.parent())) heapPush(heap, {0.0, p.parent().key(), 0});
    }
    return changed;
  }

  bool phase2(bool mandatoryOnly) {
    const uint32_t r = ++round;
    ++reserveMark;
    const int64_t nodeBudget_ = int64_t(nodeBudget());
    const int64_t triBudget = int64_t(opt.maxTriangles);
    int64_t availNodes = nodeBudget_ - int64_t(drawn);
    int64_t availFloor = triBudget - int64_t(std::max(floorsStale ? 0 : floorTris, floorTrisNow()));
    if (mandatoryOnly && availNodes >= 0 && availFloor >= 0) return collapseCulled(r);
    if (mandatoryOnly || !phase2Ready) {
      listMerges(r, !mandatoryOnly);
      phase2Ready = !mandatoryOnly;
      startRecheckLists();
    } else {
      refreshPhase2(r);
    }
    // Valid merge top (the cost is recomputed: child resolutions may have changed).
    auto mergeTop = [&]() -> const Item* {
      while (!mergeH.empty()) {
        const Item& t = mergeH.front();
        const NodeId p = keyToNode(t.key);
        if (t.resLog2 == mergeSeq[cut.index(p)] && !cut.count(p) && groupMergeable(p, r)) {
          uint32_t pres = 0;
          const double c = -mergeCost(p, &pres);
          if (c == t.priority) return &mergeH.front();
          heapPop(mergeH);
          heapPush(mergeH, mergeItem(p, c));
          continue;
        }
        heapPop(mergeH);
      }
      return nullptr;
    };
    auto afterMerge = [&](const NodeId& p) {
      if (p.level == 0) return;
      const NodeId pp = p.parent();
      if (groupMergeable(pp, r)) {
        uint32_t pres = 0;
        heapPush(mergeH, mergeItem(pp, -mergeCost(pp, &pres)));
      }
    };
    bool changed = false;
    std::vector<Item> reservedOrder;
    int64_t reservedFloorSum = 0;  // floor triangles of the reserved splits' extra nodes
    std::vector<Item> mergeAside;
    // Pops the top merge (group p), performs it and updates the node and floor room.
    auto mergeTopAndAccount = [&](const NodeId& p) {
      const int64_t before = int64_t(drawn);
      heapPop(mergeH);
      doMerge(p, r);
      availNodes += before - int64_t(drawn);
      availFloor = triBudget - int64_t(floorTrisNow()) - reservedFloorSum;
      afterMerge(p);
      changed = true;
    };
    for (;;) {
      const Item* m = mergeTop();
      if (availNodes < 0 || availFloor < 0) {  // mandatory
        if (!m) break;
        ++st.budgetMerges;
        mergeTopAndAccount(keyToNode(m->key));
        continue;
      }
      if (mandatoryOnly) {
        // Culled groups collapse (no drawn node changes).
        if (m && !node(keyToNode(m->key)).drawable && -m->priority <= 0.0 && groupUndrawn(keyToNode(m->key))) {
          const NodeId p = keyToNode(m->key);
          heapPop(mergeH);
          doMerge(p, r);
          --st.merges, --ops;  // free bookkeeping, not an adaptation operation
          afterMerge(p);
          changed = true;
          continue;
        }
        if (m) {
          mergeAside.push_back(heapPop(mergeH));
          continue;
        }
        break;
      }
      if (capped()) break;
      Entry* s = splitTop(r);
      if (m && -m->priority <= 0.0) {  // free merge: no triangles added at the local errors
        const NodeId p = keyToNode(m->key);
        if (!s || !(s->id.level > 0 && s->id.parent() == p)) {
          mergeTopAndAccount(p);
          continue;
        }
      }
      if (!s) break;
      const int64_t d = drawnDelta(*s);
      const int64_t df = d * int64_t(tris(minResLog2()));
      if (d <= availNodes && df <= availFloor) {
        const Item it = heapPop(splitH);
        reserved[cut.index(s->id)] = reserveMark;
        reservedOrder.push_back(it);
        reservedFloorSum += df;
        availNodes -= d;
        availFloor -= df;
        continue;
      }
      const double sp = splitH.front().priority;
      // Trade: a merge that costs fewer triangles than the split saves pays for it. The split is
      // blocked by the node budget or the triangle floor (both count drawn nodes), so only a merge
      // that lowers the drawn node count can pay; one that does not (a culled group whose parent
      // is visible draws one node more) is set aside for this round.
      // A merge whose parent cannot hold its children's errors (over cost) pays only when the
      // parent's error at maxResLog2 stays below the error of the node to split: merging zero-error
      // groups to split the worst node at maxResLog2 is the trade a full node budget needs.
      const NodeId mp = m ? keyToNode(m->key) : NodeId{};
      const bool pays =
          m && (-m->priority < kOverCost ? -m->priority < sp : parentErrorAtMax(node(mp)) < s->err - kEps);
      if (pays && !(s->id.level > 0 && s->id.parent() == mp)) {
        if (mergeFreedNodes(mp) <= 0) {
          mergeAside.push_back(heapPop(mergeH));
          continue;
        }
        mergeTopAndAccount(mp);
        continue;
      }
      // Does not fit, and no merge pays for it: set aside for this round.
      if (phase2Ready) splitAside.push_back(splitH.front());
      heapPop(splitH);
    }
    for (const Item& it : mergeAside) heapPush(mergeH, it);
    if (mandatoryOnly) return changed;
    return phase2Splits(reservedOrder, r, nodeBudget_, triBudget) || changed;
  }
  // Phase 2's valid split top: a drawn node as it was queued, not merged in round r nor reserved.
  Entry* splitTop(uint32_t r) {
    while (!splitH.empty()) {
      const Item& t = splitH.front();
      Entry* f = cut.find(t.key);
      if (f && f->drawn && f->resLog2 == t.resLog2 && f->mergedRound != r && !reservedNow(f->id)) return f;
      heapPop(splitH);
    }
    return nullptr;
  }
  // Phase 2's splits in round r: the reserved splits (in their order), then any further split that
  // still fits the node and triangle budgets. Returns whether any was made.
  bool phase2Splits(const std::vector<Item>& reservedOrder, uint32_t r, int64_t nodeLimit, int64_t triBudget) {
    bool changed = false;
    ++reserveMark;
    for (const Item& it : reservedOrder) {
      const Entry* f = cut.find(it.key);
      if (!f) continue;
      doSplit(f->id, r, &splitH);
      changed = true;
    }
    while (!capped()) {
      Entry* s = splitTop(r);
      if (!s) break;
      const Item it = heapPop(splitH);
      const int64_t d = drawnDelta(*s);
      if (int64_t(drawn) + d > nodeLimit || int64_t(floorTrisNow()) + d * int64_t(tris(minResLog2())) > triBudget) {
        splitAside.push_back(it);
        continue;
      }
      doSplit(s->id, r, &splitH);
      changed = true;
    }
    return changed;
  }
  // Replaces the kept nodes of every chart in a closed group by the chart's root.
  void collapseClosedCharts() {
    if (!groups.active ||
        std::none_of(groups.closedOf.begin(), groups.closedOf.end(), [](int32_t g) { return g >= 0; }))
      return;
    std::vector<NodeId> drop;
    std::vector<uint32_t> charts;
    for (const auto& [k, e] : cut)
      if (e.id.level > 0 && groups.frozen(e.id.chart)) drop.push_back(e.id);
    for (const NodeId& n : drop) {
      charts.push_back(n.chart);
      cut.erase(n);
      if (floorsReady) cutChanged.push_back(n);
    }
    std::sort(charts.begin(), charts.end());
    charts.erase(std::unique(charts.begin(), charts.end()), charts.end());
    for (uint32_t c : charts) {
      Entry root;
      root.id = {c, 0, 0, 0};
      root.floor = minResLog2();
      if (cut.count(root.id)) continue;
      cut.insert(root);
      if (floorsReady) cutChanged.push_back(root.id);
    }
  }
  // Triangle floor of the drawn nodes at minRes (floors are recomputed after the round).
  uint64_t floorTrisNow() const { return uint64_t(drawn) * tris(minResLog2()); }
  // Drawn nodes a merge of the group under p removes (drawn children minus the drawn parent).
  int64_t mergeFreedNodes(const NodeId& p) {
    int64_t n = -int64_t(node(p).drawable);
    for (uint32_t i = 0; i < 4; ++i) {
      const Entry* f = cut.find(p.child(i));
      if (f && f->drawn) ++n;
    }
    return n;
  }
  bool groupUndrawn(const NodeId& p) const {
    for (uint32_t i = 0; i < 4; ++i) {
      const Entry* f = cut.find(p.child(i));
      if (f && f->drawn) return false;
    }
    return true;
  }
};

QuadQueueAdapter::QuadQueueAdapter(const Hierarchy& h, uint32_t parallelMin)
    : h_(h), state_(std::make_shared<State>()) {
  state_->parallelMin = parallelMin;
}

void QuadQueueAdapter::reset() {
  state_->floorsReady = false;
  state_->cut.clear();
  state_->out = Cut{};
}

const Cut& QuadQueueAdapter::update(const ViewParams& view, const BudgetOptions& options, BudgetStats* stats) {
  State& s = *state_;
  s.h = &h_;
  s.view = view;
  s.opt = options;
  s.opt.maxOpsPerFrame = std::max(options.maxOpsPerFrame, 1u);
  s.ops = 0;
  s.st = {};
  BudgetStats& st = s.st;

  selectRootGroups(h_, {view, 0.0, options.frustumCull}, options.maxNodes, s.groups, options.maxTriangles);
  // Every root counts as a node in the kept cut; the closed groups' roots count once a group in
  // the returned cut.
  s.opt.maxNodes = s.groups.chartBudget(options.maxNodes);
  s.cut.init(h_);
  s.node.init(h_);
  s.node.newFrame(h_, s.view, options.frustumCull, 4 * s.cut.size());
  if (s.reserved.size() != s.cut.forestSize() || ++s.reserveMark > UINT32_MAX - 4096) {
    s.reserved.assign(s.cut.forestSize(), 0);  // (re)start the marks
    s.reserveMark = 1;
  }
  s.phase1Ready = s.phase2Ready = false;
  if (s.dirtyMark.size() != s.cut.forestSize()) s.dirtyMark.assign(s.cut.forestSize(), 0);
  if (s.nested.size() != s.cut.forestSize()) s.nested = nestedChildren(h_);
  s.fresh.clear();
  s.refloored.clear();
  if (s.mergeSeq.size() != s.cut.forestSize()) s.mergeSeq.assign(s.cut.forestSize(), 0);
  if (s.mergeSeqNext > UINT32_MAX - (1u << 24)) {  // restart the numbers (no queue holds one now)
    std::fill(s.mergeSeq.begin(), s.mergeSeq.end(), 0u);
    s.mergeSeqNext = 0;
  }
  if (s.listedSplit.size() != s.cut.forestSize()) {
    s.listedSplit.assign(s.cut.forestSize(), 0);
    s.listedGroup.assign(s.cut.forestSize(), 0);
  }
  s.collapseClosedCharts();
  if (s.cut.empty())
    for (uint32_t c = 0; c < h_.chartCount(); ++c) {
      Entry e;
      e.id = {c, 0, 0, 0};
      e.floor = s.minResLog2();
      if (!(h_.flags(e.id) & kNodeEmpty)) s.cut.insert(e);
    }
  {
    auto* items = &*s.cut.begin();
    parallelPass(s.cut.size(), s.parallelMin, [&](size_t i) { s.evaluate(items[i].second); });
    // The floors are kept from frame to frame: a node culled or uncovered changes its neighbours'.
    if (s.floorsReady)
      for (size_t i = 0; i < s.cut.size(); ++i)
        if (items[i].second.drawnFlipped) s.cutChanged.push_back(items[i].second.id);
  }
  s.floorsStale = true;
  s.recount();

  // Mandatory: node budget, triangle floor (with the stitching floors), culled groups collapse.
  s.phase2(true);
  s.computeFloors();
  for (uint32_t guard = 0; s.floorTris > options.maxTriangles && guard < 64; ++guard) {
    if (!s.phase2(true)) break;
    s.computeFloors();
  }
  s.phase1();

  for (uint32_t r = 0; r < options.maxRounds && !s.capped(); ++r) {
    s.cut.beginLog();
    const BudgetStats savedStats = st;
    const bool savedNeedsSplit = s.needsConstraintSplit;
    const double savedMax = s.maxErrorNow();
    if (!s.phase2(false)) break;
    ++st.rounds;
    s.computeFloors();
    const bool ok = s.phase1();
    const double now = s.maxErrorNow();
    const bool worse = !ok || now > savedMax + kEps;
    if (worse || now >= savedMax - kEps) {
      // Undo-based termination (paper 7.1); a round that does not strictly lower the max error
      // is undone too, so a static view reaches a fixed point.
      const uint32_t done = st.refines + st.coarsens + st.splits + st.merges;
      const uint32_t kept = savedStats.refines + savedStats.coarsens + savedStats.splits + savedStats.merges;
      s.cut.undo();  // the entries, their gaps and floors included, as before the round
      s.cutChanged.clear();
      s.recount();
      s.needsConstraintSplit = savedNeedsSplit;  // the floors the kept entries were fitted to
      st.refines = savedStats.refines, st.coarsens = savedStats.coarsens;
      st.splits = savedStats.splits, st.merges = savedStats.merges;
      st.constraintRaises = savedStats.constraintRaises;
      st.undoneOps += done - kept;
      if (worse)
        ++st.undos;
      else
        ++st.tieUndos;
      break;
    }
    s.cut.endLog();
  }

  // The drawn cut; the floors already satisfy the stitching constraint unless a node would need
  // a resolution above its maxResLog2 (then enforceStitchConstraint splits it, reported as
  // constraintSplits, and groups elsewhere merge back into the node budget).
  // Every drawn node is at or above its floor, so without such a node the constraint holds as it
  // is (enforceStitchConstraint would change nothing) and each node's errorPx is already
  // screenError's.
  s.out = s.drawnCut();
  if (s.needsConstraintSplit) {
    AdaptStats as;
    enforceStitchConstraint(h_, s.out, &view, 1.0, &as);
    st.constraintSplits = as.constraintSplits;
    st.constraintRaises += as.constraintRaises;
    if (as.constraintSplits > 0) {
      holdNodeBudget(h_, s.out, view, s.opt.maxNodes);
      fitTriangleBudget(h_, s.out, view, options.maxTriangles);
    }
    for (CutNode& n : s.out.nodes) n.errorPx = float(screenError(h_, n.id, n.resLog2, view));
  }
  markGroupedRoots(s.groups, s.out);
  AdaptStats counts;
  setCutCounts(s.out, counts);
  st.nodes = counts.nodes;
  st.closedGroups = counts.closedGroups;
  st.groupedRoots = counts.groupedRoots;
  st.triangles = s.out.triangles();
  st.rootFloor = s.groups.rootFloor;
  st.budgetBelowRoots = budgetBelowRoots(options.maxNodes, st.rootFloor);
  double sum = 0.0;
  for (const CutNode& n : s.out.nodes) {
    st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
    sum += n.errorPx;
  }
  st.meanErrorPx = s.out.nodes.empty() ? 0.0 : sum / double(s.out.nodes.size());
  if (stats) *stats = st;
  return s.out;
}

bool fitTriangleBudget(const Hierarchy& h, Cut& cut, const ViewParams& view, uint64_t maxTriangles) {
  std::vector<SideNeighbour> scratch;
  std::vector<uint32_t> floor(cut.nodes.size());
  const uint32_t rmin = h.params.minNodeResLog2;
  for (uint32_t i = 0; i < cut.nodes.size(); ++i) floor[i] = std::max(rmin, finestNeighbourGap(h, cut, i, scratch));
  uint64_t total = cut.triangles();
  std::vector<Item> heap;
  auto push = [&](uint32_t i) {
    const CutNode& n = cut.nodes[i];
    if (n.resLog2 <= floor[i]) return;
    const double loss = (screenError(h, n.id, n.resLog2 - 1, view) - screenError(h, n.id, n.resLog2, view)) /
                        double(tris(n.resLog2) - tris(n.resLog2 - 1));
    heapPush(heap, {-loss, i, n.resLog2});
  };
  for (uint32_t i = 0; i < cut.nodes.size(); ++i) push(i);
  while (total > maxTriangles && !heap.empty()) {
    const Item it = heapPop(heap);
    CutNode& n = cut.nodes[it.key];
    if (n.resLog2 != it.resLog2) continue;
    total -= tris(n.resLog2) - tris(n.resLog2 - 1);
    --n.resLog2;
    push(uint32_t(it.key));
  }
  return total <= maxTriangles;
}

}  // namespace gimlod

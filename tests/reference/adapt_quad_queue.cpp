// The reference for QuadQueueAdapter (runtime/adapt_quad_queue.h): the adapter as it was before its per-frame work
// was made incremental, kept unchanged so that the equivalence tests and bench_adapt compare
// the runtime's adapter with it (same cuts, or equal or lower error within the same budgets).
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (the quad-queue algorithm for the
// triangle-budget problem with a node budget: refine/coarsen and split/merge dual-queue pairs,
// undo-based termination); section 7.4 (stitching constraint).
#include "tests/reference/adapt_quad_queue.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "runtime/adapt_dual_queue.h"
#include "runtime/group_select.h"

namespace gimlod::reference {
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
  bool drawn = false;
  double err = 0.0;   // screen error at res; 0 when not drawn
  double dist = 1.0;  // eye distance to the bounds this frame (as screenError clamps it)
  uint32_t splitRound = 0, mergedRound = 0;
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
// hashing), with the subset of std::unordered_map's interface the adapter uses. Erasing moves the
// last entry into the hole, so iterators and pointers are valid only until the next change.
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
  iterator find(uint64_t key) {
    const int32_t s = slot_[index(key)];
    return s < 0 ? items_.end() : items_.begin() + s;
  }
  const_iterator find(uint64_t key) const {
    const int32_t s = slot_[index(key)];
    return s < 0 ? items_.end() : items_.begin() + s;
  }
  size_t count(uint64_t key) const { return slot_[index(key)] >= 0 ? 1 : 0; }
  Entry& operator[](uint64_t key) {
    const size_t i = index(key);
    if (slot_[i] < 0) {
      slot_[i] = int32_t(items_.size());
      items_.push_back({key, Entry{}});
    }
    return items_[size_t(slot_[i])].second;
  }
  void erase(iterator it) { eraseAt(size_t(it - items_.begin())); }
  void erase(uint64_t key) {
    const int32_t s = slot_[index(key)];
    if (s >= 0) eraseAt(size_t(s));
  }
  void clear() {
    for (const value_type& v : items_) slot_[index(v.first)] = -1;
    items_.clear();
  }
  // A copy of the entries for undo; restore puts them back (O(size), not O(forest)).
  std::vector<value_type> snapshot() const { return items_; }
  void restore(const std::vector<value_type>& saved) {
    clear();
    items_ = saved;
    for (size_t i = 0; i < items_.size(); ++i) slot_[index(items_[i].first)] = int32_t(i);
  }

 private:
  size_t index(uint64_t key) const {
    const NodeId n = NodeId::fromKey(key);
    return size_t(n.chart) * perChart_ + nodeIndex(n.level, n.x, n.y);
  }
  void eraseAt(size_t s) {
    slot_[index(items_[s].first)] = -1;
    if (s + 1 != items_.size()) {
      items_[s] = std::move(items_.back());
      slot_[index(items_[s].first)] = int32_t(s);
    }
    items_.pop_back();
  }
  uint32_t perChart_ = 0;
  std::vector<int32_t> slot_;
  std::vector<value_type> items_;
};

}  // namespace

struct QuadQueueAdapter::State {
  EntryMap cut;  // partition of the non-empty chart area
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
  std::vector<SideNeighbour> scratch;
  GroupSelection groups;  // this frame's closed groups (their roots never split)

  uint32_t maxResLog2(const NodeId& n) const { return h->maxResLog2(n); }
  uint32_t minResLog2() const { return h->params.minNodeResLog2; }
  uint32_t nodeBudget() const { return opt.maxNodes == 0 ? UINT32_MAX : opt.maxNodes; }
  bool capped() {
    if (ops < opt.maxOpsPerFrame) return false;
    st.opCapBound = true;
    return true;
  }
  // screenError(h, e.id, r, view) with the distance evaluated once per frame.
  double errAt(const Entry& e, uint32_t r) const { return double(h->error(e.id, r)) * view.pixelsPerRadian / e.dist; }
  // Resolution a node needs to hold `tolPx`, clamped to its maxResLog2.
  uint32_t resFor(const NodeId& n, double tolPx) const {
    return std::min(neededResolution(*h, n, view, tolPx), maxResLog2(n));
  }

  void setRes(Entry& e, uint32_t r) {
    if (e.drawn) triangles = triangles - tris(e.resLog2) + tris(r);
    e.resLog2 = r;
    e.err = e.drawn ? errAt(e, r) : 0.0;
  }
  void evaluate(Entry& e) {
    e.drawn = nodeDrawable(*h, e.id, view, opt.frustumCull);
    const auto& b = h->bounds(e.id);
    const glm::dvec3 q = glm::clamp(view.eye, glm::dvec3{b[0], b[1], b[2]}, glm::dvec3{b[3], b[4], b[5]}) - view.eye;
    e.dist = std::max(glm::length(q), view.minDistance);
    e.resLog2 = e.drawn ? std::clamp(e.resLog2, minResLog2(), maxResLog2(e.id)) : minResLog2();
    e.floor = minResLog2();
    e.err = e.drawn ? errAt(e, e.resLog2) : 0.0;
  }
  void recount() {
    drawn = 0;
    triangles = floorTris = 0;
    for (const auto& [k, e] : cut)
      if (e.drawn) {
        ++drawn;
        triangles += tris(e.resLog2);
        floorTris += tris(e.floor);
      }
  }
  double maxError() const {
    double m = 0.0;
    for (const auto& [k, e] : cut) m = std::max(m, e.err);
    return m;
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
    if (!e.drawn) return;
    ++drawn;
    triangles += tris(e.resLog2);
    floorTris += tris(e.floor);
  }
  void removeCounts(const Entry& e) {
    if (!e.drawn) return;
    --drawn;
    triangles -= tris(e.resLog2);
    floorTris -= tris(e.floor);
  }
  // Stitching floors of the drawn nodes (paper 7.4): resolution >= level gap to finer neighbours.
  // As stitchGaps: each drawn node raises the gap of its equal-or-coarser drawn neighbours.
  void computeFloors() {
    needsConstraintSplit = false;
    for (auto& [k, e] : cut) e.gap = 0;
    for (const auto& [k, m] : cut) {
      if (!m.drawn || m.id.level == 0) continue;
      walkToCoarserNeighbours(*h, m.id, [&](const NodeId& a, uint32_t up) {
        auto f = cut.find(a.key());
        if (f == cut.end()) return false;
        if (f->second.drawn) f->second.gap = std::max(f->second.gap, up);
        return true;
      });
    }
    floorTris = 0;
    for (auto& [k, e] : cut) {
      if (!e.drawn) continue;
      if (e.gap > maxResLog2(e.id)) needsConstraintSplit = true;
      e.floor = std::clamp(e.gap, minResLog2(), maxResLog2(e.id));
      floorTris += tris(e.floor);
    }
  }

  // ---- Phase 1: refine/coarsen dual queue. False when the floors exceed the triangle budget.
  bool phase1() {
    for (auto& [k, e] : cut)
      if (e.drawn && e.resLog2 < e.floor) {
        setRes(e, e.floor);
        ++st.constraintRaises;
      }
    // The refine queue is kept per resolution: a refinement's cost (added triangles) depends on
    // the resolution alone, so the refinements that fit the remaining budget are whole buckets,
    // and the best fitting one is the best of their tops (no popping of the ones that don't fit).
    std::vector<std::vector<Item>> refineB(h->params.maxNodeResLog2 + 1);
    std::vector<Item> coarsenH, errH;
    auto push = [&](const Entry& e, bool heapify) {
      if (!e.drawn) return;
      const uint64_t k = e.id.key();
      if (e.resLog2 < maxResLog2(e.id)) {
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
    };
    for (const auto& [k, e] : cut) push(e, false);
    for (auto& b : refineB) std::make_heap(b.begin(), b.end(), ItemLess{});
    std::make_heap(coarsenH.begin(), coarsenH.end(), ItemLess{});
    std::make_heap(errH.begin(), errH.end(), ItemLess{});
    auto valid = [&](const Item& it) -> Entry* {
      auto f = cut.find(it.key);
      if (f == cut.end() || !f->second.drawn || f->second.resLog2 != it.resLog2) return nullptr;
      return &f->second;
    };
    const uint64_t budget = opt.maxTriangles;
    // (a) Within the triangle budget (never capped).
    while (triangles > budget) {
      Entry* e = nullptr;
      while (!coarsenH.empty() && !(e = valid(coarsenH.front()))) heapPop(coarsenH);
      if (!e) return false;
      heapPop(coarsenH);
      setRes(*e, e->resLog2 - 1);
      ++st.coarsens, ++ops;
      push(*e, true);
    }
    for (;;) {
      bool progress = false;
      // (b) Refine, best error reduction per added triangle first, while anything fits.
      while (!capped()) {
        std::vector<Item>* best = nullptr;
        for (uint32_t r = 0; r < refineB.size(); ++r) {
          std::vector<Item>& b = refineB[r];
          if (triangles + tris(r + 1) - tris(r) > budget) continue;
          while (!b.empty() && !valid(b.front())) heapPop(b);
          if (!b.empty() && (!best || ItemLess{}(best->front(), b.front()))) best = &b;
        }
        if (!best) break;
        Entry* e = valid(heapPop(*best));
        setRes(*e, e->resLog2 + 1);
        ++st.refines, ++ops;
        push(*e, true);
        progress = true;
      }
      // (c) Balance: lower the max error by coarsening others (each staying below it), least
      // error increase per removed triangle first. Every trade lowers the sorted error vector
      // lexicographically, so this ends.
      while (!capped()) {
        Entry* m = nullptr;
        while (!errH.empty() && !(m = valid(errH.front()))) heapPop(errH);
        if (!m || m->resLog2 >= maxResLog2(m->id)) break;
        const uint64_t need = tris(m->resLog2 + 1) - tris(m->resLog2);
        const uint64_t free = budget - triangles;
        std::vector<Item> popped;
        std::vector<Entry*> chosen;
        uint64_t freed = 0;
        while (free + freed < need && !coarsenH.empty()) {
          const Item it = heapPop(coarsenH);
          Entry* c = valid(it);
          if (!c) continue;
          if (c == m || std::find(chosen.begin(), chosen.end(), c) != chosen.end()) {
            popped.push_back(it);
            continue;
          }
          // note: dropped for good: the max error only falls during the balance, so a node whose
          // coarsening would reach it now never qualifies later (its own refinement pushes a new
          // item).
          if (errAt(*c, c->resLog2 - 1) >= m->err - kEps) continue;
          popped.push_back(it);
          chosen.push_back(c);
          freed += tris(c->resLog2) - tris(c->resLog2 - 1);
        }
        for (const Item& it : popped) heapPush(coarsenH, it);
        if (free + freed < need) break;
        for (Entry* c : chosen) {
          setRes(*c, c->resLog2 - 1);
          ++st.coarsens, ++ops;
          push(*c, true);
        }
        setRes(*m, m->resLog2 + 1);
        ++st.refines, ++ops;
        push(*m, true);
        progress = true;
      }
      if (!progress || capped()) break;
    }
    return true;
  }

  // ---- Phase 2: split/merge proposals (an error-threshold adaptation with each node's current
  // error as its local threshold). mandatoryOnly: only the merges needed for the node budget and
  // the triangle floor, and zero-effect merges of culled groups. Returns whether anything changed.
  double splitPriority(const Entry& e) const {
    if (!e.drawn || e.id.level + 1 >= h->params.depth) return -1.0;
    if (e.id.level == 0 && groups.frozen(e.id.chart)) return -1.0;  // a closed group's root
    if (e.resLog2 >= maxResLog2(e.id)) return kStuckPriority * (1.0 + e.err);
    double t = double(tris(e.resLog2));
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = e.id.child(i);
      if (nodeDrawable(*h, ch, view, opt.frustumCull)) t -= double(tris(resFor(ch, e.err)));
    }
    return t;
  }
  // Merge cost (added triangles) of the group under p, and the parent's resolution.
  double mergeCost(const NodeId& p, uint32_t* parentRes) const {
    double tol = -1.0, childTris = 0.0;
    for (uint32_t i = 0; i < 4; ++i) {
      auto f = cut.find(p.child(i).key());
      if (f == cut.end() || !f->second.drawn) continue;
      tol = std::max(tol, f->second.err);
      childTris += double(tris(f->second.resLog2));
    }
    *parentRes = minResLog2();
    if (!nodeDrawable(*h, p, view, opt.frustumCull)) return -childTris;
    if (tol < 0.0) return double(tris(minResLog2()));
    const uint32_t need = neededResolution(*h, p, view, tol);
    if (need > maxResLog2(p)) {
      *parentRes = maxResLog2(p);
      return kOverCost * (1.0 + screenError(*h, p, maxResLog2(p), view));
    }
    *parentRes = need;
    return double(tris(need)) - childTris;
  }
  int64_t drawnDelta(const NodeId& n) const {
    int64_t d = -int64_t(nodeDrawable(*h, n, view, opt.frustumCull));
    for (uint32_t i = 0; i < 4; ++i) d += int64_t(nodeDrawable(*h, n.child(i), view, opt.frustumCull));
    return d;
  }
  bool groupMergeable(const NodeId& p, uint32_t r, const std::unordered_set<uint64_t>& reserved) const {
    bool any = false;
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = p.child(i);
      if (h->flags(ch) & kNodeEmpty) continue;
      auto f = cut.find(ch.key());
      if (f == cut.end() || f->second.splitRound == r || reserved.count(ch.key())) return false;
      any = true;
    }
    return any;
  }
  void doSplit(NodeId n, uint32_t r, std::vector<Item>* splitH) {
    auto it = cut.find(n.key());
    const double tol = it->second.err;
    removeCounts(it->second);
    cut.erase(it);
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = n.child(i);
      if (h->flags(ch) & kNodeEmpty) continue;
      Entry e;
      e.id = ch;
      e.splitRound = r;
      evaluate(e);
      if (e.drawn) {
        e.resLog2 = resFor(ch, tol);
        e.err = errAt(e, e.resLog2);
      }
      addCounts(e);
      cut[ch.key()] = e;
      if (splitH) {
        const double p = splitPriority(e);
        if (p > 0.0) heapPush(*splitH, {p, ch.key(), e.resLog2});
      }
    }
    ++st.splits, ++ops;
  }
  void doMerge(const NodeId& p, uint32_t r) {
    uint32_t pres = 0;
    mergeCost(p, &pres);
    for (uint32_t i = 0; i < 4; ++i) {
      auto f = cut.find(p.child(i).key());
      if (f == cut.end()) continue;
      removeCounts(f->second);
      cut.erase(f);
    }
    Entry e;
    e.id = p;
    e.mergedRound = r;
    e.resLog2 = pres;
    evaluate(e);
    addCounts(e);
    cut[p.key()] = e;
    ++st.merges, ++ops;
  }

  bool phase2(bool mandatoryOnly) {
    const uint32_t r = ++round;
    std::vector<Item> splitH, mergeH;
    std::unordered_set<uint64_t> reserved, seen;
    for (const auto& [k, e] : cut) {
      if (!mandatoryOnly) {
        const double p = splitPriority(e);
        if (p > 0.0) splitH.push_back({p, k, e.resLog2});
      }
      if (e.id.level == 0) continue;
      const NodeId par = e.id.parent();
      if (!seen.insert(par.key()).second || !groupMergeable(par, r, reserved)) continue;
      uint32_t pres = 0;
      mergeH.push_back({-mergeCost(par, &pres), par.key(), 0});
    }
    std::make_heap(splitH.begin(), splitH.end(), ItemLess{});
    std::make_heap(mergeH.begin(), mergeH.end(), ItemLess{});
    // Valid merge top (the cost is recomputed: child resolutions may have changed).
    auto mergeTop = [&]() -> const Item* {
      while (!mergeH.empty()) {
        const Item& t = mergeH.front();
        const NodeId p = keyToNode(t.key);
        if (!cut.count(t.key) && groupMergeable(p, r, reserved)) {
          uint32_t pres = 0;
          const double c = -mergeCost(p, &pres);
          if (c == t.priority) return &mergeH.front();
          const Item re{c, t.key, 0};
          heapPop(mergeH);
          heapPush(mergeH, re);
          continue;
        }
        heapPop(mergeH);
      }
      return nullptr;
    };
    auto splitTop = [&]() -> Entry* {
      while (!splitH.empty()) {
        const Item& t = splitH.front();
        auto f = cut.find(t.key);
        if (f != cut.end() && f->second.drawn && f->second.resLog2 == t.resLog2 && f->second.mergedRound != r &&
            !reserved.count(t.key))
          return &f->second;
        heapPop(splitH);
      }
      return nullptr;
    };
    auto afterMerge = [&](const NodeId& p) {
      if (p.level == 0) return;
      const NodeId pp = p.parent();
      if (groupMergeable(pp, r, reserved)) {
        uint32_t pres = 0;
        heapPush(mergeH, {-mergeCost(pp, &pres), pp.key(), 0});
      }
    };
    const int64_t nodeBudget_ = int64_t(nodeBudget());
    const int64_t triBudget = int64_t(opt.maxTriangles);
    int64_t availNodes = nodeBudget_ - int64_t(drawn);
    int64_t availFloor = triBudget - int64_t(std::max(floorTris, floorTrisNow()));
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
        if (m && !nodeDrawable(*h, keyToNode(m->key), view, opt.frustumCull) && -m->priority <= 0.0 &&
            groupUndrawn(keyToNode(m->key))) {
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
      Entry* s = splitTop();
      if (m && -m->priority <= 0.0) {  // free merge: no triangles added at the local errors
        const NodeId p = keyToNode(m->key);
        if (!s || !(s->id.level > 0 && s->id.parent() == p)) {
          mergeTopAndAccount(p);
          continue;
        }
      }
      if (!s) break;
      const int64_t d = drawnDelta(s->id);
      const int64_t df = d * int64_t(tris(minResLog2()));
      if (d <= availNodes && df <= availFloor) {
        const Item it = heapPop(splitH);
        reserved.insert(it.key);
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
      const bool pays = m && (-m->priority < kOverCost ? -m->priority < sp
                                                       : screenError(*h, mp, maxResLog2(mp), view) < s->err - kEps);
      if (pays && !(s->id.level > 0 && s->id.parent() == mp)) {
        const NodeId p = mp;
        if (mergeFreedNodes(p) <= 0) {
          mergeAside.push_back(heapPop(mergeH));
          continue;
        }
        mergeTopAndAccount(p);
        continue;
      }
      heapPop(splitH);  // does not fit, and no merge pays for it
    }
    for (const Item& it : mergeAside) heapPush(mergeH, it);
    if (mandatoryOnly) return changed;
    // Split: the reserved splits, then any further split that still fits.
    reserved.clear();
    for (const Item& it : reservedOrder) {
      auto f = cut.find(it.key);
      if (f == cut.end()) continue;
      doSplit(f->second.id, r, &splitH);
      changed = true;
    }
    while (!capped()) {
      Entry* s = splitTop();
      if (!s) break;
      const Item it = heapPop(splitH);
      const int64_t d = drawnDelta(s->id);
      if (int64_t(drawn) + d > nodeBudget_ || int64_t(floorTrisNow()) + d * int64_t(tris(minResLog2())) > triBudget)
        continue;
      (void)it;
      doSplit(s->id, r, &splitH);
      changed = true;
    }
    return changed;
  }
  // Replaces the kept nodes of every chart in a closed group by the chart's root.
  void collapseClosedCharts() {
    if (!groups.active) return;
    std::vector<uint64_t> drop;
    std::vector<uint32_t> charts;
    for (const auto& [k, e] : cut)
      if (e.id.level > 0 && groups.frozen(e.id.chart)) drop.push_back(k);
    for (uint64_t k : drop) {
      charts.push_back(NodeId::fromKey(k).chart);
      cut.erase(k);
    }
    std::sort(charts.begin(), charts.end());
    charts.erase(std::unique(charts.begin(), charts.end()), charts.end());
    for (uint32_t c : charts) {
      const NodeId root{c, 0, 0, 0};
      if (!cut.count(root.key())) cut[root.key()].id = root;
    }
  }
  // Triangle floor of the drawn nodes at minRes (floors are recomputed after the round).
  uint64_t floorTrisNow() const { return uint64_t(drawn) * tris(minResLog2()); }
  // Drawn nodes a merge of the group under p removes (drawn children minus the drawn parent).
  int64_t mergeFreedNodes(const NodeId& p) const {
    int64_t n = -int64_t(nodeDrawable(*h, p, view, opt.frustumCull));
    for (uint32_t i = 0; i < 4; ++i) {
      auto f = cut.find(p.child(i).key());
      if (f != cut.end() && f->second.drawn) ++n;
    }
    return n;
  }
  bool groupUndrawn(const NodeId& p) const {
    for (uint32_t i = 0; i < 4; ++i) {
      auto f = cut.find(p.child(i).key());
      if (f != cut.end() && f->second.drawn) return false;
    }
    return true;
  }
};

QuadQueueAdapter::QuadQueueAdapter(const Hierarchy& h) : h_(h), state_(std::make_shared<State>()) {}

void QuadQueueAdapter::reset() {
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
  s.collapseClosedCharts();
  if (s.cut.empty())
    for (uint32_t c = 0; c < h_.chartCount(); ++c) {
      const NodeId root{c, 0, 0, 0};
      if (h_.flags(root) & kNodeEmpty) continue;
      Entry e;
      e.id = root;
      s.cut[root.key()] = e;
    }
  for (auto& [k, e] : s.cut) s.evaluate(e);
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
    const auto saved = s.cut.snapshot();
    const BudgetStats savedStats = st;
    const double savedMax = s.maxError();
    if (!s.phase2(false)) break;
    ++st.rounds;
    s.computeFloors();
    const bool ok = s.phase1();
    const double now = s.maxError();
    const bool worse = !ok || now > savedMax + kEps;
    if (worse || now >= savedMax - kEps) {
      // Undo-based termination (paper 7.1); a round that does not strictly lower the max error
      // is undone too, so a static view reaches a fixed point.
      const uint32_t done = st.refines + st.coarsens + st.splits + st.merges;
      const uint32_t kept = savedStats.refines + savedStats.coarsens + savedStats.splits + savedStats.merges;
      s.cut.restore(saved);
      s.recount();
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
  }

  // The drawn cut; the floors already satisfy the stitching constraint unless a node would need
  // a resolution above its maxResLog2 (then enforceStitchConstraint splits it, reported as
  // constraintSplits, and groups elsewhere merge back into the node budget).
  s.out = s.drawnCut();
  AdaptStats as;
  enforceStitchConstraint(h_, s.out, &view, 1.0, &as);
  st.constraintSplits = as.constraintSplits;
  st.constraintRaises += as.constraintRaises;
  if (as.constraintSplits > 0) {
    holdNodeBudget(h_, s.out, view, s.opt.maxNodes);
    fitTriangleBudget(h_, s.out, view, options.maxTriangles);
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
  for (CutNode& n : s.out.nodes) {
    n.errorPx = float(screenError(h_, n.id, n.resLog2, view));
    st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
    sum += n.errorPx;
  }
  st.meanErrorPx = s.out.nodes.empty() ? 0.0 : sum / double(s.out.nodes.size());
  if (stats) *stats = st;
  return s.out;
}

}  // namespace gimlod::reference

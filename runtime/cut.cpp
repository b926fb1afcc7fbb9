#include "runtime/cut.h"

#include <algorithm>

namespace gimlod {
namespace {

// Along-side coordinate (increasing u for bottom/top, v for left/right) to the counter-clockwise
// edge parameter, and back (an involution).
uint32_t alongToCcw(uint32_t side, uint32_t t, uint32_t size) {
  return (side == kEdgeBottom || side == kEdgeRight) ? t : size - t;
}

bool chartEdgeReversed(const Hierarchy& h, const NodeId& n, uint32_t side, uint32_t adjSide) {
  const uint32_t last = (1u << n.level) - 1;
  const bool onEdge = (side == kEdgeBottom && n.y == 0) || (side == kEdgeTop && n.y == last) ||
                      (side == kEdgeLeft && n.x == 0) || (side == kEdgeRight && n.x == last);
  if (!onEdge) return true;  // inside a chart the two sides run opposite counter-clockwise
  return h.roots[n.chart][side].reversed;
}

// Side `side` of node n of h, whose neighbours drawn in `cut` are sought.
struct CutSide {
  const Hierarchy& h;
  const Cut& cut;
  const NodeId& n;
  uint32_t side;
};

// The nodes of the cut at or below node a (the node adjacent to n across the side, or a descendant
// of it) that touch a's side aSide, appended to out with the span of n's side each covers.
void collectFiner(const CutSide& s, const NodeId& a, uint32_t aSide, std::vector<SideNeighbour>& out) {
  const Hierarchy& h = s.h;
  const NodeId& n = s.n;
  const uint32_t side = s.side;
  if (a.level >= h.params.depth) return;
  const int32_t i = s.cut.find(a);
  if (i >= 0) {
    // Span of a along aSide relative to the same-level adjacent node's origin, mapped to n.
    const uint32_t L = h.params.intervalsLog2;
    const uint32_t nSize = 1u << (L - n.level);
    const uint32_t d = a.level - n.level;
    const uint32_t along = (aSide == kEdgeBottom || aSide == kEdgeTop) ? a.x : a.y;
    const uint32_t aSize = 1u << (L - a.level);
    const uint32_t o = (along & ((1u << d) - 1)) * aSize;
    const uint32_t m0 = mapAlongSide(h, n, side, aSide, o, nSize);
    const uint32_t m1 = mapAlongSide(h, n, side, aSide, o + aSize, nSize);
    out.push_back({uint32_t(i), std::min(m0, m1), std::max(m0, m1), aSide});
    return;
  }
  // Children of a touching aSide.
  for (uint32_t c = 0; c < 4; ++c) {
    const uint32_t cx = c & 1, cy = c >> 1;
    const bool touches = (aSide == kEdgeBottom && cy == 0) || (aSide == kEdgeTop && cy == 1) ||
                         (aSide == kEdgeLeft && cx == 0) || (aSide == kEdgeRight && cx == 1);
    if (touches) collectFiner(s, a.child(c), aSide, out);
  }
}

}  // namespace

void NodeKeyIndex::reset(size_t count) {
  size_t cap = 16;
  shift_ = 60;
  while (cap < 2 * count) cap *= 2, --shift_;
  slots_.assign(cap, Slot{});
  mask_ = cap - 1;
  size_ = 0;
}

void NodeKeyIndex::insert(uint64_t key, uint32_t value) {
  for (size_t i = hash(key);; i = (i + 1) & mask_) {
    Slot& s = slots_[i];
    if (s.key == kEmpty) {
      s = {key, value};
      ++size_;
      return;
    }
    if (s.key == key) {  // duplicate node in a cut: keep the last position, as a map would
      s.value = value;
      return;
    }
  }
}

void Cut::rebuildIndex() {
  index.reset(nodes.size());
  for (uint32_t i = 0; i < nodes.size(); ++i) index.insert(nodes[i].id.key(), i);
}

uint64_t Cut::triangles() const {
  uint64_t t = 0;
  for (const CutNode& n : nodes) t += 2ull << (2 * n.resLog2);
  return t;
}

uint32_t Cut::nodeCount() const {
  int32_t last = -1;
  for (const CutNode& n : nodes) last = std::max(last, n.group);
  std::vector<uint8_t> seen(size_t(last + 1), 0);
  uint32_t count = 0;
  for (const CutNode& n : nodes) {
    if (n.group < 0) {
      ++count;
    } else if (!seen[size_t(n.group)]) {
      seen[size_t(n.group)] = 1;
      ++count;
    }
  }
  return count;
}

bool adjacentNode(const Hierarchy& h, const NodeId& n, uint32_t side, NodeId* adj, uint32_t* adjSide) {
  const int32_t last = (1 << n.level) - 1;
  int32_t x = int32_t(n.x), y = int32_t(n.y);
  switch (side) {
    case kEdgeBottom: --y; break;
    case kEdgeRight: ++x; break;
    case kEdgeTop: ++y; break;
    default: --x; break;
  }
  if (x >= 0 && y >= 0 && x <= last && y <= last) {
    *adj = {n.chart, n.level, uint32_t(x), uint32_t(y)};
    *adjSide = (side + 2) % 4;
    return true;
  }
  const RootNeighbour& r = h.roots[n.chart][side];
  if (r.chart < 0) return false;
  const uint32_t count = 1u << n.level;
  const uint32_t along = (side == kEdgeBottom || side == kEdgeTop) ? n.x : n.y;
  // Index of n along its chart edge, counter-clockwise, then along the neighbour's edge.
  uint32_t ccw = (side == kEdgeBottom || side == kEdgeRight) ? along : count - 1 - along;
  if (r.reversed) ccw = count - 1 - ccw;
  const uint32_t a = (r.edge == kEdgeBottom || r.edge == kEdgeRight) ? ccw : count - 1 - ccw;
  NodeId o{uint32_t(r.chart), n.level, 0, 0};
  switch (r.edge) {
    case kEdgeBottom:
      o.x = a;
      o.y = 0;
      break;
    case kEdgeRight:
      o.x = count - 1;
      o.y = a;
      break;
    case kEdgeTop:
      o.x = a;
      o.y = count - 1;
      break;
    default:
      o.x = 0;
      o.y = a;
      break;
  }
  *adj = o;
  *adjSide = r.edge;
  return true;
}

uint32_t mapAlongSide(const Hierarchy& h, const NodeId& n, uint32_t side, uint32_t adjSide, uint32_t t, uint32_t size) {
  uint32_t ccw = alongToCcw(adjSide, t, size);
  if (chartEdgeReversed(h, n, side, adjSide)) ccw = size - ccw;
  return alongToCcw(side, ccw, size);
}

void sideNeighbours(const Hierarchy& h, const Cut& cut, const NodeId& n, uint32_t side,
                    std::vector<SideNeighbour>& out) {
  NodeId adj;
  uint32_t adjSide;
  if (!adjacentNode(h, n, side, &adj, &adjSide)) return;
  const uint32_t nSize = 1u << (h.params.intervalsLog2 - n.level);
  // Equal or coarser: adj or one of its ancestors is in the cut.
  for (NodeId a = adj;; a = a.parent()) {
    const int32_t i = cut.find(a);
    if (i >= 0) {
      out.push_back({uint32_t(i), 0, nSize, adjSide});
      return;
    }
    if (a.level == 0) break;
  }
  collectFiner({h, cut, n, side}, adj, adjSide, out);
}

}  // namespace gimlod

// The active cut: the set of drawn nodes with their resolutions, and neighbour queries across
// node and chart borders. Pure C++.
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "hierarchy/hierarchy.h"

namespace gimlod {

struct CutNode {
  NodeId id;
  uint32_t res = 0;      // drawn resolution, log2 intervals
  float errorPx = 0.f;   // projected error at `res` for the view it was adapted to
};

struct Cut {
  std::vector<CutNode> nodes;
  std::unordered_map<uint64_t, uint32_t> index;  // NodeId::key() -> position in nodes

  void rebuildIndex();
  // Position of node n in `nodes`, or -1.
  int32_t find(const NodeId& n) const {
    auto it = index.find(n.key());
    return it == index.end() ? -1 : int32_t(it->second);
  }
  uint64_t triangles() const;
};

// A neighbour drawn across one side of a node, with the span of that side it covers, in the
// node's local level-0 coordinates along +u (bottom/top) or +v (left/right).
struct SideNeighbour {
  uint32_t cutIndex = 0;
  uint32_t t0 = 0, t1 = 0;  // t0 < t1
  uint32_t theirSide = 0;
};

// Finds the cut nodes across side `side` of node n (same chart or through the root neighbours).
// Appends to out. Works for coarser, equal and finer neighbours.
void sideNeighbours(const Hierarchy& h, const Cut& cut, const NodeId& n, uint32_t side,
                    std::vector<SideNeighbour>& out);

// The node of the same level adjacent across `side`, and the side of it that faces n; false at
// an open border.
bool adjacentNode(const Hierarchy& h, const NodeId& n, uint32_t side, NodeId* adj,
                  uint32_t* adjSide);

// Maps an along-side coordinate of adj's side `adjSide` (in [0, size]) to n's side `side`.
uint32_t mapAlongSide(const Hierarchy& h, const NodeId& n, uint32_t side, uint32_t adjSide,
                      uint32_t t, uint32_t size);

}  // namespace gimlod

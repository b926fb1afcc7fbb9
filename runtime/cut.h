// The active cut: the set of drawn nodes with their resolutions, and neighbour queries across
// node and chart borders. Pure C++.
#pragma once

#include <cstdint>
#include <vector>

#include "hierarchy/hierarchy.h"

namespace gimlod {

struct CutNode {
  NodeId id;
  uint32_t resLog2 = 0;  // drawn resolution, log2 intervals
  float errorPx = 0.f;   // projected error at `res` for the view it was adapted to
  // Attribute (normal, colour) texture resolution, log2 texels per side (assignAttributeResolutions);
  // 0 means unassigned: the page's own resolution.
  uint32_t texRes = 0;
  // How far the attributes go on towards texRes - 1, in [0, 1): the screen's need lies between the
  // two, so the normals and colours blend between mips as the view moves rather than switch.
  float texBlend = 0.f;
  // The closed group (hierarchy/root_groups.h) this chart root is drawn for, or -1: the roots of
  // one closed group are one node of the cut (nodeCount).
  int32_t group = -1;
  // Geomorph: how far the node's inner vertices move onto the surface of its next coarser
  // resolution, in [0, 1] (0: as sampled; 1: on the coarser grid's triangles). Its border does not
  // move, so borders stay stitched whatever the factors.
  float morph = 0.f;
};

// Open-addressing map from NodeId::key() to a position (linear probing, load <= 1/2): the cut is
// rebuilt and queried every frame, so lookups must cost a few nanoseconds.
class NodeKeyIndex {
 public:
  // Forgets every entry and sizes the table for `count` keys.
  void reset(size_t count);
  // Adds key -> value; the key must not be present.
  void insert(uint64_t key, uint32_t value);
  // The value of key, or -1.
  int32_t find(uint64_t key) const {
    if (slots_.empty()) return -1;
    for (size_t i = hash(key);; i = (i + 1) & mask_) {
      const Slot& s = slots_[i];
      if (s.key == key) return int32_t(s.value);
      if (s.key == kEmpty) return -1;
    }
  }
  size_t size() const { return size_; }

 private:
  static constexpr uint64_t kEmpty = ~0ull;  // never a valid key (chart ids stay below 2^24)
  struct Slot {
    uint64_t key = kEmpty;
    uint32_t value = 0;
  };
  // Fibonacci hashing: the top bits of the product depend on every bit of the key.
  size_t hash(uint64_t k) const { return size_t((k * 0x9E3779B97F4A7C15ull) >> shift_); }
  std::vector<Slot> slots_;
  size_t mask_ = 0, size_ = 0;
  uint32_t shift_ = 60;
};

struct Cut {
  std::vector<CutNode> nodes;
  NodeKeyIndex index;  // NodeId::key() -> position in nodes

  void rebuildIndex();
  // Position of node n in `nodes`, or -1.
  int32_t find(const NodeId& n) const { return index.find(n.key()); }
  uint64_t triangles() const;
  // Nodes of the cut as a node budget counts them: each node, except that the roots of one closed
  // group count once together.
  uint32_t nodeCount() const;
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
bool adjacentNode(const Hierarchy& h, const NodeId& n, uint32_t side, NodeId* adj, uint32_t* adjSide);

// Maps an along-side coordinate of adj's side `adjSide` (in [0, size]) to n's side `side`.
uint32_t mapAlongSide(const Hierarchy& h, const NodeId& n, uint32_t side, uint32_t adjSide, uint32_t t, uint32_t size);

}  // namespace gimlod

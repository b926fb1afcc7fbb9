// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.4 (border stitching).
#include "runtime/stitch.h"

#include <algorithm>
#include <array>
#include <cstring>

namespace gimlod {
namespace {

using Bits = std::array<uint32_t, 3>;

Bits bitsOf(const glm::vec3& p) {
  Bits b;
  std::memcpy(b.data(), &p, sizeof(b));
  return b;
}

// Positions of the vertices on side s of a (2^res + 1)^2 grid.
void sideVertices(const std::vector<glm::vec3>& v, uint32_t res, uint32_t s, std::vector<Bits>& out) {
  const uint32_t n = 1u << res, w = n + 1;
  for (uint32_t k = 0; k <= n; ++k) {
    uint32_t i = 0, j = 0;
    switch (s) {
      case kEdgeBottom:
        i = k;
        j = 0;
        break;
      case kEdgeRight:
        i = n;
        j = k;
        break;
      case kEdgeTop:
        i = k;
        j = n;
        break;
      default:
        i = 0;
        j = k;
        break;
    }
    out.push_back(bitsOf(v[size_t(j) * w + i]));
  }
}

}  // namespace

StitchTables buildStitchTables(const Hierarchy& h, const Cut& cut) {
  StitchTables t;
  const uint32_t L = h.params.intervalsLog2;
  t.leafLog2 = L - (h.params.depth - 1);
  t.entriesPerSide = 1u << (h.params.depth - 1);
  t.bytes.assign(cut.nodes.size() * 4 * t.entriesPerSide, 0);
  const uint32_t minRes = h.params.minNodeResLog2;
  const bool morphs =
      std::any_of(cut.nodes.begin(), cut.nodes.end(), [&](const CutNode& n) { return morphByte(n, minRes) != 0; });
  if (morphs) t.morphs.assign(t.bytes.size(), 0);
  std::vector<SideNeighbour> ns;
  for (size_t i = 0; i < cut.nodes.size(); ++i) {
    for (uint32_t s = 0; s < 4; ++s) {
      ns.clear();
      sideNeighbours(h, cut, cut.nodes[i].id, s, ns);
      uint8_t* side = t.side(i, s);
      uint8_t* m = morphs ? t.morphs.data() + (side - t.bytes.data()) : nullptr;
      const uint32_t ownSpacing = L - cut.nodes[i].id.level - cut.nodes[i].resLog2;
      // Where nothing is drawn across, the node's own factor (the shader's rules then give it).
      if (m) std::fill(m, m + t.entriesPerSide, morphByte(cut.nodes[i], minRes));
      for (const SideNeighbour& n : ns) {
        const CutNode& nb = cut.nodes[n.cutIndex];
        const uint8_t spacing = uint8_t(L - nb.id.level - nb.resLog2);
        const uint32_t e0 = n.t0 >> t.leafLog2;
        const uint32_t e1 = std::min(n.t1 >> t.leafLog2, t.entriesPerSide);
        for (uint32_t e = e0; e < e1; ++e) side[e] = spacing;
        if (!m) continue;
        // A coarser or alike neighbour: its factor. A finer one: a cap on the node's own, 0 where
        // the neighbour's side is no longer than the node's vertex spacing (its corners may then be
        // odd vertices of the node's lattice, and a node's corners never move), else none.
        const uint8_t value = spacing >= ownSpacing           ? morphByte(nb, minRes)
                              : L - nb.id.level <= ownSpacing ? uint8_t(0)
                                                              : uint8_t(255);
        std::fill(m + e0, m + std::max(e0, e1), value);
      }
    }
  }
  return t;
}

CrackReport countCracks(const Hierarchy& h, const Cut& cut, const std::vector<std::vector<glm::vec3>>& vertices) {
  CrackReport r;
  std::vector<SideNeighbour> ns;
  std::vector<Bits> mine, theirs;
  for (size_t i = 0; i < cut.nodes.size(); ++i) {
    for (uint32_t s = 0; s < 4; ++s) {
      ns.clear();
      sideNeighbours(h, cut, cut.nodes[i].id, s, ns);
      if (ns.empty()) continue;
      ++r.sharedSides;
      mine.clear();
      theirs.clear();
      const uint32_t res = cut.nodes[i].resLog2;
      sideVertices(vertices[i], res, s, mine);
      for (const SideNeighbour& n : ns)
        sideVertices(vertices[n.cutIndex], cut.nodes[n.cutIndex].resLog2, n.theirSide, theirs);
      std::sort(theirs.begin(), theirs.end());
      // Only the part of the side that a drawn neighbour covers is shared (the rest may face a
      // culled or empty region, where nothing is drawn to crack against).
      const uint32_t step = 1u << (h.params.intervalsLog2 - cut.nodes[i].id.level - res);
      for (uint32_t k = 0; k < mine.size(); ++k) {
        const uint32_t t = k * step;
        const bool shared =
            std::any_of(ns.begin(), ns.end(), [&](const SideNeighbour& n) { return t >= n.t0 && t <= n.t1; });
        if (!shared) continue;
        ++r.borderVertices;
        if (!std::binary_search(theirs.begin(), theirs.end(), mine[k])) ++r.mismatches;
      }
    }
  }
  return r;
}

}  // namespace gimlod

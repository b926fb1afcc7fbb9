// What runtime core hands to the GL renderer each frame: one record per drawn node plus the
// per-node border stitching tables. Pure C++; no GL.
#pragma once

#include <cstdint>
#include <vector>

#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"
#include "runtime/cut.h"

namespace gimlod {

// One node to draw. All coordinates are in level-0 sample units of the atlas's global grid (each
// chart at its gridX, gridY).
// The node covers [originX, originX + 2^sizeLog2] x [originY, originY + 2^sizeLog2] (closed).
struct DrawNode {
  int32_t originX = 0, originY = 0;
  uint32_t sizeLog2 = 0;     // node side in level-0 intervals
  uint32_t resLog2 = 0;      // drawn grid: 2^res intervals per side, (2^res + 1)^2 vertices
  uint32_t pageResLog2 = 0;  // page data holds 2^pageResLog2 intervals per side (res <= this)
  uint32_t pageLayer = 0;    // page of the GPU page pool holding this node's data (the renderer's
                             // texture array pageLayer / L, layer pageLayer % L)
  // Mip level of the page's normal map the fragment shader samples: pageResLog2 minus the node's
  // attribute resolution when that is coarser (0: the page's full resolution).
  uint32_t texLod = 0;
  uint32_t texLodFrac = 0;  // CutNode::texBlend in 1/255 steps: the shader samples mip texLod + this
  uint32_t morph = 0;       // CutNode::morph in 1/255 steps (0..255)
};

// Border stitching tables, as in paper section 7.4. For every node and each side
// (0 bottom v=0, 1 right u=max, 2 top v=max, 3 left u=0) there are entriesPerSide bytes. Entry j
// covers the side's level-0 positions t in [j << leafLog2, (j+1) << leafLog2), t measured from
// the node origin along +u (bottom/top) or +v (left/right). Each entry is the log2 vertex
// spacing, in level-0 intervals, of the neighbour drawn there, or 0 where there is no neighbour.
// A border vertex at t whose own spacing is finer snaps to (t >> s) << s with s that entry.
// morphs, laid out as bytes, holds the neighbour's geomorph byte there (morphByte), so that both
// sides of a border move its vertices alike (empty: no border moves).
struct StitchTables {
  uint32_t leafLog2 = 0;        // log2 of a leaf node's side in level-0 intervals
  uint32_t entriesPerSide = 1;  // 2^(depth - 1)
  std::vector<uint8_t> bytes;   // nodes * 4 * entriesPerSide
  std::vector<uint8_t> morphs;  // as bytes, or empty
  uint8_t* side(size_t node, uint32_t s) { return bytes.data() + (node * 4 + s) * entriesPerSide; }
  const uint8_t* side(size_t node, uint32_t s) const { return bytes.data() + (node * 4 + s) * entriesPerSide; }
};

// A cut node's geomorph factor in 1/255 steps (DrawNode::morph): 0 at the coarsest resolution,
// which has none coarser to move onto.
uint8_t morphByte(const CutNode& n, uint32_t minNodeResLog2);

// The draw record of a cut node whose page is in `layer`. pageResLog2: the page there holds the
// node at this resolution (a root's stand-in) rather than at the finest its level may use, when
// that is coarser; n.resLog2 must not be above it.
DrawNode makeDrawNode(const AtlasManifest& m, const HierarchyParams& p, const CutNode& n, uint32_t layer,
                      uint32_t pageResLog2 = ~0u);

}  // namespace gimlod

#include "runtime/draw_list.h"

#include <algorithm>
#include <cmath>

namespace gimlod {

DrawNode makeDrawNode(const AtlasManifest& m, const HierarchyParams& p, const CutNode& n, uint32_t layer,
                      uint32_t pageResLog2) {
  const ChartInfo& c = m.charts[n.id.chart];
  const uint32_t L = p.intervalsLog2;
  const int32_t M = int32_t(1u << L);
  const int32_t size = int32_t(1u << (L - n.id.level));
  DrawNode d;
  d.originX = c.gridX * M + int32_t(n.id.x) * size;
  d.originY = c.gridY * M + int32_t(n.id.y) * size;
  d.sizeLog2 = L - n.id.level;
  d.resLog2 = n.resLog2;
  d.pageResLog2 = std::min(p.maxResLog2(n.id.level, c.finestLevel), pageResLog2);
  d.pageLayer = layer;
  // note: an attribute resolution above the page's is clamped to it (finer attribute pages are
  // not loaded); AttributeStats::abovePage counts those nodes.
  if (n.texRes != 0 && n.texRes < d.pageResLog2) d.texLod = d.pageResLog2 - n.texRes;
  // The blend towards the next coarser mip, while there is one below the page's.
  if (n.texRes != 0 && n.texRes <= d.pageResLog2 && n.texRes > p.minNodeResLog2)
    d.texLodFrac = uint32_t(std::lround(std::clamp(double(n.texBlend), 0.0, 1.0) * 255.0));
  d.morph = morphByte(n, p.minNodeResLog2);
  return d;
}

uint8_t morphByte(const CutNode& n, uint32_t minNodeResLog2) {
  if (n.resLog2 <= minNodeResLog2) return 0;
  return uint8_t(std::lround(std::clamp(double(n.morph), 0.0, 1.0) * 255.0));
}

}  // namespace gimlod

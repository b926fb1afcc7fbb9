#include "hierarchy/root_groups.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/glm.hpp>

#include "hierarchy/hierarchy.h"

namespace gimlod {
namespace {

// Spreads the low 21 bits of v to every third bit.
uint64_t spreadBits3(uint64_t v) {
  v &= 0x1FFFFFu;
  v = (v | v << 32) & 0x1F00000000FFFFull;
  v = (v | v << 16) & 0x1F0000FF0000FFull;
  v = (v | v << 8) & 0x100F00F00F00F00Full;
  v = (v | v << 4) & 0x10C30C30C30C30C3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

// The non-empty charts in the Morton order of their root boxes' centres, on a cube around them
// (ties by chart id).
std::vector<uint32_t> mortonOrder(const Hierarchy& h) {
  std::vector<uint32_t> charts;
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi = -lo;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    if (h.flags(root) & kNodeEmpty) continue;
    charts.push_back(c);
    const auto& b = h.bounds(root);
    const glm::dvec3 m = 0.5 * glm::dvec3(b[0] + b[3], b[1] + b[4], b[2] + b[5]);
    lo = glm::min(lo, m);
    hi = glm::max(hi, m);
  }
  // One scale for the three axes: a flat atlas (a terrain) orders by its plan, not by its heights.
  const glm::dvec3 d = hi - lo;
  const glm::dvec3 ext(std::max({d.x, d.y, d.z, 1e-30}));
  std::vector<std::pair<uint64_t, uint32_t>> keyed;
  keyed.reserve(charts.size());
  for (uint32_t c : charts) {
    const auto& b = h.bounds({c, 0, 0, 0});
    const glm::dvec3 m = 0.5 * glm::dvec3(b[0] + b[3], b[1] + b[4], b[2] + b[5]);
    const glm::dvec3 q = glm::clamp((m - lo) / ext, 0.0, 1.0) * double((1u << 21) - 1);
    const uint64_t key = spreadBits3(uint64_t(q.x)) | spreadBits3(uint64_t(q.y)) << 1 | spreadBits3(uint64_t(q.z)) << 2;
    keyed.push_back({key, c});
  }
  std::sort(keyed.begin(), keyed.end());
  for (size_t i = 0; i < keyed.size(); ++i) charts[i] = keyed[i].second;
  return charts;
}

void growBox(std::array<float, 6>& box, const std::array<float, 6>& b) {
  for (int k = 0; k < 3; ++k) {
    box[k] = std::min(box[k], b[k]);
    box[k + 3] = std::max(box[k + 3], b[k + 3]);
  }
}

constexpr std::array<float, 6> kEmptyBox{
    std::numeric_limits<float>::infinity(),  std::numeric_limits<float>::infinity(),
    std::numeric_limits<float>::infinity(),  -std::numeric_limits<float>::infinity(),
    -std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};

}  // namespace

RootGroups buildRootGroups(const Hierarchy& h, uint32_t maxRoots) {
  RootGroups out;
  if (maxRoots == 0 || h.params.depth == 0) return out;
  std::vector<uint32_t> order = mortonOrder(h);
  if (order.size() <= maxRoots) return out;
  for (uint32_t c : order)
    if (h.maxResLog2({c, 0, 0, 0}) + 1 < h.params.depth) return out;  // a root could need a split

  const uint32_t minRes = h.params.minNodeResLog2, resCount = h.params.resCount();
  out.minRes = minRes;
  out.resCount = resCount;
  auto growErrors = [&](uint32_t g, auto&& errorAt) {
    out.errors.resize(size_t(g + 1) * resCount, 0.f);
    for (uint32_t r = 0; r < resCount; ++r)
      out.errors[size_t(g) * resCount + r] = std::max(out.errors[size_t(g) * resCount + r], errorAt(minRes + r));
  };
  // First level: runs of kGroupFanout charts.
  for (uint32_t i = 0; i < order.size(); i += kGroupFanout) {
    RootGroups::Group g;
    g.begin = i;
    g.end = std::min<uint32_t>(i + kGroupFanout, uint32_t(order.size()));
    g.childBegin = g.begin;
    g.childEnd = g.end;
    g.bounds = kEmptyBox;
    for (uint32_t k = g.begin; k < g.end; ++k) {
      const NodeId root{order[k], 0, 0, 0};
      growBox(g.bounds, h.bounds(root));
      g.errorMin = std::max(g.errorMin, h.error(root, minRes));
      g.errorMax = std::max(g.errorMax, h.error(root, h.maxResLog2(root)));
      growErrors(uint32_t(out.groups.size()),
                 [&](uint32_t r) { return h.error(root, std::min(r, h.maxResLog2(root))); });
    }
    out.groups.push_back(g);
  }
  // Levels above: runs of kGroupFanout groups of the level below, until few enough.
  uint32_t levelBegin = 0, levelEnd = uint32_t(out.groups.size());
  for (uint32_t level = 1; levelEnd - levelBegin > maxRoots; ++level) {
    for (uint32_t i = levelBegin; i < levelEnd; i += kGroupFanout) {
      RootGroups::Group g;
      g.level = level;
      g.childBegin = i;
      g.childEnd = std::min(i + kGroupFanout, levelEnd);
      g.begin = out.groups[g.childBegin].begin;
      g.end = out.groups[g.childEnd - 1].end;
      g.bounds = kEmptyBox;
      const int32_t self = int32_t(out.groups.size());
      for (uint32_t k = g.childBegin; k < g.childEnd; ++k) {
        RootGroups::Group& child = out.groups[k];
        child.parent = self;
        growBox(g.bounds, child.bounds);
        g.errorMin = std::max(g.errorMin, child.errorMin);
        g.errorMax = std::max(g.errorMax, child.errorMax);
        growErrors(uint32_t(self), [&](uint32_t r) { return out.error(k, r); });
      }
      out.groups.push_back(g);
    }
    levelBegin = levelEnd;
    levelEnd = uint32_t(out.groups.size());
  }
  for (uint32_t g = levelBegin; g < levelEnd; ++g) out.tops.push_back(g);
  out.chartGroup.assign(h.chartCount(), -1);
  for (uint32_t g = 0; g < out.groups.size() && out.groups[g].level == 0; ++g)
    for (uint32_t k = out.groups[g].begin; k < out.groups[g].end; ++k) out.chartGroup[order[k]] = int32_t(g);
  out.order = std::move(order);
  return out;
}

}  // namespace gimlod

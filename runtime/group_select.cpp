#include "runtime/group_select.h"

#include <algorithm>
#include <queue>

#include "runtime/adapt_dual_queue.h"

namespace gimlod {
namespace {

bool boxVisible(const std::array<float, 6>& b, const ViewParams& v, bool cull) {
  return !cull || v.frustum.intersects({b[0], b[1], b[2]}, {b[3], b[4], b[5]});
}

double boxDistance(const std::array<float, 6>& b, const glm::dvec3& p) {
  const glm::dvec3 q = glm::clamp(p, glm::dvec3{b[0], b[1], b[2]}, glm::dvec3{b[3], b[4], b[5]});
  return glm::length(q - p);
}

struct Candidate {
  double priority;
  uint32_t group;
  bool operator<(const Candidate& o) const {
    return priority < o.priority || (priority == o.priority && group > o.group);
  }
};

}  // namespace

void selectRootGroups(const Hierarchy& h, const ViewParams& v, uint32_t maxNodes, double tolerancePx, bool cull,
                      GroupSelection& out) {
  const RootGroups& rg = h.groups;
  out.closedGroups = out.frozenRoots = out.opened = out.rootFloor = 0;
  out.active = !rg.empty() && maxNodes != 0;
  if (rg.empty()) {
    out.closedOf.clear();
    out.rootFloor = countVisibleRoots(h, v, cull);
    return;
  }
  auto visibleChildren = [&](uint32_t g) {
    uint32_t n = 0;
    const RootGroups::Group& gr = rg.groups[g];
    if (gr.level == 0) {
      for (uint32_t k = gr.begin; k < gr.end; ++k) n += nodeDrawable(h, {rg.order[k], 0, 0, 0}, v, cull);
    } else {
      for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c) n += boxVisible(rg.groups[c].bounds, v, cull);
    }
    return n;
  };
  auto scaleAt = [&](const std::array<float, 6>& b) {
    return v.pixelsPerRadian / std::max(boxDistance(b, v.eye), v.minDistance);
  };
  const bool threshold = tolerancePx > 0.0;
  // Over tolerance even at its maxRes: only a split can hold the tolerance.
  auto groupNeedsSplit = [&](uint32_t g) {
    return threshold && double(rg.groups[g].errorMax) * scaleAt(rg.groups[g].bounds) > tolerancePx;
  };
  auto chartNeedsSplit = [&](uint32_t c) {
    const NodeId root{c, 0, 0, 0};
    return double(h.error(root, h.maxRes(root))) * scaleAt(h.bounds(root)) > tolerancePx;
  };
  uint32_t count = 0;  // roots of the cut: closed groups and open charts (visible)
  for (uint32_t t : rg.tops) count += boxVisible(rg.groups[t].bounds, v, cull);
  out.rootFloor = count;
  std::vector<uint8_t> open(rg.groups.size(), out.active ? 0 : 1);
  // Opens g if the roots, plus three nodes for one split of each reserved open chart, still fit the
  // budget. reserveAll: every open chart reserves a split; else only those over tolerance at maxRes.
  uint64_t reserved = 0;  // open charts with a split reserved
  auto tryOpen = [&](uint32_t g, bool reserveAll) {
    const RootGroups::Group& gr = rg.groups[g];
    uint32_t k = 0, r = 0;
    if (gr.level == 0) {
      for (uint32_t i = gr.begin; i < gr.end; ++i) {
        const uint32_t c = rg.order[i];
        if (!nodeDrawable(h, {c, 0, 0, 0}, v, cull)) continue;
        ++k;
        r += reserveAll || chartNeedsSplit(c);
      }
    } else {
      for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c) k += boxVisible(rg.groups[c].bounds, v, cull);
    }
    if (uint64_t(count) - 1 + k + 3 * (reserved + r) > maxNodes) return false;
    count = count - 1 + k;
    reserved += r;
    open[g] = 1;
    ++out.opened;
    return true;
  };
  // Pops the queue, opening while tryOpen allows; an opened group's child groups that pass `admit`
  // join the queue.
  auto openFrom = [&](std::priority_queue<Candidate>& queue, bool reserveAll, auto&& admit, auto&& priority) {
    while (!queue.empty()) {
      const uint32_t g = queue.top().group;
      queue.pop();
      if (!tryOpen(g, reserveAll) || rg.groups[g].level == 0) continue;
      for (uint32_t c = rg.groups[g].childBegin; c < rg.groups[g].childEnd; ++c)
        if (boxVisible(rg.groups[c].bounds, v, cull) && admit(c)) queue.push({priority(c), c});
    }
  };
  if (out.active) {
    // First the groups that hold a chart over tolerance even at its maxRes, the worst first: each
    // open chart in that state keeps room for a split.
    if (threshold) {
      std::priority_queue<Candidate> queue;
      auto errorMaxPx = [&](uint32_t g) { return double(rg.groups[g].errorMax) * scaleAt(rg.groups[g].bounds); };
      for (uint32_t t : rg.tops)
        if (boxVisible(rg.groups[t].bounds, v, cull) && groupNeedsSplit(t)) queue.push({errorMaxPx(t), t});
      openFrom(queue, false, groupNeedsSplit, errorMaxPx);
    }
    // Then any group, the largest error at the minimum resolution first, while every open chart can
    // still split once: with few enough charts (4 of them and their splits within the budget) every
    // group opens, and the cut is the one the forest gives without groups.
    reserved = 0;
    for (uint32_t g = 0; g < rg.groups.size() && rg.groups[g].level == 0; ++g)
      if (open[g])
        for (uint32_t i = rg.groups[g].begin; i < rg.groups[g].end; ++i)
          reserved += nodeDrawable(h, {rg.order[i], 0, 0, 0}, v, cull);
    auto errorMinPx = [&](uint32_t g) { return double(rg.groups[g].errorMin) * scaleAt(rg.groups[g].bounds); };
    std::priority_queue<Candidate> queue;
    std::vector<uint8_t> reached(rg.groups.size(), 0);
    for (uint32_t t : rg.tops) reached[t] = 1;
    for (uint32_t g = uint32_t(rg.groups.size()); g-- > 0;) {
      if (!reached[g] || !boxVisible(rg.groups[g].bounds, v, cull)) continue;
      if (!open[g]) {
        queue.push({errorMinPx(g), g});
      } else if (rg.groups[g].level > 0) {
        for (uint32_t c = rg.groups[g].childBegin; c < rg.groups[g].childEnd; ++c) reached[c] = 1;
      }
    }
    openFrom(queue, true, [](uint32_t) { return true; }, errorMinPx);
  }
  // A group is closed when it is not open and every group above it is: top-down, groups above first.
  out.closedOf.assign(h.chartCount(), -1);
  std::vector<uint8_t> reached(rg.groups.size(), 0);
  for (uint32_t t : rg.tops) reached[t] = 1;
  for (uint32_t g = uint32_t(rg.groups.size()); g-- > 0;) {
    if (!reached[g]) continue;
    const RootGroups::Group& gr = rg.groups[g];
    if (open[g]) {
      if (gr.level > 0)
        for (uint32_t c = gr.childBegin; c < gr.childEnd; ++c) reached[c] = 1;
      continue;
    }
    uint32_t drawable = 0;
    for (uint32_t k = gr.begin; k < gr.end; ++k) {
      out.closedOf[rg.order[k]] = int32_t(g);
      drawable += nodeDrawable(h, {rg.order[k], 0, 0, 0}, v, cull);
    }
    out.frozenRoots += drawable;
    out.closedGroups += boxVisible(gr.bounds, v, cull) ? 1u : 0u;
  }
  if (!out.active) out.closedOf.clear();
}

void markGroupedRoots(const GroupSelection& s, Cut& cut) {
  for (CutNode& n : cut.nodes)
    n.group = s.frozen(n.id.chart) && n.id.level == 0 ? s.closedOf[n.id.chart] : -1;
}

}  // namespace gimlod

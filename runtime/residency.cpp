// Based on Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas" (I3D 2007), section 7.2 (data management: missing nodes draw with an ancestor).
#include "runtime/residency.h"

#include <algorithm>
#include <cassert>
#include <unordered_map>

namespace gimlod {

PageRequestPlan planPageRequests(const Hierarchy& h, const Cut& desired, const ResidentFn& resident,
                                 const std::unordered_set<uint64_t>& loaded) {
  const HierarchyParams& p = h.params;
  PageRequestPlan plan;
  for (const CutNode& n : desired.nodes) {
    if (resident(n.id.key())) continue;
    const double priority = double(p.depth - n.id.level) * 1e3 + std::min(double(n.errorPx), 999.0);
    if (!loaded.count(n.id.key())) plan.requests.push_back({n.id, priority});  // else loaded, waiting
    plan.wanted.insert(n.id.key());
    // Its missing ancestors too (coarser first by priority), so the stand-in for a missing node
    // is soon its parent rather than a far ancestor.
    for (NodeId a = n.id; a.level > 0;) {
      a = a.parent();
      if (resident(a.key())) break;
      if (!plan.wanted.insert(a.key()).second) break;
      if (!loaded.count(a.key())) plan.requests.push_back({a, double(p.depth - a.level) * 1e3 + 999.0});
    }
  }
  return plan;
}

namespace {

// One pass of substituteResident with the charts in levelCap held to levels <= their cap: the
// cut, and the charts whose root, on its stand-in, is left below its stitching gap.
struct SubstitutePass {
  ResidentCut out;
  std::vector<uint32_t> overGap;
};
SubstitutePass substituteOnce(const Hierarchy& h, const Cut& desired, const ViewParams& view,
                              const ResidentFn& resident, const RootStandIns& standIns,
                              const std::unordered_map<uint32_t, uint32_t>& levelCap) {
  const HierarchyParams& p = h.params;
  const auto isResident = [&](const NodeId& n) {
    if (!resident(n.key())) return false;
    const auto c = levelCap.find(n.chart);
    return c == levelCap.end() || n.level <= c->second;
  };
  // The finest resolution node b can be drawn at: its level's, or its stand-in's.
  const auto drawable = [&](const NodeId& b) {
    const uint32_t r = h.maxResLog2(b);
    return b.level == 0 && !standIns.empty() && !isResident(b) ? std::min<uint32_t>(r, standIns.resLog2[b.chart]) : r;
  };
  // Every missing node draws as its nearest resident ancestor (or its root's stand-in).
  // Substitutes under another substitute are dropped, so the cut stays a partition.
  std::unordered_set<uint64_t> substitutes;
  std::vector<NodeId> candidates;
  for (const CutNode& n : desired.nodes) {
    if (isResident(n.id)) continue;
    NodeId a = n.id;
    while (a.level > 0 && !isResident(a)) a = a.parent();
    assert((isResident(a) || !standIns.empty()) && "substituteResident: root pages must be resident");
    if (substitutes.insert(a.key()).second) candidates.push_back(a);
  }
  constexpr uint32_t kUnplaced = ~0u;
  std::unordered_map<uint64_t, uint32_t> outer;  // outermost substitute -> position in drawn
  for (const NodeId& a : candidates) {
    bool inner = false;
    for (NodeId b = a; b.level > 0 && !inner;) {
      b = b.parent();
      inner = substitutes.count(b.key()) != 0;
    }
    if (!inner) outer[a.key()] = kUnplaced;
  }
  SubstitutePass pass;
  ResidentCut& out = pass.out;
  Cut& drawn = out.cut;
  drawn.nodes.reserve(desired.nodes.size());
  for (const CutNode& n : desired.nodes) {
    auto it = outer.end();
    NodeId b = n.id;
    while (b.level > 0 && it == outer.end()) {
      b = b.parent();
      it = outer.find(b.key());
    }
    if (it == outer.end()) {
      drawn.nodes.push_back(n);
      if (n.id.level == 0 && !standIns.empty() && !isResident(n.id)) {  // a desired root on its stand-in
        ++out.nodesSubstituted;
        CutNode& r = drawn.nodes.back();
        r.resLog2 = std::min(r.resLog2, drawable(n.id));
        outer[n.id.key()] = uint32_t(drawn.nodes.size() - 1);  // its error is the stand-in's
      }
      continue;
    }
    ++out.nodesSubstituted;
    if (it->second == kUnplaced) {
      it->second = uint32_t(drawn.nodes.size());
      drawn.nodes.push_back({b, p.minResLog2(), 0.f});
    }
    CutNode& a = drawn.nodes[it->second];
    a.resLog2 = std::max(a.resLog2, std::min(n.resLog2, drawable(b)));
  }
  drawn.rebuildIndex();
  // Stitching constraint without splits: substitutes only coarsen the cut, so raising their
  // resolution suffices whenever log2 R >= depth - 1; a root on its stand-in only up to the
  // stand-in's (the caller holds its neighbours coarser); anything else is counted.
  if (out.nodesSubstituted > 0) {
    std::vector<uint32_t> gaps;
    stitchGaps(h, drawn, gaps);
    for (size_t i = 0; i < drawn.nodes.size(); ++i) {
      CutNode& n = drawn.nodes[i];
      const uint32_t gap = gaps[i];
      const bool standIn = n.id.level == 0 && !standIns.empty() && !isResident(n.id);
      out.rootsOnStandIns += standIn;
      if (gap <= n.resLog2) continue;
      if (gap <= drawable(n.id))
        n.resLog2 = gap;
      else if (standIn)
        pass.overGap.push_back(n.id.chart);
      else
        ++out.stitchUnfixable;
    }
    for (auto& [key, i] : outer)
      if (i != kUnplaced)
        drawn.nodes[i].errorPx = float(screenError(h, drawn.nodes[i].id, drawn.nodes[i].resLog2, view));
  }
  return pass;
}

}  // namespace

ResidentCut substituteResident(const Hierarchy& h, const Cut& desired, const ViewParams& view,
                               const ResidentFn& resident, const RootStandIns& standIns) {
  std::unordered_map<uint32_t, uint32_t> levelCap;  // chart -> the deepest level drawn there
  // Each pass caps charts beside the roots left below their gaps; caps only fall, so this ends
  // (at the latest with every chart at its roots' stand-ins' levels).
  for (;;) {
    auto [out, overGap] = substituteOnce(h, desired, view, resident, standIns, levelCap);
    bool capped = false;
    for (const uint32_t c : overGap)
      for (const RootNeighbour& nb : h.roots[c]) {
        if (nb.chart < 0) continue;
        const uint32_t cap = standIns.resLog2[c];
        auto [it, fresh] = levelCap.try_emplace(uint32_t(nb.chart), cap);
        if (!fresh && it->second <= cap) continue;
        it->second = cap;
        capped = true;
      }
    out.chartsCoarsened = uint32_t(levelCap.size());
    if (!capped) {
      out.stitchUnfixable += uint32_t(overGap.size());
      return out;
    }
  }
}

}  // namespace gimlod

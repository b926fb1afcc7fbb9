// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (traditional fixed-granularity LOD as
// the comparison point, and the simple top-down algorithm); section 7.4 (stitching constraint).
#include "runtime/baselines.h"

#include <queue>

#include "runtime/adapt_dual_queue.h"

namespace gimlod {

Cut adaptFixedGranularity(const Hierarchy& h, const ViewParams& view, double tolerancePx,
                          uint32_t maxNodes, AdaptStats* stats, bool frustumCull) {
  AdaptStats st;
  const uint32_t budget = maxNodes == 0 ? UINT32_MAX : maxNodes;
  struct Candidate {
    double errorPx;
    NodeId id;
  };
  auto byError = [](const Candidate& a, const Candidate& b) { return a.errorPx < b.errorPx; };
  std::priority_queue<Candidate, std::vector<Candidate>, decltype(byError)> queue(byError);
  auto candidate = [&](const NodeId& n) {
    return Candidate{screenError(h, n, h.params.maxRes(n.level), view), n};
  };
  std::vector<NodeId> done;
  uint32_t count = 0;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    if (!nodeDrawable(h, root, view, frustumCull)) {
      ++st.culled;
      continue;
    }
    queue.push(candidate(root));
    ++count;
  }
  while (!queue.empty()) {
    const Candidate c = queue.top();
    queue.pop();
    if (c.errorPx <= tolerancePx || c.id.level + 1 >= h.params.depth) {
      done.push_back(c.id);
      continue;
    }
    uint32_t children = 0;
    for (uint32_t i = 0; i < 4; ++i) children += nodeDrawable(h, c.id.child(i), view, frustumCull);
    if (count - 1 + children > budget) {
      st.nodeBudgetBound = true;
      done.push_back(c.id);
      continue;
    }
    ++st.splits;
    count = count - 1 + children;
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = c.id.child(i);
      if (nodeDrawable(h, ch, view, frustumCull))
        queue.push(candidate(ch));
      else
        ++st.culled;
    }
  }
  Cut cut;
  cut.nodes.reserve(done.size());
  for (const NodeId& n : done) cut.nodes.push_back({n, h.params.maxRes(n.level), 0.f});
  cut.rebuildIndex();
  enforceStitchConstraint(h, cut, &view, tolerancePx, &st);
  // Constraint splits give children their needed resolution: back to the fixed one (only raises,
  // so the constraint still holds).
  for (CutNode& n : cut.nodes) {
    n.res = h.params.maxRes(n.id.level);
    n.errorPx = float(screenError(h, n.id, n.res, view));
    st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
  }
  st.triangles = cut.triangles();
  if (stats) *stats = st;
  return cut;
}

Cut adaptTopDownGreedy(const Hierarchy& h, const ViewParams& view, double tolerancePx,
                       uint32_t maxNodes, AdaptStats* stats, bool frustumCull) {
  AdaptOptions o;
  o.tolerancePx = tolerancePx;
  o.maxNodes = maxNodes;
  o.frustumCull = frustumCull;
  return adaptErrorThreshold(h, view, o, stats);
}

}  // namespace gimlod

// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (simple top-down error-threshold
// adaptation with a node budget) and section 7.4 (stitching constraint).
#include "runtime/adapt.h"

#include <algorithm>
#include <cmath>
#include <queue>

#include "runtime/group_select.h"

namespace gimlod {
namespace {

glm::dvec3 boxLo(const std::array<float, 6>& b) { return {b[0], b[1], b[2]}; }
glm::dvec3 boxHi(const std::array<float, 6>& b) { return {b[3], b[4], b[5]}; }

double boxDistance(const std::array<float, 6>& b, const glm::dvec3& p) {
  const glm::dvec3 q = glm::clamp(p, boxLo(b), boxHi(b));
  return glm::length(q - p);
}

bool visible(const Hierarchy& h, const NodeId& n, const ViewParams& v, bool cull) {
  if (h.flags(n) & kNodeEmpty) return false;
  if (!cull) return true;
  const auto& b = h.bounds(n);
  return v.frustum.intersects(boxLo(b), boxHi(b));
}

uint64_t tris(uint32_t res) { return 2ull << (2 * res); }

struct Candidate {
  NodeId id;
  uint32_t resLog2;  // chosen resolution (clamped to maxResLog2)
  bool overTol;      // even maxResLog2 is above tolerance
  double priority;   // larger splits first
};

struct ByPriority {
  bool operator()(const Candidate& a, const Candidate& b) const { return a.priority < b.priority; }
};

}  // namespace

ViewParams makeViewParams(const Camera& c, uint32_t width, uint32_t height) {
  ViewParams v;
  v.eye = c.eye;
  const glm::dmat4 vp = projectionMatrix(c, double(width) / double(height)) * viewMatrix(c);
  v.frustum = frustumFromMatrix(vp);
  v.pixelsPerRadian = pixelsPerRadian(c, height);
  v.minDistance = std::max(c.nearPlane, 1e-6);
  return v;
}

double boxScreenError(const std::array<float, 6>& box, double error, const ViewParams& v) {
  const double d = std::max(boxDistance(box, v.eye), v.minDistance);
  return error * v.pixelsPerRadian / d;
}

double geomorphFactor(const Hierarchy& h, const CutNode& n, const ViewParams& v, double tolerancePx, double range) {
  if (n.resLog2 <= h.params.minNodeResLog2 || !(tolerancePx > 0.0) || !(range > 0.0)) return 0.0;
  const double coarser = screenError(h, n.id, n.resLog2 - 1, v);
  return std::clamp(1.0 - (coarser - tolerancePx) / (range * tolerancePx), 0.0, 1.0);
}

double screenError(const Hierarchy& h, const NodeId& n, uint32_t res, const ViewParams& v) {
  return boxScreenError(h.bounds(n), double(h.error(n, res)), v);
}

uint32_t neededResolution(const Hierarchy& h, const NodeId& n, const ViewParams& v, double tolPx) {
  const double d = std::max(boxDistance(h.bounds(n), v.eye), v.minDistance);
  const double tolWorld = tolPx * d / v.pixelsPerRadian;
  const uint32_t rmax = h.maxResLog2(n);
  for (uint32_t r = h.params.minNodeResLog2; r <= rmax; ++r)
    if (double(h.error(n, r)) <= tolWorld) return r;
  return rmax + 1;
}

Cut adaptErrorThreshold(const Hierarchy& h, const ViewParams& view, const AdaptOptions& options, AdaptStats* stats) {
  AdaptStats st;
  const double tol = options.tolerancePx;
  const AdaptView step{view, tol, options.frustumCull};
  GroupSelection groups;
  selectRootGroups(h, step, options.maxNodes, groups);
  // Every root counts as a node here; the closed groups' roots, which never split, count once a
  // group in the returned cut.
  const uint32_t chartBudget = groups.chartBudget(options.maxNodes);
  const uint32_t budget = chartBudget == 0 ? UINT32_MAX : chartBudget;

  auto makeCandidate = [&](const NodeId& n) {
    Candidate c{n, 0, false, 0.0};
    c.priority = topDownSplitPriority(h, n, step, groups.frozen(n.chart), &c.resLog2, &c.overTol);
    return c;
  };

  std::priority_queue<Candidate, std::vector<Candidate>, ByPriority> queue;
  std::vector<Candidate> done;
  uint32_t count = 0;  // drawn nodes; the visible roots after the loop below
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    if (!visible(h, root, view, options.frustumCull)) {
      ++st.culled;
      continue;
    }
    queue.push(makeCandidate(root));
    ++count;
  }
  st.rootFloor = groups.rootFloor;
  st.budgetBelowRoots = budgetBelowRoots(options.maxNodes, st.rootFloor);
  while (!queue.empty()) {
    Candidate c = queue.top();
    queue.pop();
    if (c.priority <= 0.0) {
      done.push_back(c);
      continue;
    }
    uint32_t visibleChildren = 0;
    for (uint32_t i = 0; i < 4; ++i) visibleChildren += visible(h, c.id.child(i), view, options.frustumCull);
    if (count - 1 + visibleChildren > budget) {
      if (c.overTol) st.nodeBudgetBound = true;
      done.push_back(c);
      continue;
    }
    ++st.splits;
    count = count - 1 + visibleChildren;
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId ch = c.id.child(i);
      if (visible(h, ch, view, options.frustumCull))
        queue.push(makeCandidate(ch));
      else
        ++st.culled;
    }
  }

  Cut cut;
  cut.nodes.reserve(done.size());
  for (const Candidate& c : done) {
    cut.nodes.push_back({c.id, c.resLog2, 0.f});
    // A root held in a closed group for the node budget, over tolerance even at its maxResLog2.
    if (c.overTol && groups.frozen(c.id.chart) && c.id.level + 1 < h.params.depth) st.nodeBudgetBound = true;
  }
  cut.rebuildIndex();
  enforceStitchConstraint(h, cut, &view, tol, &st);
  if (st.constraintSplits > 0) holdNodeBudget(h, cut, view, chartBudget);
  for (CutNode& n : cut.nodes) {
    n.errorPx = float(screenError(h, n.id, n.resLog2, view));
    st.maxErrorPx = std::max(st.maxErrorPx, double(n.errorPx));
  }
  markGroupedRoots(groups, cut);
  setCutCounts(cut, st);
  st.triangles = cut.triangles();
  if (stats) *stats = st;
  return cut;
}

void setCutCounts(const Cut& cut, AdaptStats& st) {
  st.nodes = cut.nodeCount();
  st.groupedRoots = 0;
  for (const CutNode& n : cut.nodes) st.groupedRoots += n.group >= 0;
  st.closedGroups = st.nodes - (uint32_t(cut.nodes.size()) - st.groupedRoots);
}

double topDownSplitPriority(const Hierarchy& h, const NodeId& n, const AdaptView& adaptView, bool held, uint32_t* res,
                            bool* overTol) {
  const ViewParams& view = adaptView.view;
  const double tolPx = adaptView.tolerancePx;
  const bool cull = adaptView.cull;
  const uint32_t rmax = h.maxResLog2(n);
  const uint32_t need = neededResolution(h, n, view, tolPx);
  const bool leaf = held || n.level + 1 >= h.params.depth;
  *overTol = need > rmax;
  *res = std::min(need, rmax);
  if (leaf) return -1.0;
  if (*overTol) return overTolerancePriority(screenError(h, n, rmax, view));  // the worst error first
  uint64_t childTris = 0;
  for (uint32_t i = 0; i < 4; ++i) {
    const NodeId ch = n.child(i);
    if (!visible(h, ch, view, cull)) continue;
    childTris += tris(std::min(neededResolution(h, ch, view, tolPx), h.maxResLog2(ch)));
  }
  return double(tris(*res)) - double(childTris);  // triangles saved by splitting
}

uint32_t countVisibleRoots(const Hierarchy& h, const ViewParams& v, bool cull) {
  uint32_t n = 0;
  for (uint32_t c = 0; c < h.chartCount(); ++c) n += visible(h, {c, 0, 0, 0}, v, cull);
  return n;
}

uint32_t finestNeighbourGap(const Hierarchy& h, const Cut& cut, uint32_t i, std::vector<SideNeighbour>& scratch) {
  uint32_t gap = 0;
  const NodeId& id = cut.nodes[i].id;
  for (uint32_t s = 0; s < 4; ++s) {
    scratch.clear();
    sideNeighbours(h, cut, id, s, scratch);
    for (const SideNeighbour& sn : scratch) {
      const uint32_t l = cut.nodes[sn.cutIndex].id.level;
      if (l > id.level) gap = std::max(gap, l - id.level);
    }
  }
  return gap;
}

void stitchGaps(const Hierarchy& h, const Cut& cut, std::vector<uint32_t>& gaps) {
  gaps.assign(cut.nodes.size(), 0);
  for (const CutNode& m : cut.nodes) {
    if (m.id.level == 0) continue;  // nothing is coarser than a root
    walkToCoarserNeighbours(h, m.id, [&](const NodeId& a, uint32_t up) {
      const int32_t i = cut.find(a);
      if (i < 0) return false;
      gaps[i] = std::max(gaps[i], up);  // 0 for an equal neighbour
      return true;
    });
  }
}

bool enforceStitchConstraint(const Hierarchy& h, Cut& cut, const ViewParams* view, double tolerancePx,
                             AdaptStats* stats) {
  std::vector<uint32_t> gaps;
  // Each pass splits the nodes that cannot reach the needed resolution; the tree is finite, so
  // this ends after at most depth passes.
  for (uint32_t pass = 0; pass <= h.params.depth; ++pass) {
    stitchGaps(h, cut, gaps);
    std::vector<uint32_t> toSplit;
    for (uint32_t i = 0; i < cut.nodes.size(); ++i) {
      CutNode& n = cut.nodes[i];
      const uint32_t gap = gaps[i];
      if (gap <= n.resLog2) continue;
      if (gap <= h.maxResLog2(n.id)) {
        n.resLog2 = gap;
        if (stats) ++stats->constraintRaises;
      } else {
        toSplit.push_back(i);
      }
    }
    if (toSplit.empty()) return true;
    std::vector<bool> remove(cut.nodes.size(), false);
    std::vector<CutNode> added;
    for (uint32_t i : toSplit) {
      remove[i] = true;
      if (stats) ++stats->constraintSplits;
      for (uint32_t c = 0; c < 4; ++c) {
        const NodeId ch = cut.nodes[i].id.child(c);
        if (h.flags(ch) & kNodeEmpty) continue;
        uint32_t r = h.params.minNodeResLog2;
        if (view) r = std::min(neededResolution(h, ch, *view, tolerancePx), h.maxResLog2(ch));
        added.push_back({ch, r, 0.f});
      }
    }
    std::vector<CutNode> kept;
    kept.reserve(cut.nodes.size() + added.size());
    for (uint32_t i = 0; i < cut.nodes.size(); ++i)
      if (!remove[i]) kept.push_back(cut.nodes[i]);
    kept.insert(kept.end(), added.begin(), added.end());
    cut.nodes.swap(kept);
    cut.rebuildIndex();
  }
  return countStitchViolations(h, cut) == 0;
}

uint32_t holdNodeBudget(const Hierarchy& h, Cut& cut, const ViewParams& view, uint32_t maxNodes) {
  struct Group {
    NodeId parent;
    uint32_t resLog2 = 0;
    double errorPx = 0.0;
  };
  std::vector<SideNeighbour> scratch;
  uint32_t merges = 0;
  while (maxNodes != 0 && cut.nodes.size() > maxNodes) {
    // The complete groups, smallest parent error first.
    std::vector<NodeId> parents;
    for (const CutNode& n : cut.nodes)
      if (n.id.level > 0) parents.push_back(n.id.parent());
    std::sort(parents.begin(), parents.end(), [](const NodeId& a, const NodeId& b) { return a.key() < b.key(); });
    parents.erase(std::unique(parents.begin(), parents.end()), parents.end());
    std::vector<Group> groups;
    for (const NodeId& p : parents) {
      uint32_t finest = 0;
      bool complete = true;
      for (uint32_t c = 0; c < 4 && complete; ++c) {
        const NodeId ch = p.child(c);
        if (h.flags(ch) & kNodeEmpty) continue;
        const int32_t i = cut.find(ch);
        complete = i >= 0;
        if (complete) finest = std::max(finest, cut.nodes[size_t(i)].resLog2);
      }
      if (!complete) continue;
      const uint32_t res = std::min(finest + 1, h.maxResLog2(p));
      groups.push_back({p, res, screenError(h, p, res, view)});
    }
    std::sort(groups.begin(), groups.end(), [](const Group& a, const Group& b) {
      return a.errorPx != b.errorPx ? a.errorPx < b.errorPx : a.parent.key() < b.parent.key();
    });
    // Merged in that order while over the budget (merging one group leaves the others complete);
    // a parent whose neighbours are too fine for its maxResLog2 gets its children back.
    bool merged = false;
    for (const Group& g : groups) {
      if (cut.nodes.size() <= maxNodes) break;
      std::vector<CutNode> children;
      std::erase_if(cut.nodes, [&](const CutNode& n) {
        const bool child = n.id.level > 0 && n.id.parent() == g.parent;
        if (child) children.push_back(n);
        return child;
      });
      cut.nodes.push_back({g.parent, g.resLog2, float(g.errorPx)});
      cut.rebuildIndex();
      const uint32_t gap = finestNeighbourGap(h, cut, uint32_t(cut.nodes.size() - 1), scratch);
      if (gap <= h.maxResLog2(g.parent)) {
        cut.nodes.back().resLog2 = std::max(g.resLog2, gap);
        cut.nodes.back().errorPx = float(screenError(h, g.parent, cut.nodes.back().resLog2, view));
        merged = true;
        ++merges;
        continue;
      }
      cut.nodes.pop_back();
      cut.nodes.insert(cut.nodes.end(), children.begin(), children.end());
      cut.rebuildIndex();
    }
    if (!merged) break;
  }
  return merges;
}

uint32_t attributeResolution(const Hierarchy& h, const NodeId& n, const ViewParams& v, double texelsPerPixel,
                             float* blend) {
  if (blend) *blend = 0.f;
  const auto& b = h.bounds(n);
  const double diag = glm::length(boxHi(b) - boxLo(b));
  const double d = std::max(boxDistance(b, v.eye), v.minDistance);
  const double texels = diag * v.pixelsPerRadian / d * texelsPerPixel;
  const uint32_t lo = h.params.minNodeResLog2, hi = h.params.intervalsLog2 - h.finestLevel(n.chart) - n.level;
  if (!(texels > double(1u << lo))) return lo;  // also NaN
  const uint32_t r = uint32_t(std::ceil(std::log2(texels)));
  const uint32_t res = std::clamp(r, lo, hi);
  // Between lo and hi the need lies in (res - 1, res]: the blend is how far it is from res.
  if (blend) *blend = res == r ? float(double(r) - std::log2(texels)) : 0.f;
  return res;
}

AttributeStats assignAttributeResolutions(const Hierarchy& h, Cut& cut, const ViewParams& v, double texelsPerPixel) {
  AttributeStats st;
  for (CutNode& n : cut.nodes) {
    n.texRes = attributeResolution(h, n.id, v, texelsPerPixel, &n.texBlend);
    const uint64_t side = (1ull << n.texRes) + 1;
    st.texels += side * side;
    const uint32_t page = h.maxResLog2(n.id);
    st.aboveGeometry += n.texRes > n.resLog2;
    st.belowPage += n.texRes < page;
    st.abovePage += n.texRes > page;
  }
  return st;
}

std::vector<uint8_t> nestedChildren(const Hierarchy& h) {
  const uint32_t per = nodesPerChart(h.params.depth);
  std::vector<uint8_t> nested(size_t(per) * h.chartCount(), 0);
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const Hierarchy::ChartNodes& cn = h.charts[c];
    for (uint32_t l = 0; l + 1 < h.params.depth; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) {
          const NodeId n{c, l, x, y};
          const auto& b = cn.bounds[nodeIndex(l, x, y)];
          bool in = true;
          for (uint32_t k = 0; k < 4 && in; ++k) {
            const NodeId ch = n.child(k);
            const uint32_t i = nodeIndex(ch.level, ch.x, ch.y);
            if (cn.flags[i] & kNodeEmpty) continue;
            const auto& cb = cn.bounds[i];
            for (int a = 0; a < 3; ++a) in = in && cb[a] >= b[a] && cb[a + 3] <= b[a + 3];
          }
          nested[size_t(c) * per + nodeIndex(l, x, y)] = uint8_t(in);
        }
  }
  return nested;
}

uint32_t countStitchViolations(const Hierarchy& h, const Cut& cut) {
  std::vector<SideNeighbour> scratch;
  uint32_t bad = 0;
  for (uint32_t i = 0; i < cut.nodes.size(); ++i)
    if (finestNeighbourGap(h, cut, i, scratch) > cut.nodes[i].resLog2) ++bad;
  return bad;
}

}  // namespace gimlod

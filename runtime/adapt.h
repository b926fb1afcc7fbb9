// View-dependent adaptation: chooses the cut (nodes) and each node's resolution.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (the simple top-down algorithm for the
// error-threshold problem with a maximum node count) and 7.4 (the stitching constraint).
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "runtime/camera.h"
#include "runtime/cut.h"

namespace gimlod {

// What the adaptation needs of a view.
struct ViewParams {
  glm::dvec3 eye{0.0};
  Frustum frustum;
  double pixelsPerRadian = 1000.0;  // viewport height / (2 tan(fovy / 2))
  double minDistance = 1e-3;        // distances below this count as this (camera inside a box)
};
ViewParams makeViewParams(const Camera& c, uint32_t width, uint32_t height);

// The view a step of the adaptation is for: the view, the screen-space error tolerated in it in
// pixels, and whether the nodes outside its frustum are culled.
struct AdaptView {
  const ViewParams& view;
  double tolerancePx = 1.0;
  bool cull = true;
};

// Projected size in pixels of a world-space error seen from the closest point of the node's
// bounds: error * pixelsPerRadian / distance.
double screenError(const Hierarchy& h, const NodeId& n, uint32_t res, const ViewParams& v);
// The same for a world-space error seen from the closest point of a box (minx, miny, minz, maxx,
// maxy, maxz): a node's bounds, or a group's above the charts.
double boxScreenError(const std::array<float, 6>& box, double error, const ViewParams& v);

// Geomorph factor of a drawn node (CutNode::morph): how far its inner vertices move onto its next
// coarser resolution, so the switch to that resolution does not pop. 0 while that resolution's
// screen error is (1 + range) times the tolerance or more, rising linearly to 1 as it comes down
// to the tolerance, where the adapter would switch to it (CDLOD morphs over a third of each
// range; range 0.5 morphs over the last third of the error's way down). 0 at the coarsest
// resolution.
double geomorphFactor(const Hierarchy& h, const CutNode& n, const ViewParams& v, double tolerancePx, double range);

// Priority tier of a node that cannot meet the tolerance even at its finest resolution: above
// every triangle-count priority, ordered by its error. note: scaled, not added: 1e30 + err would
// round every error away and tie the whole tier.
inline constexpr double kOverTolerancePriority = 1e30;
inline double overTolerancePriority(double errorPx) { return kOverTolerancePriority * (1.0 + errorPx); }

// The kept-node count from which the coherent adapters' per-frame passes run in parallel (TBB):
// below it, waking the workers costs more than the pass saves (bench_adapt on 2 cores). Their
// cuts do not depend on it, nor on the thread count.
inline constexpr uint32_t kDefaultParallelMin = 8192;

struct AdaptOptions {
  double tolerancePx = 1.0;  // screen-space error threshold in pixels; must be > 0
  uint32_t maxNodes = 4096;  // node budget; 0 means no limit
  bool frustumCull = true;
};

struct AdaptStats {
  uint32_t splits = 0;
  uint32_t constraintRaises = 0;  // resolutions raised by the stitching constraint
  uint32_t constraintSplits = 0;  // splits forced by the stitching constraint
  uint32_t culled = 0;
  bool nodeBudgetBound = false;  // some node stays above tolerance because of maxNodes
  double maxErrorPx = 0.0;
  uint64_t triangles = 0;
  // The smallest cut: the visible top groups (hierarchy/root_groups.h), or the visible chart roots
  // of an atlas without groups (countVisibleRoots). No cut has fewer nodes.
  uint32_t rootFloor = 0;
  bool budgetBelowRoots = false;  // maxNodes < rootFloor: the cut is the visible roots, over maxNodes
  uint32_t nodes = 0;             // nodes of the cut (Cut::nodeCount: a closed group's roots once)
  uint32_t closedGroups = 0;      // closed groups drawn (each a node: its chart roots, unsplit)
  uint32_t groupedRoots = 0;      // chart roots those groups draw
};

// Chart roots drawn for this view: not empty and, when cull, with bounds that meet the frustum.
// Every visible root puts at least one node in a cut, so this is the floor under any node budget.
// note: a coherent adapter's kept cut may hold a visible root's descendants whose boxes are all
// culled, and then draws nothing of that chart: fewer nodes than the floor.
uint32_t countVisibleRoots(const Hierarchy& h, const ViewParams& v, bool cull);

// Sets st.nodes, st.closedGroups and st.groupedRoots from a cut whose grouped roots are marked
// (CutNode::group).
void setCutCounts(const Cut& cut, AdaptStats& st);

// Whether a node budget (0: no limit) is below the root floor. The adapters then draw exactly the
// visible roots (no split), and report it (AdaptStats::budgetBelowRoots, BudgetStats likewise).
inline bool budgetBelowRoots(uint32_t maxNodes, uint32_t rootFloor) { return maxNodes != 0 && maxNodes < rootFloor; }

// Error-threshold adaptation: each node gets the lowest resolution within tolerance; nodes are
// split, best triangle saving first (nodes over tolerance before all others), while the node
// budget allows. Then the stitching constraint is enforced (enforceStitchConstraint). The cut has
// at most max(maxNodes, rootFloor) nodes: constraint splits (constraintSplits) merge back
// (holdNodeBudget), unless no group of siblings can.
Cut adaptErrorThreshold(const Hierarchy& h, const ViewParams& view, const AdaptOptions& options,
                        AdaptStats* stats = nullptr);

// The top-down greedy's split priority of node n (adaptErrorThreshold, paper 7.1): the triangles
// saved by drawing its visible children, each at its needed resolution, instead of n at its own;
// for a node over tolerance even at its maxResLog2, overTolerancePriority of that error (those split
// first, the worst first); -1 for a leaf or a held node (held: a closed group's root). Sets *res to
// n's needed resolution clamped to its maxResLog2, and *overTol.
double topDownSplitPriority(const Hierarchy& h, const NodeId& n, const AdaptView& view, bool held, uint32_t* res,
                            bool* overTol);

// Lowest resolution of n whose screen error is within tolerance, or maxResLog2 + 1 if none.
uint32_t neededResolution(const Hierarchy& h, const NodeId& n, const ViewParams& v, double tolPx);

// Per forest node (chart * nodesPerChart + nodeIndex): 1 when every non-empty child's bounds lie
// within the node's. Then a child of a node inside the frustum is inside too (Frustum::classify),
// and its eye distance is at least the node's and at most the node's plus the node's extent: the
// adapters bound their children's resolutions from that without the children's view data. Not so
// where a terrain's padding lies flat at the lowest height (emptyTerrainTile): such children are
// empty, and not looked at.
std::vector<uint8_t> nestedChildren(const Hierarchy& h);
// The first resolution from minRes whose error (errs[res - minRes]) is at most tolWorld, else
// maxRes: neededResolution's search, at a tolerance in world units. Never lower for a larger
// tolWorld.
inline uint32_t firstWithin(const float* errs, uint32_t minRes, uint32_t maxRes, double tolWorld) {
  for (uint32_t r = minRes; r <= maxRes; ++r)
    if (double(errs[r - minRes]) <= tolWorld) return r;
  return maxRes;
}

// The stitching constraint (paper 7.4): a node's resolution is at least the level difference to
// its finest neighbour on any side, so it has a vertex for every small neighbour's corner. Raises
// resolutions, and splits nodes whose maximum resolution is too low. Returns false when the cut
// could not be fixed (never for a valid hierarchy).
bool enforceStitchConstraint(const Hierarchy& h, Cut& cut, const ViewParams* view, double tolerancePx,
                             AdaptStats* stats = nullptr);

// The node budget held after the stitching constraint split past it: while the cut has more than
// maxNodes nodes (0: no limit), merges a complete group of sibling nodes (every child that is not
// empty) into their parent, the parent of smallest screen error first, where the parent can meet
// the constraint at its maxResLog2. The parent takes one level above its children's finest
// resolution (capped at its maxResLog2), raised to the constraint's. Best effort: stops when no group
// can merge. Returns the merges.
uint32_t holdNodeBudget(const Hierarchy& h, Cut& cut, const ViewParams& view, uint32_t maxNodes);

// Largest level difference between cut node i and a finer drawn neighbour on any of its sides:
// the lowest resolution the stitching constraint allows it. scratch is reused storage.
uint32_t finestNeighbourGap(const Hierarchy& h, const Cut& cut, uint32_t i, std::vector<SideNeighbour>& scratch);

// For each side of node m (level > 0), walks from the adjacent node of m's level (across chart
// borders too) up its ancestors, calling stop(a, m.level - a.level) until it returns true (the
// caller found its equal-or-coarser neighbour there) or the walk reaches a root or an ancestor of
// m. The core of the stitching-gap computations (stitchGaps and the adapters' dense versions).
template <typename Stop>
void walkToCoarserNeighbours(const Hierarchy& h, const NodeId& m, Stop&& stop) {
  const uint32_t last = (1u << m.level) - 1;
  for (uint32_t side = 0; side < 4; ++side) {
    NodeId a = m;
    bool inChart = true;
    switch (side) {  // inside the chart without adjacentNode's border logic
      case kEdgeBottom:
        inChart = a.y > 0;
        --a.y;
        break;
      case kEdgeRight:
        inChart = a.x < last;
        ++a.x;
        break;
      case kEdgeTop:
        inChart = a.y < last;
        ++a.y;
        break;
      default:
        inChart = a.x > 0;
        --a.x;
        break;
    }
    uint32_t aSide;
    if (!inChart && !adjacentNode(h, m, side, &a, &aSide)) continue;
    const bool sameChart = a.chart == m.chart;
    for (;; a = a.parent()) {
      const uint32_t up = m.level - a.level;
      if (sameChart && a.x == (m.x >> up) && a.y == (m.y >> up)) break;  // never in a cut with m
      if (stop(a, up) || a.level == 0) break;
    }
  }
}

// The same gaps found from the coarse side, for adapters that keep them from frame to frame and
// update only the nodes beside a change. `find(n)` gives the kept node n (anything with a `drawn`
// flag), or null when n is not kept; the kept nodes tile the non-empty area (no node with an
// ancestor).
//
// The kept node at or above node b, or null (b's area is kept finer, or is empty).
template <typename Find>
auto keptCovering(NodeId b, Find&& find) -> decltype(find(b)) {
  for (;;) {
    if (auto* e = find(b)) return e;
    if (b.level == 0) return nullptr;
    b = b.parent();
  }
}
// f(node) for every kept node inside node b (b not kept) that touches b's side `side`.
template <typename Find, typename F>
void keptAlongSide(const Hierarchy& h, const NodeId& b, uint32_t side, Find&& find, F&& f) {
  if (h.flags(b) & kNodeEmpty) return;  // nothing is kept inside an empty node
  if (auto* e = find(b)) return f(*e);
  if (b.level + 1 >= h.params.depth) return;
  static constexpr uint32_t kChildren[4][2] = {{0, 1}, {1, 3}, {2, 3}, {0, 2}};  // bottom, right, top, left
  for (uint32_t c : kChildren[side]) keptAlongSide(h, b.child(c), side, find, f);
}
// f(node) for every kept node across the sides of node n (kept or not): the coarser or equal one
// covering each same-level neighbour, or the finer ones along the shared side. Every node whose
// stitching gap can change when n joins or leaves the kept nodes.
template <typename Find, typename F>
void keptBeside(const Hierarchy& h, const NodeId& n, Find&& find, F&& f) {
  for (uint32_t side = 0; side < 4; ++side) {
    NodeId b;
    uint32_t bSide = 0;
    if (!adjacentNode(h, n, side, &b, &bSide)) continue;
    if (auto* c = keptCovering(b, find))
      f(*c);
    else
      keptAlongSide(h, b, bSide, find, f);
  }
}
// The stitching gap of a drawn kept node a (stitchGaps' value): the largest level difference to a
// finer drawn kept node across one of its sides. Such a node's walk (walkToCoarserNeighbours)
// ends at a: its same-level neighbour lies in a, whose ancestors are not kept.
template <typename Find>
uint32_t keptGap(const Hierarchy& h, const NodeId& a, Find&& find) {
  uint32_t gap = 0;
  for (uint32_t side = 0; side < 4; ++side) {
    NodeId b;
    uint32_t bSide = 0;
    if (!adjacentNode(h, a, side, &b, &bSide) || keptCovering(b, find)) continue;  // equal or coarser
    keptAlongSide(h, b, bSide, find, [&](const auto& m) {
      if (m.drawn) gap = std::max(gap, m.id.level - a.level);
    });
  }
  return gap;
}

// For every cut node, the largest level difference to a finer drawn neighbour on any side: the
// lowest resolution the stitching constraint allows it (gaps[i] == finestNeighbourGap(.., i, ..)).
// Each node finds its equal-or-coarser neighbour on each side by walking up from the adjacent
// node of its own level and raises that neighbour's gap: O(cut * depth) index lookups.
void stitchGaps(const Hierarchy& h, const Cut& cut, std::vector<uint32_t>& gaps);

// Paper 7.1 (last paragraph): the resolution of a node's attribute textures (normal and colour
// maps), chosen apart from its geometry from the projected size of its bounds and a
// pixel-to-texel ratio. Returns log2 texels per node side: the lowest that puts at least
// texelsPerPixel texels on each pixel of the bounds' projected diagonal (diagonal *
// pixelsPerRadian / distance), clamped to [minNodeResLog2, intervalsLog2 - level] (the finest
// data the pyramid holds for the node). texelsPerPixel must be > 0. blend, when given, gets how far
// the need is below that resolution, towards the next coarser, in [0, 1) (0 where clamped), so the
// attributes can be sampled between the two mips (CutNode::texBlend): continuous as the view
// moves, and across a split, whose children need one resolution less of their finer pages.
uint32_t attributeResolution(const Hierarchy& h, const NodeId& n, const ViewParams& v, double texelsPerPixel,
                             float* blend = nullptr);

struct AttributeStats {
  uint64_t texels = 0;         // sum over nodes of (2^texRes + 1)^2: attribute data the cut uses
  uint32_t aboveGeometry = 0;  // nodes whose attribute resolution is finer than their geometry
  uint32_t belowPage = 0;      // nodes sampling a coarser level than their page holds
  uint32_t abovePage = 0;      // nodes that want finer data than their page (page res is used)
};

// Sets texRes of every cut node (attributeResolution). Returns what the choice amounts to.
AttributeStats assignAttributeResolutions(const Hierarchy& h, Cut& cut, const ViewParams& v, double texelsPerPixel);

// The number of constraint violations in a cut (0 for a valid cut). For tests and checks.
uint32_t countStitchViolations(const Hierarchy& h, const Cut& cut);

}  // namespace gimlod

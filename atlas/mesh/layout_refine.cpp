// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5; Sander et al. 2001 (chart splitting).
#include "atlas/mesh/layout_refine.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include <boost/graph/adjacency_list.hpp>
#include <boost/graph/strong_components.hpp>
#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec4.hpp>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include "atlas/mesh/patch_topology.h"

namespace gimlod {
namespace {

// The triangles reached from the one inside `side`'s first edge, crossing no edge in `walls`
// (undirected keys); empty if that triangle is not in the graph's patch.
std::unordered_set<uint32_t> floodFrom(const PatchLayout& layout, const PatchGraph& g, const PatchSide& side,
                                       const std::unordered_set<uint64_t>& walls) {
  const uint32_t seed = g.triangleOf(directedEdgeKey(side.vertices[0], side.vertices[1]));
  if (seed == ~0u) return {};
  std::unordered_set<uint32_t> part{seed};
  std::vector<uint32_t> stack{seed};
  while (!stack.empty()) {
    const uint32_t t = stack.back();
    stack.pop_back();
    const auto& tri = layout.triangles[t];
    for (int c = 0; c < 3; ++c) {
      const uint32_t a = tri[c], b = tri[(c + 1) % 3];
      if (walls.contains(undirectedEdgeKey(a, b))) continue;
      const uint32_t o = g.triangleOf(directedEdgeKey(b, a));
      if (o != ~0u && part.insert(o).second) stack.push_back(o);
    }
  }
  return part;
}

// Where an old side of a split patch goes: the part (patch index) and its side index there.
struct SidePlace {
  uint32_t patch, index;
};

// Cuts patch p along `path` (corner i .. corner j, interior vertices between, interior edges).
bool splitAlong(PatchLayout& layout, uint32_t p, uint32_t i, uint32_t j, const PatchGraph& g,
                const std::vector<uint32_t>& path) {
  const Patch& patch = layout.patches[p];
  const uint32_t n = uint32_t(patch.sides.size());
  const uint32_t d = (j + n - i) % n;  // sides in the first part
  if (d < 2 || d > n - 2 || path.size() < 2) return false;
  if (path.front() != patch.sides[i].vertices.front() || path.back() != patch.sides[j].vertices.front()) {
    return false;
  }
  std::unordered_set<uint32_t> seenOnPath;
  for (size_t k = 0; k < path.size(); ++k) {
    if (!seenOnPath.insert(path[k]).second) return false;  // not simple
    if (k > 0 && k + 1 < path.size() && g.onBoundary.contains(path[k])) return false;
    if (k + 1 < path.size() && g.boundaryEdges.contains(undirectedEdgeKey(path[k], path[k + 1]))) return false;
  }
  std::unordered_set<uint64_t> cut;
  for (size_t k = 0; k + 1 < path.size(); ++k) cut.insert(undirectedEdgeKey(path[k], path[k + 1]));

  // Triangles of the first part: flood from side i's first edge, never crossing the cut.
  const std::unordered_set<uint32_t> first = floodFrom(layout, g, patch.sides[i], cut);
  if (first.empty()) return false;
  // Every side must border the part it goes to.
  for (uint32_t s = 0; s < n; ++s) {
    const PatchSide& side = patch.sides[s];
    const uint32_t t = g.triangleOf(directedEdgeKey(side.vertices[0], side.vertices[1]));
    if (t == ~0u) return false;
    const bool inFirst = (s + n - i) % n < d;
    if (first.contains(t) != inFirst) return false;
  }
  if (first.size() >= patch.triangles.size()) return false;

  Patch a, b;
  for (uint32_t t : patch.triangles) (first.contains(t) ? a : b).triangles.push_back(t);
  if (!isDisk(layout, a.triangles) || !isDisk(layout, b.triangles)) return false;

  const uint32_t q = uint32_t(layout.patches.size());
  std::vector<SidePlace> place(n);
  for (uint32_t s = 0; s < n; ++s) {
    const uint32_t offset = (s + n - i) % n;
    place[s] = offset < d ? SidePlace{p, offset} : SidePlace{q, (s + n - j) % n};
  }
  for (uint32_t k = 0; k < d; ++k) a.sides.push_back(patch.sides[(i + k) % n]);
  for (uint32_t k = 0; k < n - d; ++k) b.sides.push_back(patch.sides[(j + k) % n]);
  PatchSide cutA, cutB;
  cutA.vertices.assign(path.rbegin(), path.rend());  // corner j -> corner i
  cutB.vertices = path;                              // corner i -> corner j
  cutA.neighbourPatch = int32_t(q);
  cutA.neighbourSide = n - d;
  cutB.neighbourPatch = int32_t(p);
  cutB.neighbourSide = d;
  cutA.reversed = cutB.reversed = true;
  // Links: sides of this patch that face this patch are remapped; others are told the new place.
  for (uint32_t s = 0; s < n; ++s) {
    const PatchSide& old = patch.sides[s];
    PatchSide& moved = place[s].patch == p ? a.sides[place[s].index] : b.sides[place[s].index];
    if (old.neighbourPatch == int32_t(p)) {
      moved.neighbourPatch = int32_t(place[old.neighbourSide].patch);
      moved.neighbourSide = place[old.neighbourSide].index;
    } else if (old.neighbourPatch >= 0) {
      PatchSide& other = layout.patches[uint32_t(old.neighbourPatch)].sides[old.neighbourSide];
      other.neighbourPatch = int32_t(place[s].patch);
      other.neighbourSide = place[s].index;
    }
  }
  a.sides.push_back(std::move(cutA));
  b.sides.push_back(std::move(cutB));
  layout.patches[p] = std::move(a);
  layout.patches.push_back(std::move(b));
  return true;
}

// Where each boundary vertex of a patch sits: (side, index in the side), corners as (side, 0).
std::unordered_map<uint32_t, std::pair<uint32_t, uint32_t>> boundaryPlaces(const Patch& patch) {
  std::unordered_map<uint32_t, std::pair<uint32_t, uint32_t>> at;
  for (uint32_t s = 0; s < patch.sides.size(); ++s) {
    const auto& v = patch.sides[s].vertices;
    for (uint32_t k = 0; k + 1 < v.size(); ++k) at[v[k]] = {s, k};
  }
  return at;
}

// Side counts of the two parts if the patch is cut between boundary vertices at places a and b
// (corners inserted where there are none yet): {part from a forward to b, the other part}; {0, 0}
// if either part would have fewer than 3 sides.
std::pair<uint32_t, uint32_t> partSides(const Patch& patch, std::pair<uint32_t, uint32_t> a,
                                        std::pair<uint32_t, uint32_t> b) {
  const uint32_t n = uint32_t(patch.sides.size());
  std::vector<uint32_t> offset(n + 1, 0);
  for (uint32_t s = 0; s < n; ++s) offset[s + 1] = offset[s] + uint32_t(patch.sides[s].vertices.size()) - 1;
  const uint32_t loop = offset[n];
  const uint32_t pa = offset[a.first] + a.second, pb = offset[b.first] + b.second;
  if (pa == pb) return {0, 0};
  const uint32_t span = (pb + loop - pa) % loop;
  uint32_t inside = 0;  // corners strictly between a and b going forward
  for (uint32_t c = 0; c < n; ++c) {
    const uint32_t dc = (offset[c] + loop - pa) % loop;
    if (dc > 0 && dc < span) ++inside;
  }
  const uint32_t total = n - (a.second == 0) - (b.second == 0);  // corners other than a and b
  const uint32_t outside = total - inside;
  if (inside < 1 || outside < 1) return {0, 0};
  return {inside + 2, outside + 2};
}

}  // namespace

bool splitPatchAtCorners(PatchLayout& layout, uint32_t p, uint32_t i, uint32_t j) {
  if (p >= layout.patches.size()) return false;
  const Patch& patch = layout.patches[p];
  const uint32_t n = uint32_t(patch.sides.size());
  if (i >= n || j >= n) return false;
  const PatchGraph g = patchGraph(layout, patch);
  const uint32_t src = patch.sides[i].vertices.front(), dst = patch.sides[j].vertices.front();
  const Paths paths = shortestCuts(layout, g, src, dst);
  if (!paths.dist.contains(dst)) return false;
  std::vector<uint32_t> path{dst};
  while (path.back() != src) path.push_back(paths.prev.at(path.back()));
  std::reverse(path.begin(), path.end());  // src .. dst
  return splitAlong(layout, p, i, j, g, path);
}

bool insertCorner(PatchLayout& layout, uint32_t p, uint32_t side, uint32_t k, uint32_t maxSides) {
  if (p >= layout.patches.size() || side >= layout.patches[p].sides.size()) return false;
  const PatchSide s = layout.patches[p].sides[side];
  if (k == 0 || k + 1 >= s.vertices.size()) return false;
  if (layout.patches[p].sides.size() + 1 > maxSides) return false;
  const int32_t q = s.neighbourPatch;
  if (q == int32_t(p)) return false;
  if (q >= 0 && layout.patches[uint32_t(q)].sides.size() + 1 > maxSides) return false;

  // New index of an old side of patch x after the split of side `at` (its second half at + 1).
  auto shifted = [](uint32_t old, uint32_t at) { return old <= at ? old : old + 1; };
  const uint32_t t = s.neighbourSide;
  auto newIndex = [&](int32_t patch, uint32_t old) {
    if (patch == int32_t(p)) return shifted(old, side);
    if (patch == q) return shifted(old, t);
    return old;
  };
  // Tell the other patches about the shifted indices, and remap links between p and q.
  for (const int32_t x : {int32_t(p), q}) {
    if (x < 0) continue;
    for (uint32_t o = 0; o < layout.patches[uint32_t(x)].sides.size(); ++o) {
      if ((x == int32_t(p) && o == side) || (x == q && o == t)) continue;
      PatchSide& ps = layout.patches[uint32_t(x)].sides[o];
      if (ps.neighbourPatch < 0) continue;
      if (ps.neighbourPatch == int32_t(p) || ps.neighbourPatch == q) {
        ps.neighbourSide = newIndex(ps.neighbourPatch, ps.neighbourSide);
      } else {
        layout.patches[uint32_t(ps.neighbourPatch)].sides[ps.neighbourSide].neighbourSide = newIndex(x, o);
      }
    }
  }
  PatchSide s1 = s, s2 = s;
  s1.vertices.assign(s.vertices.begin(), s.vertices.begin() + k + 1);
  s2.vertices.assign(s.vertices.begin() + k, s.vertices.end());
  auto& ps = layout.patches[p].sides;
  if (q >= 0) {
    const PatchSide w = layout.patches[uint32_t(q)].sides[t];
    const size_t kw = s.reversed ? w.vertices.size() - 1 - k : k;
    PatchSide w1 = w, w2 = w;
    w1.vertices.assign(w.vertices.begin(), w.vertices.begin() + kw + 1);
    w2.vertices.assign(w.vertices.begin() + kw, w.vertices.end());
    // Reversed runs pair the first half of one with the second half of the other.
    const uint32_t s1Pair = s.reversed ? t + 1 : t, s2Pair = s.reversed ? t : t + 1;
    s1.neighbourSide = s1Pair;
    s2.neighbourSide = s2Pair;
    w1.neighbourSide = s.reversed ? side + 1 : side;
    w2.neighbourSide = s.reversed ? side : side + 1;
    auto& qs = layout.patches[uint32_t(q)].sides;
    qs[t] = std::move(w1);
    qs.insert(qs.begin() + t + 1, std::move(w2));
  }
  ps[side] = std::move(s1);
  ps.insert(ps.begin() + side + 1, std::move(s2));
  return true;
}

namespace {

// Of a side's vertices first..last (inner ones by default), the one nearest `fraction` of its arc
// length (0 if there is none).
uint32_t sideVertexNear(const PatchLayout& layout, const PatchSide& side, double fraction, uint32_t first = 1,
                        uint32_t last = ~0u) {
  const double target = fraction * sideLength(layout, side);
  last = std::min<uint32_t>(last, uint32_t(side.vertices.size()) - 2);
  uint32_t best = 0;
  double at = 0.0, bestGap = std::numeric_limits<double>::infinity();
  for (uint32_t k = 1; k <= last; ++k) {
    at += glm::length(layout.positions[side.vertices[k]] - layout.positions[side.vertices[k - 1]]);
    if (k >= first && std::abs(at - target) < bestGap) best = k, bestGap = std::abs(at - target);
  }
  return best;
}

// The inner vertex of a side nearest its arc-length middle (0 if it has none).
uint32_t sideMiddleVertex(const PatchLayout& layout, const PatchSide& side) {
  return sideVertexNear(layout, side, 0.5);
}

// Every corner vertex with its (patch, corner index) incidences.
std::unordered_map<uint32_t, std::vector<std::pair<uint32_t, uint32_t>>> cornerIncidences(const PatchLayout& layout) {
  std::unordered_map<uint32_t, std::vector<std::pair<uint32_t, uint32_t>>> at;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    const auto& sides = layout.patches[p].sides;
    for (uint32_t i = 0; i < sides.size(); ++i) at[sides[i].vertices.front()].push_back({p, i});
  }
  return at;
}

// Whether corner i of a patch of n sides starts spokes in the sides layout (two quads meet there).
bool spokeCorner(uint32_t n, uint32_t i) { return n >= 6 && i % 2 == 0; }

// Whether corner i of patch p is on the border (a side there is open).
bool borderCorner(const PatchLayout& layout, uint32_t p, uint32_t i) {
  const auto& sides = layout.patches[p].sides;
  const uint32_t n = uint32_t(sides.size());
  return sides[i].neighbourPatch < 0 || sides[(i + n - 1) % n].neighbourPatch < 0;
}

// Corners of two patches only, away from the border, where neither patch has spokes: one quad of
// each meets there.
bool foldedCorner(const PatchLayout& layout, const std::vector<std::pair<uint32_t, uint32_t>>& in) {
  if (in.size() != 2) return false;
  for (const auto& [p, i] : in) {
    if (borderCorner(layout, p, i) || spokeCorner(uint32_t(layout.patches[p].sides.size()), i)) return false;
  }
  return true;
}

}  // namespace

uint32_t twoQuadCorners(const PatchLayout& layout) {
  uint32_t count = 0;
  for (const auto& [v, in] : cornerIncidences(layout)) count += foldedCorner(layout, in);
  return count;
}

namespace {

// The pairings (rotated by one or not) of `patches` under which every two-patch corner starts
// spokes in one of its patches, as a 2-SAT problem: per patch of 6 or more sides, x_p = 1 rotates
// it; corner i of such a patch then starts spokes iff x_p == i % 2 (a patch of 4 sides, or one not
// in `patches`, is a constant), and each corner asks for one of its two. Solved by the strongly
// connected components of the implication graph (Aspvall, Plass, Tarjan 1979; Boost's
// strong_components). False, unchanged, if no pairing satisfies every corner that some pairing of
// `patches` can change.
bool alignSpokesExactly(PatchLayout& layout, const std::vector<uint32_t>& patches) {
  std::vector<int32_t> var(layout.patches.size(), -1);
  std::vector<uint32_t> patchOf;
  for (const uint32_t p : patches) {
    if (var[p] < 0 && layout.patches[p].sides.size() >= 6) {
      var[p] = int32_t(patchOf.size());
      patchOf.push_back(p);
    }
  }
  // Node 2v + b: x_v == b.
  boost::adjacency_list<boost::vecS, boost::vecS, boost::directedS> implies(2 * patchOf.size());
  // A literal: a node, or a constant (kTrue / kFalse).
  constexpr int64_t kTrue = -1, kFalse = -2;
  for (const auto& [v, in] : cornerIncidences(layout)) {
    if (in.size() != 2) continue;
    bool open = false;
    int64_t lit[2];
    for (int k = 0; k < 2; ++k) {
      const auto& [p, i] = in[k];
      open = open || borderCorner(layout, p, i);
      lit[k] = var[p] >= 0                                                ? int64_t(2 * var[p] + i % 2)
               : spokeCorner(uint32_t(layout.patches[p].sides.size()), i) ? kTrue
                                                                          : kFalse;
    }
    if (open || lit[0] == kTrue || lit[1] == kTrue) continue;
    if (lit[0] == kFalse && lit[1] == kFalse) continue;
    // (a or b): not a -> b, not b -> a; a constant false side leaves the unit clause (b or b).
    const int64_t a = lit[0] == kFalse ? lit[1] : lit[0], b = lit[1] == kFalse ? lit[0] : lit[1];
    boost::add_edge(size_t(a ^ 1), size_t(b), implies);
    boost::add_edge(size_t(b ^ 1), size_t(a), implies);
  }
  // Tarjan's algorithm numbers the components in reverse topological order.
  std::vector<int> comp(2 * patchOf.size());
  boost::strong_components(implies,
                           boost::make_iterator_property_map(comp.begin(), boost::get(boost::vertex_index, implies)));
  for (size_t v = 0; v < patchOf.size(); ++v) {
    if (comp[2 * v] == comp[2 * v + 1]) return false;
  }
  // x_v = 1 where its "true" node comes first in topological order (a lower Tarjan number).
  for (size_t v = 0; v < patchOf.size(); ++v) {
    if (comp[2 * v + 1] < comp[2 * v]) rotatePatchSides(layout, patchOf[v], 1);
  }
  return true;
}

}  // namespace

uint32_t alignSpokes(PatchLayout& layout, const std::vector<uint32_t>& only) {
  std::vector<uint32_t> patches = only;
  if (only.empty()) {
    for (uint32_t p = 0; p < layout.patches.size(); ++p) patches.push_back(p);
  }
  if (alignSpokesExactly(layout, patches)) return twoQuadCorners(layout);
  // Otherwise each patch of 6 or more sides takes the pairing under which more of its two-patch
  // corners start spokes (those the other patch leaves without), in two passes.
  for (int pass = 0; pass < 2; ++pass) {
    const auto at = cornerIncidences(layout);
    for (const uint32_t p : patches) {
      const uint32_t n = uint32_t(layout.patches[p].sides.size());
      if (n < 6) continue;
      int score[2] = {0, 0};
      for (uint32_t i = 0; i < n; ++i) {
        const auto& in = at.at(layout.patches[p].sides[i].vertices.front());
        if (in.size() != 2) continue;
        const auto& other = in[0].first == p && in[0].second == i ? in[1] : in[0];
        if (other.first == p) continue;
        const uint32_t on = uint32_t(layout.patches[other.first].sides.size());
        if (spokeCorner(on, other.second)) continue;  // the other patch has spokes there
        ++score[i % 2];
      }
      if (score[1] > score[0]) rotatePatchSides(layout, p, 1);
    }
  }
  return twoQuadCorners(layout);
}

MendCornersResult mendTwoChartCorners(PatchLayout& layout, uint32_t maxSides) {
  MendCornersResult r;
  uint32_t& left = r.left;
  left = alignSpokes(layout);
  // Each try is judged on the whole layout after alignSpokes: kept only if fewer corners are left.
  for (uint32_t round = 0; round < 8 && left > 0; ++round) {
    bool changed = false;
    for (const auto& [x, in] : cornerIncidences(layout)) {
      if (!foldedCorner(layout, in)) continue;
      for (const auto& [p, i] : in) {
        const std::vector<Patch> saved = layout.patches;
        const uint32_t n = uint32_t(layout.patches[p].sides.size());
        const uint32_t before = (i + n - 1) % n;
        bool ok = true;
        for (const uint32_t side : {std::max(i, before), std::min(i, before)}) {
          const uint32_t k = sideMiddleVertex(layout, layout.patches[p].sides[side]);
          ok = ok && k != 0 && insertCorner(layout, p, side, k, maxSides);
        }
        const uint32_t now = ok ? alignSpokes(layout) : left;
        if (now < left) {
          left = now;
          r.corners += 2;
          changed = true;
          break;
        }
        layout.patches = saved;
      }
      if (changed) break;  // the incidences changed
    }
    if (!changed) break;
  }
  return r;
}

bool rotationFoldsNoCorner(PatchLayout& layout, uint32_t p) {
  auto foldedAtP = [&] {
    const auto at = cornerIncidences(layout);
    uint32_t folded = 0;
    for (const PatchSide& side : layout.patches[p].sides) folded += foldedCorner(layout, at.at(side.vertices.front()));
    return folded;
  };
  const uint32_t before = foldedAtP();
  rotatePatchSides(layout, p, 1);
  const uint32_t after = foldedAtP();
  rotatePatchSides(layout, p, uint32_t(layout.patches[p].sides.size()) - 1);
  return after <= before;
}

void rotatePatchSides(PatchLayout& layout, uint32_t p, uint32_t k) {
  Patch& patch = layout.patches.at(p);
  const uint32_t n = uint32_t(patch.sides.size());
  if (n == 0 || k % n == 0) return;
  auto moved = [&](uint32_t old) { return (old + n - k % n) % n; };  // new index of old side
  for (uint32_t i = 0; i < n; ++i) {
    PatchSide& side = patch.sides[i];
    if (side.neighbourPatch < 0) continue;
    if (uint32_t(side.neighbourPatch) == p) {
      side.neighbourSide = moved(side.neighbourSide);
    } else {
      layout.patches[uint32_t(side.neighbourPatch)].sides[side.neighbourSide].neighbourSide = moved(i);
    }
  }
  std::rotate(patch.sides.begin(), patch.sides.begin() + k % n, patch.sides.end());
}

uint32_t splitTwoSidedHoles(PatchLayout& layout, uint32_t maxSides) {
  struct SideAt {
    uint32_t patch, side;
  };
  // The open side starting at each boundary vertex (one per vertex on a manifold boundary).
  std::unordered_map<uint32_t, SideAt> startingAt;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (uint32_t i = 0; i < layout.patches[p].sides.size(); ++i) {
      const PatchSide& s = layout.patches[p].sides[i];
      if (s.neighbourPatch < 0) startingAt.emplace(s.vertices.front(), SideAt{p, i});
    }
  }
  auto sideOf = [&](const SideAt& at) -> const PatchSide& { return layout.patches[at.patch].sides[at.side]; };
  // The holes of at most two sides, each as its longest side's patch and start vertex (found
  // before any change, since the corners made renumber the sides).
  std::vector<std::pair<uint32_t, uint32_t>> holes;
  std::unordered_set<uint32_t> seen;
  for (const auto& [start, first] : startingAt) {
    if (seen.contains(start)) continue;
    std::vector<SideAt> loop;
    for (SideAt at = first;;) {
      loop.push_back(at);
      seen.insert(sideOf(at).vertices.front());
      const auto next = startingAt.find(sideOf(at).vertices.back());
      if (next == startingAt.end() || loop.size() > 2 || next->first == start) break;
      at = next->second;
    }
    if (loop.size() > 2) continue;
    const SideAt longest = *std::max_element(loop.begin(), loop.end(), [&](const SideAt& a, const SideAt& b) {
      return sideLength(layout, sideOf(a)) < sideLength(layout, sideOf(b));
    });
    holes.push_back({longest.patch, sideOf(longest).vertices.front()});
  }
  std::sort(holes.begin(), holes.end());  // (the map's order is not the input's)
  uint32_t corners = 0;
  for (const auto& hole : holes) {
    // note: named, not a structured binding, since the lambda below uses them (clang before 16
    // cannot capture structured bindings).
    const uint32_t p = hole.first, start = hole.second;
    const auto& sides = layout.patches[p].sides;
    const auto it = std::find_if(sides.begin(), sides.end(), [&](const PatchSide& s) {
      return s.neighbourPatch < 0 && s.vertices.front() == start;
    });
    if (it == sides.end()) continue;  // (not reached: corners made elsewhere keep its start)
    const uint32_t i = uint32_t(it - sides.begin());
    if (it->vertices.size() < 4 || sides.size() + 2 > maxSides) continue;
    // The inner vertices nearest a third and two thirds of the side's arc length, distinct.
    const uint32_t last = uint32_t(it->vertices.size()) - 1;
    const uint32_t k1 = sideVertexNear(layout, *it, 1.0 / 3.0, 1, last - 2);
    const uint32_t k2 = sideVertexNear(layout, *it, 2.0 / 3.0, k1 + 1, last - 1);
    if (!insertCorner(layout, p, i, k1, maxSides)) continue;
    if (!insertCorner(layout, p, i + 1, k2 - k1, maxSides)) {
      throw std::logic_error("splitTwoSidedHoles: the second corner of a side with room for it was refused");
    }
    corners += 2;
  }
  return corners;
}

EvenSidesResult evenSides(PatchLayout& layout, const std::vector<uint32_t>& within, uint32_t maxSides) {
  EvenSidesResult r;
  const uint32_t np = uint32_t(layout.patches.size());
  std::vector<uint8_t> allowed(np, within.empty() ? 1 : 0);
  for (uint32_t p : within) {
    if (p < np) allowed[p] = 1;
  }
  auto sidesOf = [&](uint32_t p) { return uint32_t(layout.patches[p].sides.size()); };
  auto odd = [&](uint32_t p) { return allowed[p] && sidesOf(p) % 2 == 1; };
  // The longest side of p towards `towards` (a patch, or -1: open) that can take a corner with
  // both patches gaining one within `room` more sides; -1 if none.
  auto sideTowards = [&](uint32_t p, int32_t towards, uint32_t roomP, uint32_t roomQ) {
    int32_t best = -1;
    double bestLength = -1.0;
    if (sidesOf(p) + 1 > roomP) return best;
    if (towards >= 0 &&
        (!allowed[uint32_t(towards)] || uint32_t(towards) == p || sidesOf(uint32_t(towards)) + 1 > roomQ))
      return best;
    for (uint32_t i = 0; i < sidesOf(p); ++i) {
      const PatchSide& side = layout.patches[p].sides[i];
      if (side.neighbourPatch != towards || side.vertices.size() < 3) continue;
      const double l = sideLength(layout, side);
      if (l > bestLength) best = int32_t(i), bestLength = l;
    }
    return best;
  };
  auto split = [&](uint32_t p, uint32_t i) {
    const uint32_t k = sideMiddleVertex(layout, layout.patches[p].sides[i]);
    if (k != 0 && insertCorner(layout, p, i, k, maxSides)) ++r.corners;
  };
  // Odd pairs across one side, then open sides.
  for (uint32_t p = 0; p < np; ++p) {
    if (!odd(p)) continue;
    int32_t bestSide = -1;
    double bestLength = -1.0;
    for (uint32_t i = 0; i < sidesOf(p); ++i) {
      const PatchSide& side = layout.patches[p].sides[i];
      if (side.neighbourPatch < 0 || uint32_t(side.neighbourPatch) == p || side.vertices.size() < 3) continue;
      const uint32_t q = uint32_t(side.neighbourPatch);
      // Two triangles would become two single quads meeting at the new corner, with nothing to
      // start spokes there: leave them to other pairs.
      if (!odd(q) || std::max(sidesOf(p), sidesOf(q)) < 5 || std::max(sidesOf(p), sidesOf(q)) + 1 > maxSides) continue;
      const double l = sideLength(layout, side);
      if (l > bestLength) bestSide = int32_t(i), bestLength = l;
    }
    if (bestSide >= 0) split(p, uint32_t(bestSide));
  }
  for (uint32_t p = 0; p < np; ++p) {
    if (!odd(p)) continue;
    const int32_t i = sideTowards(p, -1, maxSides, maxSides);
    if (i >= 0) split(p, uint32_t(i));
  }
  // Chains: breadth first from an odd patch through patches that can gain two corners, to an odd
  // patch or one with an open side that can take a corner.
  for (uint32_t start = 0; start < np; ++start) {
    if (!odd(start)) continue;
    std::vector<int32_t> prev(np, -2);
    std::vector<uint32_t> queue{start};
    prev[start] = -1;
    int32_t end = -1;
    bool endOpen = false;
    for (size_t at = 0; at < queue.size() && end < 0; ++at) {
      const uint32_t x = queue[at];
      // x gains one corner towards the next patch and (but for the start) one from the previous.
      const uint32_t roomX = x == start ? maxSides : maxSides - 1;
      for (const PatchSide& side : layout.patches[x].sides) {
        if (side.neighbourPatch < 0) continue;
        const uint32_t y = uint32_t(side.neighbourPatch);
        if (prev[y] != -2 || !allowed[y] || sideTowards(x, int32_t(y), roomX, maxSides) < 0) continue;
        // Two triangles paired directly would become two single quads alone at their new corner
        // (as above); y may still end a longer chain.
        if (x == start && odd(y) && std::max(sidesOf(x), sidesOf(y)) < 5) continue;
        prev[y] = int32_t(x);
        if (odd(y)) {
          end = int32_t(y);
          break;
        }
        if (sideTowards(y, -1, maxSides - 1, maxSides) >= 0) {
          end = int32_t(y);
          endOpen = true;
          break;
        }
        queue.push_back(y);
      }
    }
    if (end < 0) continue;
    if (endOpen) split(uint32_t(end), uint32_t(sideTowards(uint32_t(end), -1, maxSides, maxSides)));
    for (uint32_t y = uint32_t(end); prev[y] >= 0; y = uint32_t(prev[y])) {
      const uint32_t x = uint32_t(prev[y]);
      const int32_t i = sideTowards(x, int32_t(y), maxSides, maxSides);
      if (i >= 0) split(x, uint32_t(i));
    }
  }
  for (uint32_t p = 0; p < np; ++p) r.oddLeft += odd(p);
  return r;
}

namespace {

// Splits patch p's triangle with the directed edge a -> b at vertex m on that edge: it keeps
// a -> m, and a new triangle of p takes m -> b. False if p has no such triangle.
bool splitTriangleAtEdge(PatchLayout& layout, uint32_t p, uint32_t a, uint32_t b, uint32_t m) {
  std::vector<uint32_t>& triangles = layout.patches[p].triangles;
  for (const uint32_t t : triangles) {
    const std::array<uint32_t, 3> tri = layout.triangles[t];
    for (int c = 0; c < 3; ++c) {
      if (tri[c] != a || tri[(c + 1) % 3] != b) continue;
      const uint32_t o = tri[(c + 2) % 3];
      layout.triangles[t] = {a, m, o};
      layout.triangles.push_back({m, b, o});
      triangles.push_back(uint32_t(layout.triangles.size() - 1));
      return true;
    }
  }
  return false;
}

}  // namespace

uint32_t splitSingleEdgeSides(PatchLayout& layout, const std::vector<uint32_t>& patches) {
  uint32_t split = 0;
  for (const uint32_t p : patches) {
    if (p >= layout.patches.size()) continue;
    for (uint32_t i = 0; i < layout.patches[p].sides.size(); ++i) {
      const PatchSide& side = layout.patches[p].sides[i];
      if (side.vertices.size() != 2 || !side.reversed) continue;
      const uint32_t a = side.vertices[0], b = side.vertices[1];
      const glm::vec3 pa = layout.positions[a], pb = layout.positions[b];
      if (pa == pb) continue;
      const int32_t q = side.neighbourPatch;
      const uint32_t t = side.neighbourSide;
      const uint32_t m = uint32_t(layout.positions.size());
      layout.positions.push_back(0.5f * (pa + pb));
      if (!layout.colours.empty()) {
        const glm::vec4 mean = 0.5f * (glm::vec4(layout.colours[a]) + glm::vec4(layout.colours[b]));
        layout.colours.push_back(glm::u8vec4(glm::round(mean)));
      }
      if (!splitTriangleAtEdge(layout, p, a, b, m) || (q >= 0 && !splitTriangleAtEdge(layout, uint32_t(q), b, a, m)))
        throw std::logic_error("splitSingleEdgeSides: a side's edge has no triangle in its patch");
      auto& own = layout.patches[p].sides[i].vertices;
      own.insert(own.begin() + 1, m);
      if (q >= 0) {
        auto& across = layout.patches[uint32_t(q)].sides[t].vertices;
        across.insert(across.begin() + 1, m);
      }
      ++split;
    }
  }
  return split;
}

std::vector<uint32_t> patchesNear(const PatchLayout& layout, const std::vector<uint32_t>& from, uint32_t reach) {
  const uint32_t np = uint32_t(layout.patches.size());
  std::vector<uint32_t> depth(np, ~0u), reached;
  for (const uint32_t p : from) {
    if (p < np && depth[p] == ~0u) depth[p] = 0, reached.push_back(p);
  }
  for (size_t at = 0; at < reached.size(); ++at) {
    const uint32_t x = reached[at];
    if (depth[x] == reach) continue;
    for (const PatchSide& side : layout.patches[x].sides) {
      if (side.neighbourPatch < 0 || depth[uint32_t(side.neighbourPatch)] != ~0u) continue;
      depth[uint32_t(side.neighbourPatch)] = depth[x] + 1;
      reached.push_back(uint32_t(side.neighbourPatch));
    }
  }
  std::sort(reached.begin(), reached.end());
  return reached;
}

namespace {

// The best acceptable cut of patch p passing through one of `sources` (vertices of the patch);
// with no sources, through boundary vertices (at most 96, spread evenly): the neck. With
// minShare > 0, only cuts that leave at least that share of the border on either side count.
// Empty if none. Reads the layout only. See splitPatchThrough and splitPatchAtNeck.
std::vector<uint32_t> findCut(const PatchLayout& layout, uint32_t p, std::vector<uint32_t> sources, uint32_t maxSides,
                              double minShare = 0.0, uint32_t minPartEdges = 0) {
  if (p >= layout.patches.size()) return {};
  const Patch& patch = layout.patches[p];
  const PatchGraph g = patchGraph(layout, patch);
  const auto places = boundaryPlaces(patch);
  // Arc length of every boundary vertex from corner 0, for the parts' perimeters.
  std::unordered_map<uint32_t, double> arc;
  double perimeter = 0.0;
  for (const PatchSide& side : patch.sides) {
    for (size_t k = 0; k + 1 < side.vertices.size(); ++k) {
      arc[side.vertices[k]] = perimeter;
      perimeter += glm::length(layout.positions[side.vertices[k + 1]] - layout.positions[side.vertices[k]]);
    }
  }
  auto sidesOf = [&](uint32_t patchId) { return uint32_t(layout.patches[patchId].sides.size()); };
  // Each boundary vertex's place along the loop, for the parts' boundary edges.
  std::unordered_map<uint32_t, uint32_t> loopAt;
  for (const PatchSide& side : patch.sides) {
    for (size_t k = 0; k + 1 < side.vertices.size(); ++k) loopAt.emplace(side.vertices[k], uint32_t(loopAt.size()));
  }
  const uint32_t loopEdges = uint32_t(loopAt.size());
  // A cut between boundary vertices e1 and e2 is acceptable when both parts get 3..maxSides
  // sides and every neighbour that gains a corner stays within maxSides.
  auto acceptable = [&](uint32_t e1, uint32_t e2) {
    const auto a = places.at(e1), b = places.at(e2);
    const auto [s1, s2] = partSides(patch, a, b);
    if (s1 == 0 || s1 > maxSides || s2 > maxSides) return false;
    const uint32_t forwardEdges = (loopAt.at(e2) + loopEdges - loopAt.at(e1)) % loopEdges;
    if (std::min(forwardEdges, loopEdges - forwardEdges) < minPartEdges) return false;
    int32_t gained[2] = {-1, -1};  // neighbours gaining a corner (the same one may gain two)
    for (int e = 0; e < 2; ++e) {
      const auto& at = e == 0 ? a : b;
      if (at.second == 0) continue;
      const PatchSide& side = patch.sides[at.first];
      if (side.neighbourPatch == int32_t(p)) return false;
      gained[e] = side.neighbourPatch;
    }
    for (int e = 0; e < 2; ++e) {
      if (gained[e] < 0) continue;
      const uint32_t gain = gained[0] == gained[1] ? 2 : 1;
      if (sidesOf(uint32_t(gained[e])) + gain > maxSides) return false;
    }
    return true;
  };
  double bestScore = std::numeric_limits<double>::infinity();
  std::vector<uint32_t> best;
  auto consider = [&](std::vector<uint32_t> path, double length) {
    const uint32_t e1 = path.front(), e2 = path.back();
    if (e1 == e2 || !acceptable(e1, e2)) return;
    const double forward = std::fmod(arc.at(e2) - arc.at(e1) + perimeter, perimeter);
    if (minShare > 0.0 && std::min(forward, perimeter - forward) < minShare * perimeter) return;
    const double smaller = std::min(forward, perimeter - forward) + length;
    double score = smaller > 0.0 ? length / smaller : std::numeric_limits<double>::infinity();
    // A new corner changes the neighbour's polygon too: prefer ends at corners.
    for (const uint32_t e : {e1, e2}) {
      if (places.at(e).second != 0) score *= 1.25;
    }
    if (score < bestScore) bestScore = score, best = std::move(path);
  };
  // At most 96 boundary vertices, spread evenly along the border: the sources of a neck search,
  // and the far ends a balanced cut (minShare) may also reach besides the nearest.
  std::vector<uint32_t> spread;
  {
    std::vector<uint32_t> loop;
    for (const PatchSide& side : patch.sides) loop.insert(loop.end(), side.vertices.begin(), side.vertices.end() - 1);
    const size_t step = std::max<size_t>(1, loop.size() / 96);
    for (size_t k = 0; k < loop.size(); k += step) spread.push_back(loop[k]);
  }
  if (sources.empty()) sources = spread;
  if (!(minShare > 0.0)) spread.clear();
  for (const uint32_t v : sources) {
    // The 48 nearest boundary vertices are all the search needs (and the spread ends).
    const Paths paths = shortestCuts(layout, g, v, ~0u, spread.empty() ? 48 : std::numeric_limits<size_t>::max());
    std::vector<std::pair<double, uint32_t>> ends;  // reached boundary vertices by distance
    for (const auto& [w, dist] : paths.dist) {
      if (w != v && g.onBoundary.contains(w)) ends.push_back({dist, w});
    }
    std::sort(ends.begin(), ends.end());
    if (ends.size() > 48) {
      std::unordered_set<uint32_t> keep(spread.begin(), spread.end());
      std::vector<std::pair<double, uint32_t>> kept(ends.begin(), ends.begin() + 48);
      for (size_t k = 48; k < ends.size(); ++k) {
        if (keep.contains(ends[k].second)) kept.push_back(ends[k]);
      }
      ends = std::move(kept);
    }
    auto pathTo = [&](uint32_t w) {  // v .. w
      std::vector<uint32_t> path{w};
      while (path.back() != v) path.push_back(paths.prev.at(path.back()));
      std::reverse(path.begin(), path.end());
      return path;
    };
    if (g.onBoundary.contains(v)) {
      for (const auto& [dist, w] : ends) consider(pathTo(w), dist);
      continue;
    }
    // Interior v: two tree paths that leave v by different edges meet only at v.
    std::vector<std::vector<uint32_t>> toEnd;
    for (const auto& e : ends) toEnd.push_back(pathTo(e.second));
    for (size_t x = 0; x < ends.size(); ++x) {
      for (size_t y = x + 1; y < ends.size(); ++y) {
        if (toEnd[x][1] == toEnd[y][1]) continue;
        std::vector<uint32_t> path(toEnd[x].rbegin(), toEnd[x].rend());
        path.insert(path.end(), toEnd[y].begin() + 1, toEnd[y].end());
        consider(std::move(path), ends[x].first + ends[y].first);
      }
    }
  }
  return best;
}

// Cuts patch p along `best` (findCut's path): new corners at its ends where there are none
// (indices shift as sides split), then the cut between them. False if that fails (the patch may
// then have gained a corner, still valid).
bool applyCut(PatchLayout& layout, uint32_t p, const std::vector<uint32_t>& best, uint32_t maxSides) {
  if (best.size() < 2) return false;
  for (const uint32_t e : {best.front(), best.back()}) {
    const auto at = boundaryPlaces(layout.patches[p]).at(e);
    // The patch itself may pass maxSides until it is cut (acceptable() bounded both parts and the
    // neighbours).
    if (at.second != 0 && !insertCorner(layout, p, at.first, at.second, maxSides + 2)) return false;
  }
  const Patch& now = layout.patches[p];
  uint32_t i = ~0u, j = ~0u;
  for (uint32_t c = 0; c < now.sides.size(); ++c) {
    if (now.sides[c].vertices.front() == best.front()) i = c;
    if (now.sides[c].vertices.front() == best.back()) j = c;
  }
  if (i >= now.sides.size() || j >= now.sides.size()) return false;
  return splitAlong(layout, p, i, j, patchGraph(layout, now), best);
}

bool splitByCut(PatchLayout& layout, uint32_t p, std::vector<uint32_t> sources, uint32_t maxSides) {
  return applyCut(layout, p, findCut(layout, p, std::move(sources), maxSides), maxSides);
}

}  // namespace

// The share of the perimeter each part of a balanced cut keeps at least (halvePatch, and
// splitPatchFromDeepest, whose cut then runs down both sides of a tube).
constexpr double kBalancedCutShare = 0.25;

bool halvePatch(PatchLayout& layout, uint32_t p, uint32_t maxSides, uint32_t minPartEdges) {
  return applyCut(layout, p, findCut(layout, p, {}, maxSides, kBalancedCutShare, minPartEdges), maxSides);
}

uint32_t patchTriangleAt(const PatchLayout& layout, uint32_t p, uint32_t v) {
  for (const uint32_t t : layout.patches[p].triangles) {
    const auto& tri = layout.triangles[t];
    if (tri[0] == v || tri[1] == v || tri[2] == v) return t;
  }
  return ~0u;
}

uint32_t deepestPatchVertex(const PatchLayout& layout, uint32_t p) {
  const PatchGraph g = patchGraph(layout, layout.patches[p]);
  std::unordered_map<uint32_t, double> dist;
  using Item = std::pair<double, uint32_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
  for (const uint32_t v : g.onBoundary) {
    dist[v] = 0.0;
    queue.push({0.0, v});
  }
  uint32_t deepest = ~0u;
  double far = 0.0;
  while (!queue.empty()) {
    const auto [d, u] = queue.top();
    queue.pop();
    if (d > dist.at(u)) continue;
    if (d > far || (d == far && d > 0.0 && u < deepest)) far = d, deepest = u;
    const auto [begin, end] = g.neighboursOf(u);
    for (auto it = begin; it != end; ++it) {
      const uint32_t w = it->second;
      if (g.onBoundary.contains(w)) continue;
      const double nd = d + glm::length(layout.positions[w] - layout.positions[u]);
      const auto [at, inserted] = dist.try_emplace(w, nd);
      if (!inserted && !(nd < at->second)) continue;
      at->second = nd;
      queue.push({nd, w});
    }
  }
  return deepest;
}

bool splitPatchFromDeepest(PatchLayout& layout, uint32_t p, uint32_t maxSides) {
  if (p >= layout.patches.size()) return false;
  const uint32_t v = deepestPatchVertex(layout, p);
  if (v == ~0u) return false;
  return applyCut(layout, p, findCut(layout, p, {v}, maxSides, kBalancedCutShare), maxSides);
}

bool splitPatchThrough(PatchLayout& layout, uint32_t p, uint32_t triangle, uint32_t maxSides) {
  if (triangle >= layout.triangles.size()) return false;
  const auto& t = layout.triangles[triangle];
  return splitByCut(layout, p, {t[0], t[1], t[2]}, maxSides);
}

namespace {

// The best corner-to-corner cut (splitPatchAtNeck's fallback): no neighbour changes.
bool splitPatchAtCornerNeck(PatchLayout& layout, uint32_t p) {
  if (p >= layout.patches.size()) return false;
  if (layout.patches[p].sides.size() == 3) {
    // A fourth corner at the arc-length middle of the longest side that has an inner vertex.
    const Patch& patch = layout.patches[p];
    int best = -1;
    double bestLength = 0.0;
    for (uint32_t s = 0; s < 3; ++s) {
      const double l = sideLength(layout, patch.sides[s]);
      if (patch.sides[s].vertices.size() >= 3 && l > bestLength) best = int(s), bestLength = l;
    }
    if (best < 0) return false;
    const PatchSide& s = patch.sides[uint32_t(best)];
    double run = 0.0;
    uint32_t k = 1;
    for (; k + 2 < s.vertices.size(); ++k) {
      run += glm::length(layout.positions[s.vertices[k]] - layout.positions[s.vertices[k - 1]]);
      if (run >= 0.5 * bestLength) break;
    }
    if (!insertCorner(layout, p, uint32_t(best), k)) return false;
  }
  const Patch& patch = layout.patches[p];
  const uint32_t n = uint32_t(patch.sides.size());
  std::vector<double> lengths(n);
  double total = 0.0;
  for (uint32_t s = 0; s < n; ++s) total += lengths[s] = sideLength(layout, patch.sides[s]);
  const PatchGraph g = patchGraph(layout, patch);
  struct Candidate {
    double score;
    uint32_t i, j;
  };
  std::vector<Candidate> candidates;
  for (uint32_t i = 0; i < n; ++i) {
    const Paths paths = shortestCuts(layout, g, patch.sides[i].vertices.front());
    double perimeter = 0.0;
    for (uint32_t d = 1; d + 1 < n; ++d) {
      perimeter += lengths[(i + d - 1) % n];
      const uint32_t j = (i + d) % n;
      if (d < 2 || j < i) continue;  // each unordered pair once
      const auto it = paths.dist.find(patch.sides[j].vertices.front());
      if (it == paths.dist.end()) continue;
      const double smaller = std::min(perimeter, total - perimeter) + it->second;
      candidates.push_back({it->second / smaller, i, j});
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& x, const Candidate& y) { return x.score < y.score; });
  for (const Candidate& c : candidates) {
    if (splitPatchAtCorners(layout, p, c.i, c.j)) return true;
  }
  return false;
}

}  // namespace

bool straightenSide(PatchLayout& layout, uint32_t p, uint32_t s, bool keepHalves) {
  if (p >= layout.patches.size() || s >= layout.patches[p].sides.size()) return false;
  const PatchSide side = layout.patches[p].sides[s];
  if (side.neighbourPatch < 0 || side.neighbourPatch == int32_t(p)) return false;
  const uint32_t q = uint32_t(side.neighbourPatch), t = side.neighbourSide;
  const Patch &pp = layout.patches[p], &qq = layout.patches[q];
  // The union of both patches, bounded by every side but the shared one.
  Patch u;
  u.triangles = pp.triangles;
  u.triangles.insert(u.triangles.end(), qq.triangles.begin(), qq.triangles.end());
  for (uint32_t k = 0; k < pp.sides.size(); ++k) {
    if (k != s) u.sides.push_back(pp.sides[k]);
  }
  for (uint32_t k = 0; k < qq.sides.size(); ++k) {
    if (k != t) u.sides.push_back(qq.sides[k]);
  }
  const uint32_t a = side.vertices.front(), b = side.vertices.back();
  double before = 0.0;
  for (size_t k = 0; k + 1 < side.vertices.size(); ++k) {
    before += glm::length(layout.positions[side.vertices[k + 1]] - layout.positions[side.vertices[k]]);
  }
  // The shortest path between the corners, searched only where a path shorter than the side
  // can run: the triangles with a vertex closer to both corners together than the side is long
  // (shortestCutWithin, trianglesWithin; the margin covers the float lengths' rounding). A side
  // that is already straight leaves a thin ellipse, and most of the second round's sides are.
  const double bound = before * (1.0 + 1e-5);
  Patch near;
  near.sides = u.sides;
  near.triangles = trianglesWithin(layout, u.triangles, a, b, bound);
  std::vector<uint32_t> path{b};
  {
    const Paths paths = shortestCutWithin(layout, patchGraph(layout, near), a, b, bound);
    if (!paths.dist.contains(b) || !(paths.dist.at(b) < before * (1.0 - 1e-9))) return false;
    while (path.back() != a) path.push_back(paths.prev.at(path.back()));
  }
  std::reverse(path.begin(), path.end());
  if (path == side.vertices) return false;
  const PatchGraph g = patchGraph(layout, u, false);  // for the flood below, no more paths
  // p's part: flood from p's next side, never crossing the new side or any other side.
  std::unordered_set<uint64_t> walls(g.boundaryEdges.begin(), g.boundaryEdges.end());
  for (size_t k = 0; k + 1 < path.size(); ++k) walls.insert(undirectedEdgeKey(path[k], path[k + 1]));
  const std::unordered_set<uint32_t> mine = floodFrom(layout, g, pp.sides[(s + 1) % pp.sides.size()], walls);
  if (mine.empty()) return false;
  // Every other side of p borders p's part, every other side of q does not.
  auto borders = [&](const PatchSide& x) {
    const uint32_t t = g.triangleOf(directedEdgeKey(x.vertices[0], x.vertices[1]));
    return t != ~0u && mine.contains(t);
  };
  for (uint32_t k = 0; k < pp.sides.size(); ++k) {
    if (k != s && !borders(pp.sides[k])) return false;
  }
  for (uint32_t k = 0; k < qq.sides.size(); ++k) {
    if (k != t && borders(qq.sides[k])) return false;
  }
  std::vector<uint32_t> inP, inQ;
  for (uint32_t tri : u.triangles) (mine.contains(tri) ? inP : inQ).push_back(tri);
  if (inP.empty() || inQ.empty() || !isDisk(layout, inP) || !isDisk(layout, inQ)) return false;
  if (keepHalves && (2 * inP.size() < pp.triangles.size() || 2 * inQ.size() < qq.triangles.size())) return false;
  layout.patches[p].triangles = std::move(inP);
  layout.patches[q].triangles = std::move(inQ);
  layout.patches[p].sides[s].vertices = path;
  layout.patches[q].sides[t].vertices = side.reversed ? std::vector<uint32_t>(path.rbegin(), path.rend()) : path;
  return true;
}

bool lengthenSide(PatchLayout& layout, uint32_t a, uint32_t s, double by) {
  if (a >= layout.patches.size() || s >= layout.patches[a].sides.size() || !(by > 0.0)) return false;
  const uint32_t na = uint32_t(layout.patches[a].sides.size()), sn = (s + 1) % na;
  const PatchSide S = layout.patches[a].sides[s], N = layout.patches[a].sides[sn];
  if (S.neighbourPatch < 0 || N.neighbourPatch < 0 || !S.reversed || !N.reversed) return false;
  const uint32_t b = uint32_t(S.neighbourPatch), c = uint32_t(N.neighbourPatch);
  if (b == a || c == a || b == c) return false;
  const uint32_t nb = uint32_t(layout.patches[b].sides.size()), nc = uint32_t(layout.patches[c].sides.size());
  const uint32_t t = S.neighbourSide, tp = (t + nb - 1) % nb;  // B's side ending at the corner
  const uint32_t cn = N.neighbourSide, cb = (cn + 1) % nc;     // C's sides with A, then with B
  const PatchSide &bc = layout.patches[b].sides[tp], &cbSide = layout.patches[c].sides[cb];
  const uint32_t corner = S.vertices.back();
  if (bc.neighbourPatch != int32_t(c) || bc.neighbourSide != cb || !bc.reversed || cbSide.vertices.size() < 3 ||
      N.vertices.size() < 3 || N.vertices.front() != corner || cbSide.vertices.front() != corner) {
    return false;
  }
  // The new corner: the inner vertex of N nearest `by` along it, within its first half.
  const double half = 0.5 * sideLength(layout, N);
  size_t k = 1;
  {
    double arc = 0.0, best = std::numeric_limits<double>::infinity();
    for (size_t i = 1; i + 1 < N.vertices.size(); ++i) {
      arc += glm::length(layout.positions[N.vertices[i]] - layout.positions[N.vertices[i - 1]]);
      if (i > 1 && arc > half) break;
      if (std::abs(arc - by) < best) best = std::abs(arc - by), k = i;
    }
  }
  const uint32_t moved = N.vertices[k];
  // The path from it through C's interior to the nearest inner vertex of C's side with B,
  // searched among C's triangles near the corner.
  const Patch& C = layout.patches[c];
  const double reach = glm::length(layout.positions[moved] - layout.positions[corner]);
  Patch near;
  near.sides = C.sides;
  near.triangles = trianglesWithin(layout, C.triangles, corner, moved, 6.0 * reach);
  const Paths paths = shortestCuts(layout, patchGraph(layout, near), moved);
  size_t j = 0;
  double nearest = std::numeric_limits<double>::infinity();
  for (size_t i = 1; i + 1 < cbSide.vertices.size(); ++i) {
    const auto it = paths.dist.find(cbSide.vertices[i]);
    if (it != paths.dist.end() && it->second < nearest) nearest = it->second, j = i;
  }
  if (j == 0) return false;
  std::vector<uint32_t> path{cbSide.vertices[j]};
  while (path.back() != moved) path.push_back(paths.prev.at(path.back()));
  std::reverse(path.begin(), path.end());  // new corner -> C's side with B
  // The triangles C gives: flooded from the corner, crossing neither C's border nor the path.
  const PatchGraph g = patchGraph(layout, C, false);
  std::unordered_set<uint64_t> walls(g.boundaryEdges.begin(), g.boundaryEdges.end());
  for (size_t i = 0; i + 1 < path.size(); ++i) walls.insert(undirectedEdgeKey(path[i], path[i + 1]));
  const std::unordered_set<uint32_t> given = floodFrom(layout, g, cbSide, walls);
  if (given.empty() || given.size() >= C.triangles.size()) return false;
  auto inside = [&](const PatchSide& x, bool last) {
    const size_t e = last ? x.vertices.size() - 2 : 0;
    const uint32_t tri = g.triangleOf(directedEdgeKey(x.vertices[e], x.vertices[e + 1]));
    return tri != ~0u && given.contains(tri);
  };
  for (uint32_t x = 0; x < nc; ++x) {
    if (x != cb && inside(C.sides[x], false)) return false;
  }
  if (inside(cbSide, true)) return false;
  std::vector<uint32_t> rest, gained = layout.patches[b].triangles;
  for (const uint32_t tri : C.triangles) (given.contains(tri) ? gained : rest).push_back(tri);
  if (!isDisk(layout, rest) || !isDisk(layout, gained)) return false;

  std::vector<uint32_t> longer = S.vertices;
  longer.insert(longer.end(), N.vertices.begin() + 1, N.vertices.begin() + ptrdiff_t(k) + 1);
  std::vector<uint32_t> shorter(N.vertices.begin() + ptrdiff_t(k), N.vertices.end());
  std::vector<uint32_t> rerouted = path;
  rerouted.insert(rerouted.end(), cbSide.vertices.begin() + ptrdiff_t(j) + 1, cbSide.vertices.end());
  layout.patches[c].triangles = std::move(rest);
  layout.patches[b].triangles = std::move(gained);
  layout.patches[b].sides[t].vertices.assign(longer.rbegin(), longer.rend());
  layout.patches[b].sides[tp].vertices.assign(rerouted.rbegin(), rerouted.rend());
  layout.patches[c].sides[cn].vertices.assign(shorter.rbegin(), shorter.rend());
  layout.patches[c].sides[cb].vertices = std::move(rerouted);
  layout.patches[a].sides[s].vertices = std::move(longer);
  layout.patches[a].sides[sn].vertices = std::move(shorter);
  return true;
}

uint32_t lengthenShortSides(PatchLayout& layout, double fraction) {
  uint32_t lengthened = 0;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (uint32_t s = 0; s < layout.patches[p].sides.size(); ++s) {
      const PatchSide& side = layout.patches[p].sides[s];
      if (side.neighbourPatch <= int32_t(p)) continue;  // each shared side once
      const uint32_t q = uint32_t(side.neighbourPatch), t = side.neighbourSide;
      const double want = fraction * std::min(meanSideLength(layout, p), meanSideLength(layout, q)),
                   length = sideLength(layout, side);
      if (!(length < want)) continue;
      // From the end on the longer next side first (p's next side at one end, q's at the other).
      const double nextP = sideLength(layout, layout.patches[p].sides[(s + 1) % layout.patches[p].sides.size()]);
      const double nextQ = sideLength(layout, layout.patches[q].sides[(t + 1) % layout.patches[q].sides.size()]);
      const bool done =
          nextP >= nextQ
              ? lengthenSide(layout, p, s, 2.0 * want - length) || lengthenSide(layout, q, t, 2.0 * want - length)
              : lengthenSide(layout, q, t, 2.0 * want - length) || lengthenSide(layout, p, s, 2.0 * want - length);
      lengthened += done ? 1 : 0;
      spdlog::debug("side {} of patch {} ({} edges, {:.4g} long, {:.3f} of the shorter mean side): {}", s, p,
                    side.vertices.size() - 1, length, length / (want / fraction), done ? "lengthened" : "left");
    }
  }
  return lengthened;
}

uint32_t straightenSides(PatchLayout& layout, uint32_t rounds, bool keepHalves) {
  uint32_t changed = 0;
  std::vector<uint8_t> changedBefore;
  for (uint32_t r = 0; r < rounds; ++r) {
    // Every shared side once, from its smaller patch, in batches of sides whose patch pairs are
    // disjoint: straightenSide reads and writes its two patches only, so a batch runs in
    // parallel. Batches are filled greedily in side order, so the result does not depend on the
    // thread count.
    // After the first round, only sides with a patch the last round changed: the shortest path
    // between the same corners through the same two patches is the same.
    std::vector<std::pair<uint32_t, uint32_t>> pending;
    for (uint32_t p = 0; p < layout.patches.size(); ++p) {
      for (uint32_t s = 0; s < layout.patches[p].sides.size(); ++s) {
        const int32_t q = layout.patches[p].sides[s].neighbourPatch;
        if (q > int32_t(p) && (r == 0 || changedBefore[p] || changedBefore[uint32_t(q)])) pending.push_back({p, s});
      }
    }
    std::vector<uint8_t> changedNow(layout.patches.size(), 0);
    uint32_t now = 0;
    std::vector<uint8_t> busy(layout.patches.size(), 0);
    while (!pending.empty()) {
      std::vector<std::pair<uint32_t, uint32_t>> batch, rest;
      std::fill(busy.begin(), busy.end(), 0);
      for (const auto& [p, s] : pending) {
        const uint32_t q = uint32_t(layout.patches[p].sides[s].neighbourPatch);
        if (busy[p] || busy[q]) {
          rest.push_back({p, s});
        } else {
          busy[p] = busy[q] = 1;
          batch.push_back({p, s});
        }
      }
      std::vector<uint8_t> done(batch.size(), 0);
      tbb::parallel_for(size_t{0}, batch.size(), [&](size_t k) {
        done[k] = straightenSide(layout, batch[k].first, batch[k].second, keepHalves) ? 1 : 0;
      });
      for (size_t k = 0; k < batch.size(); ++k) {
        if (!done[k]) continue;
        ++now;
        changedNow[batch[k].first] = 1;
        changedNow[uint32_t(layout.patches[batch[k].first].sides[batch[k].second].neighbourPatch)] = 1;
      }
      pending = std::move(rest);
    }
    changedBefore = std::move(changedNow);
    changed += now;
    if (now == 0) break;
  }
  return changed;
}

namespace {

// What mendFirstSideEar did to a patch.
enum class EarStep {
  None,     // no ear it could mend
  Mended,   // an ear moved to the neighbour, or its middle vertex became a corner
  NeedsCut  // an ear on an open side of a patch with 8 sides: the patch must be cut first
};

// Mends the first side ear of patch p (see moveSideEars) on an open side, or on a shared side
// from its reversed end (each shared side is looked at from one of its patches). Changes only
// patch p and its neighbour across the side, never the number of patches, so the references it
// holds stay valid. With mayCut, an ear on an open side that cannot take a corner (8 sides
// already) is answered with NeedsCut, and the caller cuts the patch; else the search goes on.
EarStep mendFirstSideEar(PatchLayout& layout, uint32_t p, bool mayCut) {
  Patch& patch = layout.patches[p];
  // Directed edge -> triangle of this patch (its boundary runs counter-clockwise, so the
  // triangle inside along side edge a -> b holds a -> b).
  std::unordered_map<uint64_t, uint32_t> inside;
  for (uint32_t t : patch.triangles) {
    const auto& tri = layout.triangles[t];
    for (int c = 0; c < 3; ++c) inside[directedEdgeKey(tri[c], tri[(c + 1) % 3])] = t;
  }
  for (uint32_t s = 0; s < patch.sides.size(); ++s) {
    PatchSide& side = patch.sides[s];
    if (side.neighbourPatch == int32_t(p) || (side.neighbourPatch >= 0 && !side.reversed)) continue;
    const std::vector<uint32_t>& v = side.vertices;
    for (size_t k = 0; k + 2 < v.size(); ++k) {
      const auto it = inside.find(directedEdgeKey(v[k], v[k + 1]));
      if (it == inside.end()) continue;
      const uint32_t t = it->second;
      const auto& tri = layout.triangles[t];
      if (tri[0] != v[k + 2] && tri[1] != v[k + 2] && tri[2] != v[k + 2]) continue;
      // The third edge must be inside the patch (else the patch is this one triangle).
      if (!inside.contains(directedEdgeKey(v[k], v[k + 2]))) continue;
      if (side.neighbourPatch < 0) {
        // No neighbour to take it: its middle vertex becomes a corner, so its vertices lie on
        // two edges of the polygon.
        if (insertCorner(layout, p, s, uint32_t(k + 1))) return EarStep::Mended;
        if (mayCut) return EarStep::NeedsCut;
        continue;
      }
      Patch& other = layout.patches[uint32_t(side.neighbourPatch)];
      PatchSide& mirror = other.sides[side.neighbourSide];
      const uint32_t middle = v[k + 1];
      patch.triangles.erase(std::find(patch.triangles.begin(), patch.triangles.end(), t));
      other.triangles.push_back(t);
      side.vertices.erase(side.vertices.begin() + std::ptrdiff_t(k + 1));
      mirror.vertices.erase(std::find(mirror.vertices.begin(), mirror.vertices.end(), middle));
      return EarStep::Mended;
    }
  }
  return EarStep::None;
}

}  // namespace

uint32_t moveSideEars(PatchLayout& layout, const std::vector<uint32_t>& only, bool splitFull) {
  std::vector<uint32_t> patches = only;
  if (patches.empty()) {
    for (uint32_t p = 0; p < layout.patches.size(); ++p) patches.push_back(p);
  }
  uint32_t moved = 0;
  for (size_t w = 0; w < patches.size(); ++w) {
    const uint32_t p = patches[w];
    if (p >= layout.patches.size()) continue;
    uint32_t splits = 0;
    for (;;) {
      const EarStep step = mendFirstSideEar(layout, p, splitFull && splits < 2);
      if (step == EarStep::None) break;
      if (step == EarStep::Mended) {
        ++moved;
        continue;
      }
      // A patch with 8 sides already is cut at its neck (at most twice), both parts looked at
      // again; a failed cut may still have left it a corner, so the patch is looked at again
      // either way. No reference into the layout is held here: the cut appends patches.
      ++splits;
      const size_t count = layout.patches.size();
      if (splitPatchAtNeck(layout, p)) {
        for (size_t q = count; q < layout.patches.size(); ++q) patches.push_back(uint32_t(q));
      }
    }
  }
  return moved;
}

bool splitPatchAtNeck(PatchLayout& layout, uint32_t p) {
  return splitByCut(layout, p, {}, 8) || splitPatchAtCornerNeck(layout, p);
}

void EarSplits::undo(PatchLayout& layout) {
  if (changed.empty()) return;
  for (auto it = changed.rbegin(); it != changed.rend(); ++it) layout.triangles[it->first] = it->second;
  layout.triangles.resize(triangles);
  layout.positions.resize(positions);
  layout.colours.resize(colours);
  changed.clear();
}

namespace {

// Splits patch p's ear t (a -> b -> c, with a -> b and b -> c on an open side) and the triangle u
// across its inner edge (a -> c -> d) at the edge's midpoint.
void splitEar(PatchLayout& layout, uint32_t p, uint32_t t, uint32_t u, std::array<uint32_t, 4> abcd,
              EarSplits& record) {
  const auto [a, b, c, d] = abcd;
  const uint32_t m = uint32_t(layout.positions.size());
  layout.positions.push_back(0.5f * (layout.positions[a] + layout.positions[c]));
  if (!layout.colours.empty())
    layout.colours.push_back(glm::u8vec4((glm::uvec4(layout.colours[a]) + glm::uvec4(layout.colours[c])) / 2u));
  record.changed.push_back({t, layout.triangles[t]});
  record.changed.push_back({u, layout.triangles[u]});
  const uint32_t t2 = uint32_t(layout.triangles.size()), u2 = t2 + 1;
  layout.triangles[t] = {a, b, m};
  layout.triangles.push_back({b, c, m});
  layout.triangles[u] = {a, m, d};
  layout.triangles.push_back({m, c, d});
  layout.patches[p].triangles.push_back(t2);
  layout.patches[p].triangles.push_back(u2);
}

}  // namespace

uint32_t splitOpenSideEars(PatchLayout& layout, EarSplits* record) {
  *record = EarSplits{layout.positions.size(), layout.colours.size(), layout.triangles.size(), {}};
  uint32_t split = 0;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    const std::vector<PatchSide>& sides = layout.patches[p].sides;
    if (std::none_of(sides.begin(), sides.end(), [](const PatchSide& s) { return s.neighbourPatch < 0; })) continue;
    // Directed edge -> triangle of this patch, as mendFirstSideEar finds its ears.
    std::unordered_map<uint64_t, uint32_t> inside;
    auto index = [&](uint32_t t) {
      const auto& tri = layout.triangles[t];
      for (int c = 0; c < 3; ++c) inside[directedEdgeKey(tri[c], tri[(c + 1) % 3])] = t;
    };
    for (uint32_t t : layout.patches[p].triangles) index(t);
    for (const PatchSide& side : sides) {
      if (side.neighbourPatch >= 0) continue;
      const std::vector<uint32_t>& v = side.vertices;
      for (size_t k = 0; k + 2 < v.size(); ++k) {
        const uint32_t a = v[k], b = v[k + 1], c = v[k + 2];
        const auto ear = inside.find(directedEdgeKey(a, b));
        if (ear == inside.end()) continue;
        const uint32_t t = ear->second;
        const auto& et = layout.triangles[t];
        if (et[0] != c && et[1] != c && et[2] != c) continue;
        const auto across = inside.find(directedEdgeKey(a, c));  // the triangle across the ear's inner edge
        if (across == inside.end()) continue;
        const uint32_t u = across->second;
        uint32_t d = ~0u;
        for (uint32_t w : layout.triangles[u])
          if (w != a && w != c) d = w;
        if (std::find(v.begin(), v.end(), d) != v.end()) continue;
        splitEar(layout, p, t, u, {a, b, c, d}, *record);
        for (const uint32_t x : {t, u, uint32_t(layout.triangles.size() - 2), uint32_t(layout.triangles.size() - 1)})
          index(x);
        inside.erase(directedEdgeKey(a, c));
        inside.erase(directedEdgeKey(c, a));
        ++split;
      }
    }
  }
  return split;
}

GeometryImageSet resampleAndRepair(PatchLayout& layout, const ResampleOptions& options,
                                   const ChartRepairOptions& repair, ChartRepairStats* stats) {
  GeometryImageSet set = resampleLayout(layout, options);
  return repairCharts(layout, std::move(set), options, repair, stats);
}

namespace {

using Fold = std::pair<uint32_t, uint32_t>;  // a patch to cut, the triangle where it is worst

// What the repair weighs, per patch or summed over patches: flipped texels first, then by how much
// the charts' sampling errors exceed the bound (in multiples of it, times the chart's area),
// compared in that order.
struct Badness {
  uint64_t flips = 0;
  double excess = 0.0;
  Badness& operator+=(const Badness& o) {
    flips += o.flips;
    excess += o.excess;
    return *this;
  }
  bool operator<(const Badness& o) const {
    return flips != o.flips ? flips < o.flips : excess < o.excess * (1.0 - 1e-9);
  }
  bool any() const { return flips > 0 || excess > 0.0; }
};

// Patch p and its neighbours (ring 1), and their neighbours too (ring 2), sorted.
std::vector<uint32_t> patchRing(const PatchLayout& layout, std::vector<uint32_t> from) {
  std::vector<uint32_t> out = from;
  for (uint32_t q : from) {
    for (const PatchSide& side : layout.patches[q].sides) {
      if (side.neighbourPatch >= 0) out.push_back(uint32_t(side.neighbourPatch));
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// One split under trial: the patches it may change (a split changes the patch and gives its
// neighbours corners, whose new side numbers their own neighbours' links name: two rings), and
// copies of them for the undo.
struct Trial {
  uint32_t patch = 0, triangle = 0;
  std::vector<uint32_t> touched, rings;
  std::vector<Patch> saved;
  std::vector<uint32_t> cut;
  size_t firstNew = 0, endNew = 0;  // patches it appended
  bool done = false, kept = false;
};

// The folds split into a batch, greedily in order, whose two rings are pairwise disjoint, and the
// rest. A batch's splits touch disjoint patches, so they can be searched in parallel and made in
// any order with the same result as one after another.
// With wide, the rings are three (making side counts even around a cut may put corners on the
// second ring's sides, whose own neighbours' links follow).
std::vector<Trial> disjointBatch(const PatchLayout& layout, std::vector<Fold>& folds, bool wide) {
  std::vector<uint8_t> busy(layout.patches.size(), 0);
  std::vector<Trial> batch;
  std::vector<Fold> rest;
  for (const Fold& f : folds) {
    Trial t;
    t.patch = f.first;
    t.triangle = f.second;
    t.touched = patchRing(layout, {f.first});
    t.rings = patchRing(layout, t.touched);
    if (wide) t.rings = patchRing(layout, t.rings);
    if (std::any_of(t.rings.begin(), t.rings.end(), [&](uint32_t q) { return busy[q] != 0; })) {
      rest.push_back(f);
      continue;
    }
    for (uint32_t q : t.rings) busy[q] = 1;
    batch.push_back(std::move(t));
  }
  folds = std::move(rest);
  return batch;
}

// Removes the patches flagged dead (nothing live may link to them) and renumbers the links;
// `perPatch` is compacted alike.
template <typename T>
std::vector<int32_t> removePatches(PatchLayout& layout, const std::vector<uint8_t>& dead, std::vector<T>& perPatch) {
  std::vector<int32_t> index(layout.patches.size(), -1);
  uint32_t next = 0;
  for (uint32_t q = 0; q < layout.patches.size(); ++q) {
    if (!dead[q]) index[q] = int32_t(next++);
  }
  if (next == layout.patches.size()) return index;
  for (uint32_t q = 0; q < layout.patches.size(); ++q) {
    if (dead[q]) continue;
    for (PatchSide& side : layout.patches[q].sides) {
      if (side.neighbourPatch >= 0) side.neighbourPatch = index[uint32_t(side.neighbourPatch)];
    }
    if (uint32_t(index[q]) == q) continue;  // (a self move would empty it)
    layout.patches[uint32_t(index[q])] = std::move(layout.patches[q]);
    perPatch[uint32_t(index[q])] = perPatch[q];
  }
  layout.patches.resize(next);
  perPatch.resize(next);
  return index;
}

}  // namespace

namespace {

// One repair (see repairCharts): of the sampling errors alone (errorsOnly), or of the flipped
// texels first and the sampling errors after.
GeometryImageSet repairPass(PatchLayout& layout, GeometryImageSet set, const ResampleOptions& options,
                            const ChartRepairOptions& repair, ChartRepairStats& st,
                            const std::function<bool()>& mayGrow, bool errorsOnly) {
  const uint32_t maxRounds = repair.rounds;
  const uint64_t workBudget = repair.workBudget;
  const double maxError = repair.maxSampleError;
  // The repair of the sampling errors halves patches rather than clipping them: its cuts leave at
  // least a quarter of the border on either side.
  const double share = errorsOnly ? 0.25 : 0.0;
  auto badnessOf = [&](const GeometryImage& g) {
    Badness b;
    b.flips = g.quality.flippedTexels;
    // Weighted by the chart's area, so that cutting a patch in two with the same errors is no
    // worse, and no better.
    if (maxError > 0.0 && g.quality.sampleError > maxError)
      b.excess = (g.quality.sampleError / maxError - 1.0) * g.quality.area3D;
    return b;
  };
  auto badnessPerPatch = [&](const GeometryImageSet& s) {
    std::vector<Badness> f(layout.patches.size());
    for (const GeometryImage& g : s.charts) f[g.patch] += badnessOf(g);
    return f;
  };
  auto total = [&](const GeometryImageSet& s) {
    Badness b;
    for (const GeometryImage& g : s.charts) b += badnessOf(g);
    return b;
  };
  // What a repair of the sampling errors must do: lower them and add no flipped texel; what the
  // repair of both does: lower the flipped texels, or keep them and lower the errors.
  auto better = [&](const Badness& a, const Badness& b) {
    return errorsOnly ? a.flips <= b.flips && a.excess < b.excess * (1.0 - 1e-9) : a < b;
  };
  auto notWorse = [&](const Badness& a, const Badness& b) {
    return errorsOnly ? a.flips <= b.flips && a.excess <= b.excess : !(b < a);
  };
  auto toRepair = [&](const GeometryImageSet& s) {
    const Badness b = total(s);
    return errorsOnly ? b.excess > 0.0 : b.any();
  };
  if (!toRepair(set)) return set;
  auto grow = [&] {
    if (st.trianglesWholeRounds + st.trianglesTrials >= workBudget) {
      st.stoppedForWork = true;
      return false;
    }
    if (!mayGrow || mayGrow()) return true;
    st.stoppedForMemory = true;
    return false;
  };
  uint64_t* work = &st.trianglesWholeRounds;  // where the resamplings below count
  if (!grow()) return set;
  std::vector<glm::dvec3> ownNormals;
  if (!repair.normals) ownNormals = layoutVertexNormals(layout);
  const std::vector<glm::dvec3>& normals = repair.normals ? *repair.normals : ownNormals;
  // A triangle of patch p at layout vertex v (the patch's first triangle if none is).
  auto triangleAt = [&](uint32_t p, uint32_t v) {
    const uint32_t t = patchTriangleAt(layout, p, v);
    return t != ~0u ? t : layout.patches[p].triangles.front();
  };
  // The patches to cut: those with a fold (where it is), else with a sampling error over the
  // bound (at its worst vertex).
  auto folding = [&](const GeometryImageSet& s) {
    std::vector<Fold> bad;
    for (const GeometryImage& g : s.charts) {
      if (!bad.empty() && bad.back().first == g.patch) continue;
      if (!errorsOnly && !g.foldTriangles.empty()) {
        bad.push_back({g.patch, g.foldTriangles.front()});
      } else if (badnessOf(g).excess > 0.0 && g.quality.sampleErrorVertex != ~0u) {
        bad.push_back({g.patch, triangleAt(g.patch, g.quality.sampleErrorVertex)});
      }
    }
    return bad;
  };
  // Resamples only the flagged patches.
  auto resampleOnly = [&](const std::vector<uint8_t>& only) {
    ResampleReuse reuse;
    reuse.normals = &normals;
    reuse.only = &only;
    reuse.params = repair.params;
    GeometryImageSet r = resampleLayout(layout, options, reuse);
    *work += r.trianglesParameterized;
    return r;
  };
  // The full resampling of the current layout, from `earlier` (made from `earlierPatches`) where
  // patches are unchanged, and from `extra` (made from the current patches, possibly partial).
  auto refresh = [&](const std::vector<Patch>& earlierPatches, const std::vector<Patch>* extraPatches,
                     GeometryImageSet* extra) {
    ResampleReuse reuse;
    reuse.normals = &normals;
    reuse.params = repair.params;
    if (extra) reuse.earlier.push_back({extraPatches, extra});
    reuse.earlier.push_back({&earlierPatches, &set});
    set = resampleLayout(layout, options, reuse);
    *work += set.trianglesParameterized;
    ++st.rounds;
  };
  // A cut may leave ears (moveSideEars) in the patches it touched; mending them stays within
  // the trial's two rings. For the sides quad layout, the side counts round the cut are then made
  // even again within the second ring (its third is saved); false if that fails.
  const bool sidesLayout = options.quads == QuadLayout::kSides;
  // A part with few border edges has sides too short to take the corner that would make its side
  // count even: the sides layout cuts off no such part.
  const uint32_t minPartEdges = sidesLayout ? 4 : 0;
  // The most sides a cut leaves a part or a neighbour: 9 in the sides layout (the count made even
  // then stays within kMaxPatchSides, with room for chains of corners), else the clustering's 8.
  const uint32_t cutSides = sidesLayout ? 9 : 8;
  // The two-chart corners the repair started with (evenSides and alignSpokes leave none where they
  // can); no cut may add to them.
  const uint32_t cornersBefore = sidesLayout ? twoQuadCorners(layout) : 0;
  auto mendEars = [&](const Trial& t) {
    std::vector<uint32_t> patches = t.touched;
    for (size_t q = t.firstNew; q < t.endNew; ++q) patches.push_back(uint32_t(q));
    moveSideEars(layout, patches, false);
    if (!sidesLayout) return true;
    const std::vector<uint32_t> region = patchRing(layout, patches);
    if (evenSides(layout, region).oddLeft > 0) return false;
    // A cut whose corners leave two charts alone at a corner is not made.
    return alignSpokes(layout, region) <= cornersBefore;
  };
  // The sides layout pairs a patch's sides (2j, 2j+1) into quads; the other pairing (its sides
  // rotated by one) puts the spokes at the other corners. Every folding patch of 6 or more sides
  // tries it; kept where the patch gets better.
  if (sidesLayout && !errorsOnly) {
    const std::vector<Patch> saved = layout.patches;
    const std::vector<Badness> was = badnessPerPatch(set);
    std::vector<uint8_t> only(layout.patches.size(), 0);
    std::vector<uint32_t> rotated;
    for (uint32_t p = 0; p < layout.patches.size(); ++p) {
      if (was[p].flips == 0 || layout.patches[p].sides.size() < 6 || !rotationFoldsNoCorner(layout, p)) continue;
      rotatePatchSides(layout, p, 1);
      only[p] = 1;
      rotated.push_back(p);
    }
    if (!rotated.empty()) {
      const std::vector<Patch> rotatedPatches = layout.patches;
      GeometryImageSet trial = resampleOnly(only);
      std::vector<Badness> after(layout.patches.size());
      for (const GeometryImage& g : trial.charts) after[g.patch] += badnessOf(g);
      for (uint32_t p : rotated) {
        if (!(after[p] < was[p])) rotatePatchSides(layout, p, uint32_t(layout.patches[p].sides.size()) - 1);
      }
      refresh(saved, &rotatedPatches, &trial);
    }
  }
  // First, whole rounds: every folding patch cut at once (neck first, else through the fold),
  // kept while the flipped texels drop. Cheap (only the cut patches and their neighbours are
  // resampled) and it lets halves be cut again.
  for (uint32_t round = 0; round < maxRounds && toRepair(set) && grow(); ++round) {
    const std::vector<Patch> saved = layout.patches;
    uint32_t split = 0;
    std::vector<Fold> queue = folding(set);
    while (!queue.empty()) {
      std::vector<Trial> batch = disjointBatch(layout, queue, sidesLayout);
      tbb::parallel_for(size_t{0}, batch.size(), [&](size_t k) {
        batch[k].cut = findCut(layout, batch[k].patch, {}, cutSides, share, minPartEdges);
      });
      for (Trial& t : batch) {
        t.firstNew = layout.patches.size();
        const bool done = applyCut(layout, t.patch, t.cut, cutSides) || splitPatchAtCornerNeck(layout, t.patch) ||
                          splitPatchThrough(layout, t.patch, t.triangle);
        t.endNew = layout.patches.size();
        if (done) mendEars(t);
        split += done;
      }
    }
    // (A failed cut may still have left a corner; the sides layout needs even side counts and
    // no new two-chart corner.)
    if (split == 0 || (sidesLayout && (evenSides(layout).oddLeft > 0 || alignSpokes(layout) > cornersBefore))) {
      layout.patches = saved;
      break;
    }
    // The patches the round changed, before and after.
    const std::vector<Badness> was = badnessPerPatch(set);
    std::vector<uint8_t> changed(layout.patches.size(), 0);
    Badness before;
    for (uint32_t p = 0; p < layout.patches.size(); ++p) {
      if (p < saved.size() && patchSamplesAlike(saved[p], layout.patches[p], p)) continue;
      changed[p] = 1;
      if (p < saved.size()) before += was[p];
    }
    GeometryImageSet trial = resampleOnly(changed);
    if (!better(total(trial), before)) {
      layout.patches = saved;
      ++st.rounds;
      break;
    }
    refresh(saved, &layout.patches, &trial);
    st.patchesSplit += split;
  }
  // Then patch by patch, each split judged where it acts: kept only if it lowers the flipped
  // texels of the patches it changed (a cut can move a fold rather than remove it, and a new
  // corner reshapes the neighbour's polygon too). The cut through the fold is tried first and
  // must remove some of it; else the cut at the neck, which may also just not add any (the fold
  // is then in a smaller patch, which the next round cuts again). Folds are taken in batches of
  // disjoint two rings (disjointBatch): cuts searched in parallel, made in turn, judged by one
  // resampling of every changed patch, the failures undone.
  work = &st.trianglesTrials;
  for (uint32_t round = 0; round < maxRounds && toRepair(set) && !st.stoppedForMemory && !st.stoppedForWork; ++round) {
    std::vector<Fold> queue = folding(set);
    // Kept current as splits are kept (a later split's neighbours may be earlier ones' parts).
    std::vector<Badness> patchBadness = badnessPerPatch(set);
    const std::vector<Patch> roundStart = layout.patches;
    // The charts of the patches kept trials changed, by patch, with the patches they were made
    // from: the round's closing resampling takes them unless a later trial changed the patch again.
    GeometryImageSet kept;
    std::vector<Patch> keptPatches;
    uint32_t split = 0;
    st.patchesUnsplit = 0;
    while (!queue.empty() && grow()) {
      std::vector<Trial> batch = disjointBatch(layout, queue, sidesLayout);
      for (Trial& t : batch) {
        for (uint32_t q : t.rings) t.saved.push_back(layout.patches[q]);
      }
      for (const bool neck : {false, true}) {
        std::vector<Trial*> open;
        for (Trial& t : batch) {
          if (!t.kept) open.push_back(&t);
        }
        if (open.empty()) break;
        tbb::parallel_for(size_t{0}, open.size(), [&](size_t k) {
          Trial& t = *open[k];
          const auto& tri = layout.triangles[t.triangle];
          t.cut = neck ? findCut(layout, t.patch, {}, cutSides, share, minPartEdges)
                       : findCut(layout, t.patch, {tri[0], tri[1], tri[2]}, cutSides, share, minPartEdges);
        });
        for (Trial* t : open) {
          t->firstNew = layout.patches.size();
          t->done = applyCut(layout, t->patch, t->cut, cutSides) || (neck && splitPatchAtCornerNeck(layout, t->patch));
          t->endNew = layout.patches.size();
          if (t->done) t->done = mendEars(*t);
          if (!t->done) {  // undone at once (its new patches are the last), so every patch left resamples
            for (size_t r = 0; r < t->rings.size(); ++r) layout.patches[t->rings[r]] = t->saved[r];
            layout.patches.resize(t->firstNew);
            t->endNew = t->firstNew;
          }
        }
        std::vector<uint8_t> only(layout.patches.size(), 0);
        patchBadness.resize(layout.patches.size());
        // Per trial, the patches it changed, and what they weighed before.
        std::vector<std::vector<uint32_t>> now(open.size());
        std::vector<Badness> before(open.size());
        for (size_t k = 0; k < open.size(); ++k) {
          const Trial& t = *open[k];
          if (!t.done) continue;
          for (size_t r = 0; r < t.rings.size(); ++r) {
            const uint32_t q = t.rings[r];
            if (patchSamplesAlike(t.saved[r], layout.patches[q], q)) continue;
            now[k].push_back(q);
            before[k] += patchBadness[q];
          }
          for (size_t q = t.firstNew; q < t.endNew; ++q) now[k].push_back(uint32_t(q));
          for (uint32_t q : now[k]) only[q] = 1;
        }
        GeometryImageSet trial = resampleOnly(only);
        std::vector<Badness> after(layout.patches.size());
        for (const GeometryImage& g : trial.charts) after[g.patch] += badnessOf(g);
        std::vector<uint8_t> dead(layout.patches.size(), 0);
        for (size_t k = 0; k < open.size(); ++k) {
          Trial& t = *open[k];
          Badness a;
          for (uint32_t q : now[k]) a += after[q];
          if (t.done && (better(a, before[k]) || (neck && notWorse(a, before[k])))) {
            t.kept = true;
            for (uint32_t q : now[k]) patchBadness[q] = after[q];
            continue;
          }
          for (size_t r = 0; r < t.rings.size(); ++r) layout.patches[t.rings[r]] = t.saved[r];
          for (size_t q = t.firstNew; q < t.endNew; ++q) dead[q] = 1;
        }
        const std::vector<int32_t> index = removePatches(layout, dead, patchBadness);
        // Removing the failed trials' new patches keeps the others' order, so every side keeps
        // its owner and the kept patches' charts stay those of their new index.
        for (size_t k = 0; k < open.size(); ++k) {
          if (!open[k]->kept) continue;
          for (uint32_t q : now[k]) {
            const uint32_t at = uint32_t(index[q]);
            const PatchResampleStats& ps = trial.patches[q];
            if (kept.patches.size() <= at) kept.patches.resize(at + 1), keptPatches.resize(at + 1);
            kept.patches[at] = ps;
            kept.patches[at].firstChart = uint32_t(kept.charts.size());
            for (uint32_t i = 0; i < ps.quads; ++i) kept.charts.push_back(std::move(trial.charts[ps.firstChart + i]));
            keptPatches[at] = layout.patches[at];
          }
        }
      }
      for (const Trial& t : batch) {
        if (t.kept) {
          ++split;
        } else {
          ++st.patchesUnsplit;
        }
      }
    }
    if (split == 0) break;
    st.patchesSplit += split;
    refresh(roundStart, &keptPatches, &kept);
  }
  return set;
}

}  // namespace

GeometryImageSet repairCharts(PatchLayout& layout, GeometryImageSet set, const ResampleOptions& options,
                              const ChartRepairOptions& repair, ChartRepairStats* stats,
                              const std::function<bool()>& mayGrow) {
  ChartRepairStats local;
  ChartRepairStats& st = stats ? *stats : local;
  st = ChartRepairStats{};
  st.flippedTexelsFirst = set.image.flippedTexels;
  st.sampleErrorFirst = set.image.sampleError;
  if (repair.maxSampleError > 0.0) {
    for (uint8_t o : patchesOverSampleError(set, layout.patches.size(), repair.maxSampleError))
      st.patchesOverErrorFirst += o;
  }
  // Patches too coarsely sampled are halved first, by cuts that add no flipped texel; then the
  // folds, by cuts that must not raise the sampling errors again.
  // Twice: the fold repair's cuts change the layout, and a patch that no halving could improve
  // without a fold may then be cut.
  for (int cycle = 0; cycle < 2; ++cycle) {
    const uint32_t splitBefore = st.patchesSplit;
    // Each pass counts its own unsplit patches (a pass with nothing to do counts none).
    uint32_t unsplitForErrors = 0;
    if (repair.maxSampleError > 0.0) {
      st.patchesUnsplit = 0;
      set = repairPass(layout, std::move(set), options, repair, st, mayGrow, true);
      unsplitForErrors = st.patchesUnsplit;
    }
    st.patchesUnsplit = 0;
    set = repairPass(layout, std::move(set), options, repair, st, mayGrow, false);
    st.patchesUnsplit += unsplitForErrors;
    if (repair.maxSampleError <= 0.0 || set.image.sampleError <= repair.maxSampleError ||
        st.patchesSplit == splitBefore || st.stoppedForMemory || st.stoppedForWork)
      break;
  }
  return set;
}

}  // namespace gimlod

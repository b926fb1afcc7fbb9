// Topology of a patch of a chart layout: its interior edge graph, shortest interior paths between
// boundary vertices (the cuts that split a patch or straighten a side), and the disk test.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5; Sander et al. 2001 (chart splitting).
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <queue>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "atlas/mesh/patch_layout.h"

namespace gimlod {

// Key of the undirected edge {a, b} (smaller vertex in the high half).
inline uint64_t undirectedEdgeKey(uint32_t a, uint32_t b) {
  return a < b ? (uint64_t{a} << 32) | b : (uint64_t{b} << 32) | a;
}
// Key of the directed edge a -> b.
inline uint64_t directedEdgeKey(uint32_t a, uint32_t b) { return (uint64_t{a} << 32) | b; }

// What shortestInteriorPaths does at a vertex it settles.
enum class PathStep : uint8_t {
  kThrough,  // go on through the vertex
  kEnd,      // paths end here (a boundary vertex)
  kStop,     // end the whole search
};

// Dijkstra from `source` over a patch's interior (the one shortest-path search of the cuts).
// Graph provides:
//   void start(uint32_t source);                   // distance 0, no predecessor
//   double distance(uint32_t v);                   // of a vertex reached so far
//   bool relax(uint32_t w, double d, uint32_t u);  // w new or d shorter: stores d and u, true
//   void forNeighbours(uint32_t u, Fn fn);         // fn(w, edge length) over u's interior edges
// visit(u) is called once for each settled vertex, in order of (distance, vertex), and says
// whether paths go on through u. Ties keep the first predecessor found (strictly shorter
// distances replace), so paths do not depend on the order in which neighbours are listed.
template <class Graph, class Visit>
void shortestInteriorPaths(Graph& g, uint32_t source, Visit&& visit) {
  using Item = std::pair<double, uint32_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> heap;
  g.start(source);
  heap.push({0.0, source});
  while (!heap.empty()) {
    // note: plain names, not a structured binding: the lambda below captures them (clang 14).
    const double d = heap.top().first;
    const uint32_t u = heap.top().second;
    heap.pop();
    if (d > g.distance(u)) continue;
    const PathStep step = visit(u);
    if (step == PathStep::kStop) break;
    if (step == PathStep::kEnd) continue;
    g.forNeighbours(u, [&](uint32_t w, double length) {
      const double nd = d + length;
      if (g.relax(w, nd, u)) heap.push({nd, w});
    });
  }
}

// The patch's vertex graph restricted to what a cut may use: edges that are not on the patch
// boundary, through vertices that are not on it (a cut only starts and ends at the boundary).
// Flat sorted arrays (no node per entry): patches of tens of thousands of triangles are built
// and searched thousands of times by straightening and the flip repair.
struct PatchGraph {
  std::vector<std::pair<uint32_t, uint32_t>> adjacency;  // (vertex, neighbour), sorted; global ids
  std::unordered_set<uint32_t> onBoundary;
  std::unordered_set<uint64_t> boundaryEdges;
  std::vector<std::pair<uint64_t, uint32_t>> edgeTriangles;  // (directed edge, triangle), sorted

  // The patch's triangle holding directed edge `key`, ~0u if none.
  uint32_t triangleOf(uint64_t key) const;
  // The interior neighbours of vertex u, as a range of `adjacency`.
  std::pair<const std::pair<uint32_t, uint32_t>*, const std::pair<uint32_t, uint32_t>*> neighboursOf(uint32_t u) const;
};

// The graph of `patch` (its triangles and sides) in `layout`. Without withPaths, no adjacency:
// enough for triangleOf and the boundary, not for the path searches.
PatchGraph patchGraph(const PatchLayout& layout, const Patch& patch, bool withPaths = true);

// Shortest cut paths from `source`: distances and predecessors over interior vertices.
struct Paths {
  std::unordered_map<uint32_t, double> dist;
  std::unordered_map<uint32_t, uint32_t> prev;
};

// Shortest interior paths of graph g from `source` (edge lengths from the layout's float
// positions). It may stop early, once `target` is settled, or once `boundaryEnds` boundary
// vertices are: the paths to settled vertices are then final, and every other vertex in `dist`
// is at least as far as any settled one (so the nearest ends are exactly known). ~0u: no target.
Paths shortestCuts(const PatchLayout& layout, const PatchGraph& g, uint32_t source, uint32_t target = ~0u,
                   size_t boundaryEnds = std::numeric_limits<size_t>::max());

// The shortest interior path from `source` to `target`, if one is shorter than `bound`: the
// search of shortestCuts(layout, g, source, target), but a vertex u whose distance plus its
// straight distance to the target is `bound` or more is not gone through (no path through it can
// be shorter). Where a path shorter than `bound` exists, its distances and predecessors are
// those of shortestCuts, ties included: a vertex left out could only have offered a vertex of
// that path a distance longer than its own. So g need only hold the triangles with a vertex u
// closer to both ends than `bound` (|source - u| + |u - target| < bound): every edge of every
// vertex the search goes through.
Paths shortestCutWithin(const PatchLayout& layout, const PatchGraph& g, uint32_t source, uint32_t target, double bound);

// The triangles of `triangles` (layout ids, in their order) with a vertex u closer to both
// `source` and `target` together than `bound` (|source - u| + |u - target| < bound, with a margin
// for the float lengths' rounding): what shortestCutWithin's graph needs.
std::vector<uint32_t> trianglesWithin(const PatchLayout& layout, const std::vector<uint32_t>& triangles,
                                      uint32_t source, uint32_t target, double bound);

// Euler characteristic V - E + F of a set of the layout's triangles.
int64_t eulerCharacteristic(const PatchLayout& layout, const std::vector<uint32_t>& triangles);

// True if V - E + F = 1 (for a connected set of triangles, as a flood fill gives: a disk).
bool isDisk(const PatchLayout& layout, const std::vector<uint32_t>& triangles);

}  // namespace gimlod

// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5; Sander et al. 2001 (chart splitting).
#include "atlas/mesh/patch_topology.h"

#include <algorithm>

#include <glm/geometric.hpp>

namespace gimlod {
namespace {

// shortestCuts' graph for shortestInteriorPaths: the patch graph's interior edges, with lengths
// from the layout's float positions, and the paths in a Paths.
struct CutSearch {
  const PatchLayout& layout;
  const PatchGraph& g;
  Paths r;
  void start(uint32_t source) { r.dist[source] = 0.0; }
  double distance(uint32_t v) { return r.dist[v]; }
  bool relax(uint32_t w, double d, uint32_t u) {
    auto [dit, inserted] = r.dist.try_emplace(w, d);
    if (!inserted && !(d < dit->second)) return false;
    dit->second = d;
    r.prev[w] = u;
    return true;
  }
  template <class Fn>
  void forNeighbours(uint32_t u, Fn&& fn) const {
    const auto [first, last] = g.neighboursOf(u);
    for (auto e = first; e != last; ++e) {
      const uint32_t w = e->second;
      fn(w, glm::length(layout.positions[w] - layout.positions[u]));
    }
  }
};

}  // namespace

uint32_t PatchGraph::triangleOf(uint64_t key) const {
  const auto it = std::lower_bound(edgeTriangles.begin(), edgeTriangles.end(), std::pair<uint64_t, uint32_t>{key, 0u});
  return it != edgeTriangles.end() && it->first == key ? it->second : ~0u;
}

std::pair<const std::pair<uint32_t, uint32_t>*, const std::pair<uint32_t, uint32_t>*> PatchGraph::neighboursOf(
    uint32_t u) const {
  const auto lo = std::lower_bound(adjacency.begin(), adjacency.end(), std::pair<uint32_t, uint32_t>{u, 0u});
  auto hi = lo;
  while (hi != adjacency.end() && hi->first == u) ++hi;
  return {adjacency.data() + (lo - adjacency.begin()), adjacency.data() + (hi - adjacency.begin())};
}

PatchGraph patchGraph(const PatchLayout& layout, const Patch& patch, bool withPaths) {
  PatchGraph g;
  for (const PatchSide& s : patch.sides) {
    for (size_t k = 0; k < s.vertices.size(); ++k) {
      g.onBoundary.insert(s.vertices[k]);
      if (k + 1 < s.vertices.size()) g.boundaryEdges.insert(undirectedEdgeKey(s.vertices[k], s.vertices[k + 1]));
    }
  }
  g.edgeTriangles.reserve(patch.triangles.size() * 3);
  if (withPaths) g.adjacency.reserve(patch.triangles.size() * 3);
  for (uint32_t t : patch.triangles) {
    const auto& tri = layout.triangles[t];
    for (int c = 0; c < 3; ++c) {
      const uint32_t a = tri[c], b = tri[(c + 1) % 3];
      g.edgeTriangles.push_back({directedEdgeKey(a, b), t});
      // Each interior edge is seen from both of its triangles: add it from one.
      if (withPaths && a < b && !g.boundaryEdges.contains(undirectedEdgeKey(a, b))) {
        g.adjacency.push_back({a, b});
        g.adjacency.push_back({b, a});
      }
    }
  }
  std::sort(g.edgeTriangles.begin(), g.edgeTriangles.end());
  std::sort(g.adjacency.begin(), g.adjacency.end());
  return g;
}

Paths shortestCuts(const PatchLayout& layout, const PatchGraph& g, uint32_t source, uint32_t target,
                   size_t boundaryEnds) {
  CutSearch search{layout, g, {}};
  size_t ends = 0;
  shortestInteriorPaths(search, source, [&](uint32_t u) {
    if (u == target) return PathStep::kStop;
    if (u != source && g.onBoundary.contains(u)) {  // reached a boundary vertex: stop
      return ++ends >= boundaryEnds ? PathStep::kStop : PathStep::kEnd;
    }
    return PathStep::kThrough;
  });
  return std::move(search.r);
}

Paths shortestCutWithin(const PatchLayout& layout, const PatchGraph& g, uint32_t source, uint32_t target,
                        double bound) {
  CutSearch search{layout, g, {}};
  const glm::vec3 end = layout.positions[target];
  shortestInteriorPaths(search, source, [&](uint32_t u) {
    if (u == target) return PathStep::kStop;
    if (u != source && g.onBoundary.contains(u)) return PathStep::kEnd;
    // (The straight distance as the edges' lengths are taken, from float positions.)
    if (search.distance(u) + double(glm::length(layout.positions[u] - end)) >= bound) return PathStep::kEnd;
    return PathStep::kThrough;
  });
  return std::move(search.r);
}

std::vector<uint32_t> trianglesWithin(const PatchLayout& layout, const std::vector<uint32_t>& triangles,
                                      uint32_t source, uint32_t target, double bound) {
  const glm::vec3 pa = layout.positions[source], pb = layout.positions[target];
  std::vector<uint32_t> out;
  for (const uint32_t t : triangles) {
    for (const uint32_t v : layout.triangles[t]) {
      const glm::vec3 x = layout.positions[v];
      if (double(glm::length(x - pa)) + double(glm::length(x - pb)) < bound * (1.0 + 1e-5)) {
        out.push_back(t);
        break;
      }
    }
  }
  return out;
}

int64_t eulerCharacteristic(const PatchLayout& layout, const std::vector<uint32_t>& tris) {
  std::vector<uint32_t> verts;
  std::vector<uint64_t> edges;
  verts.reserve(tris.size() * 3);
  edges.reserve(tris.size() * 3);
  for (uint32_t t : tris) {
    const auto& tri = layout.triangles[t];
    for (int c = 0; c < 3; ++c) {
      verts.push_back(tri[c]);
      edges.push_back(undirectedEdgeKey(tri[c], tri[(c + 1) % 3]));
    }
  }
  std::sort(verts.begin(), verts.end());
  std::sort(edges.begin(), edges.end());
  const auto v = std::unique(verts.begin(), verts.end()) - verts.begin();
  const auto e = std::unique(edges.begin(), edges.end()) - edges.begin();
  return int64_t(v) - int64_t(e) + int64_t(tris.size());
}

bool isDisk(const PatchLayout& layout, const std::vector<uint32_t>& triangles) {
  return eulerCharacteristic(layout, triangles) == 1;
}

}  // namespace gimlod

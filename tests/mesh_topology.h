// Topology of indexed triangle meshes, welded by bit-identical position as `gimlod export` and
// the charting weld: what the scan tests compare between a scan and its exported atlas surface.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <numeric>
#include <ostream>
#include <utility>
#include <vector>

#include <glm/vec3.hpp>

#include "atlas/mesh/mesh_io.h"

namespace gimlod::test {

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  }
  void unite(uint32_t a, uint32_t b) { parent[find(a)] = find(b); }
};

// Topology of an indexed triangle mesh after welding bit-identical positions (as the exporter
// welds, and as the charting welds the input): open boundary loops (connected components of the
// edges used by one triangle), non-manifold edges (used by more than two), and V - E + F over the
// vertices that triangles use.
struct Topology {
  uint64_t vertices = 0, edges = 0, triangles = 0;
  uint64_t boundaryEdges = 0, boundaryLoops = 0, nonManifoldEdges = 0;
  int64_t euler() const { return int64_t(vertices) - int64_t(edges) + int64_t(triangles); }
};

inline Topology topologyOf(const std::vector<glm::vec3>& positions, const std::vector<std::array<uint32_t, 3>>& tris) {
  // Weld bit-identical positions.
  std::vector<uint32_t> order(positions.size());
  std::iota(order.begin(), order.end(), 0u);
  auto key = [&](uint32_t i) {
    std::array<uint32_t, 3> k;
    std::memcpy(k.data(), &positions[i], sizeof(k));
    return k;
  };
  std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
  std::vector<uint32_t> weld(positions.size());
  uint32_t next = 0;
  for (size_t i = 0; i < order.size(); ++i) {
    if (i > 0 && key(order[i]) != key(order[i - 1])) ++next;
    weld[order[i]] = next;
  }
  Topology t;
  std::vector<std::pair<uint64_t, uint32_t>> edges;  // (undirected edge key, count)
  std::vector<uint64_t> keys;
  keys.reserve(tris.size() * 3);
  std::vector<uint8_t> used(positions.empty() ? 0 : next + 1, 0);
  for (const auto& tri : tris) {
    const uint32_t a = weld[tri[0]], b = weld[tri[1]], c = weld[tri[2]];
    if (a == b || b == c || a == c) continue;  // collapsed by the weld: not a triangle
    ++t.triangles;
    for (uint32_t v : {a, b, c}) used[v] = 1;
    for (auto [p, q] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}})
      keys.push_back((uint64_t(std::min(p, q)) << 32) | std::max(p, q));
  }
  std::sort(keys.begin(), keys.end());
  UnionFind loops(used.size());
  std::vector<uint8_t> onBoundary(used.size(), 0);
  for (size_t i = 0; i < keys.size();) {
    size_t j = i;
    while (j < keys.size() && keys[j] == keys[i]) ++j;
    ++t.edges;
    if (j - i == 1) {
      ++t.boundaryEdges;
      const uint32_t p = uint32_t(keys[i] >> 32), q = uint32_t(keys[i]);
      onBoundary[p] = onBoundary[q] = 1;
      loops.unite(p, q);
    } else if (j - i > 2) {
      ++t.nonManifoldEdges;
    }
    i = j;
  }
  for (size_t v = 0; v < used.size(); ++v) {
    t.vertices += used[v];
    t.boundaryLoops += onBoundary[v] && loops.find(uint32_t(v)) == v;
  }
  return t;
}

inline std::ostream& operator<<(std::ostream& os, const Topology& t) {
  return os << "V " << t.vertices << " E " << t.edges << " F " << t.triangles << " (chi " << t.euler() << "), "
            << t.boundaryLoops << " boundary loops of " << t.boundaryEdges << " edges, " << t.nonManifoldEdges
            << " non-manifold edges";
}

// The scan's own topology, welded by bit-identical position like the export.
inline Topology inputTopology(const std::filesystem::path& input) {
  const IndexedMesh mesh = readMesh(input);
  return topologyOf(mesh.positions, mesh.triangles);
}

}  // namespace gimlod::test

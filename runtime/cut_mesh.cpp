#include "runtime/cut_mesh.h"

#include <cstring>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "core/atlas_format.h"

namespace gimlod {
namespace {

struct PositionKey {
  std::array<uint32_t, 3> bits;
  bool operator==(const PositionKey&) const = default;
};
struct PositionHash {
  size_t operator()(const PositionKey& k) const {
    uint64_t h = 1469598103934665603ull;
    for (uint32_t b : k.bits) h = (h ^ b) * 1099511628211ull;
    return size_t(h);
  }
};

uint64_t edgeKey(uint32_t a, uint32_t b) { return a < b ? (uint64_t(a) << 32 | b) : (uint64_t(b) << 32 | a); }

template <typename T>
void put(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}

}  // namespace

CutMesh buildCutMesh(const Hierarchy& h, const Cut& cut, const std::vector<std::vector<glm::vec3>>& captured,
                     const std::array<glm::dvec2, 2>* validRect) {
  if (captured.size() != cut.nodes.size()) throw std::invalid_argument("buildCutMesh: one capture per cut node");
  CutMesh m;
  std::unordered_map<PositionKey, uint32_t, PositionHash> index;
  std::vector<uint8_t> onOpenBorder;
  for (size_t n = 0; n < cut.nodes.size(); ++n) {
    const CutNode& node = cut.nodes[n];
    const uint32_t side = (1u << node.resLog2) + 1;
    if (captured[n].size() != size_t(side) * side)
      throw std::invalid_argument("buildCutMesh: node " + std::to_string(n) + " has " +
                                  std::to_string(captured[n].size()) + " vertices, not " + std::to_string(side * side));
    const NodeId& id = node.id;
    const uint32_t cells = 1u << id.level;  // nodes per chart side at this level
    const std::array<RootNeighbour, 4>& roots = h.roots[id.chart];
    std::vector<uint32_t> local(size_t(side) * side);
    for (uint32_t j = 0; j < side; ++j)
      for (uint32_t i = 0; i < side; ++i) {
        const glm::vec3& p = captured[n][size_t(j) * side + i];
        PositionKey key;
        std::memcpy(key.bits.data(), &p, sizeof key.bits);
        const auto [it, fresh] = index.emplace(key, uint32_t(m.positions.size()));
        if (fresh) {
          m.positions.push_back(p);
          m.chart.push_back(id.chart);
          m.level.push_back(uint8_t(id.level));
          m.nodeX.push_back(id.x);
          m.nodeY.push_back(id.y);
          m.resLog2.push_back(uint8_t(node.resLog2));
          onOpenBorder.push_back(0);
        }
        // On a chart border without a neighbour (edges: bottom v = 0, right u = 1, top v = 1,
        // left u = 0).
        const bool atBottom = id.y == 0 && j == 0, atTop = id.y == cells - 1 && j == side - 1;
        const bool atLeft = id.x == 0 && i == 0, atRight = id.x == cells - 1 && i == side - 1;
        const bool open = (atBottom && roots[kEdgeBottom].chart < 0) || (atRight && roots[kEdgeRight].chart < 0) ||
                          (atTop && roots[kEdgeTop].chart < 0) || (atLeft && roots[kEdgeLeft].chart < 0);
        const bool pastDem = validRect && (p.x <= (*validRect)[0].x || p.y <= (*validRect)[0].y ||
                                           p.x >= (*validRect)[1].x || p.y >= (*validRect)[1].y);
        onOpenBorder[it->second] |= uint8_t(open || pastDem);
        local[size_t(j) * side + i] = it->second;
      }
    for (uint32_t j = 0; j + 1 < side; ++j)
      for (uint32_t i = 0; i + 1 < side; ++i) {
        const uint32_t a = local[size_t(j) * side + i], b = local[size_t(j) * side + i + 1];
        const uint32_t c = local[size_t(j + 1) * side + i + 1], d = local[size_t(j + 1) * side + i];
        for (const std::array<uint32_t, 3>& t : {std::array<uint32_t, 3>{a, b, c}, std::array<uint32_t, 3>{a, c, d}})
          if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) m.triangles.push_back(t);
      }
  }
  std::unordered_map<uint64_t, uint32_t> uses;
  uses.reserve(m.triangles.size() * 3);
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++uses[edgeKey(t[k], t[(k + 1) % 3])];
  for (const auto& [key, count] : uses) {
    if (count != 1) continue;
    ++m.boundaryEdges;
    const uint32_t a = uint32_t(key >> 32), b = uint32_t(key);
    (onOpenBorder[a] && onOpenBorder[b] ? m.openBorderEdges : m.otherBoundaryEdges) += 1;
  }
  return m;
}

void writeCutMeshPly(const std::filesystem::path& path, const CutMesh& m) {
  std::string out =
      "ply\nformat binary_little_endian 1.0\ncomment gimlod: the cut as drawn, stitched positions from the vertex "
      "shader\nelement vertex " +
      std::to_string(m.positions.size()) +
      "\nproperty float x\nproperty float y\nproperty float z\nproperty uint chart\nproperty uchar level\n"
      "property uint node_x\nproperty uint node_y\nproperty uchar res\nelement face " +
      std::to_string(m.triangles.size()) + "\nproperty list uchar uint vertex_indices\nend_header\n";
  out.reserve(out.size() + m.positions.size() * 26 + m.triangles.size() * 13);
  for (size_t i = 0; i < m.positions.size(); ++i) {
    put(out, m.positions[i].x);
    put(out, m.positions[i].y);
    put(out, m.positions[i].z);
    put(out, m.chart[i]);
    put(out, m.level[i]);
    put(out, m.nodeX[i]);
    put(out, m.nodeY[i]);
    put(out, m.resLog2[i]);
  }
  for (const auto& t : m.triangles) {
    put(out, uint8_t(3));
    for (uint32_t v : t) put(out, v);
  }
  atomicWriteFile(path, out.data(), out.size());
}

}  // namespace gimlod

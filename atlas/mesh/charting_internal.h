// Internals of the charting stages, shared by atlas/mesh/charting.cpp (the face clusterer and
// the stages), atlas/mesh/mesh_repair.cpp (welding and repair) and atlas/mesh/layout_builder.cpp
// (corners, sides and patch splits). Not part of the public interface (atlas/mesh/charting.h).
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cstdint>
#include <limits>
#include <vector>

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include "atlas/mesh/charting.h"

namespace gimlod::charting {

using Clock = std::chrono::steady_clock;
inline constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();

inline double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

inline uint32_t nextHe(uint32_t h) { return h - h % 3 + (h % 3 + 1) % 3; }

// The boundary half-edge of cluster c (faces labelled c) that follows boundary half-edge h: turn
// around h's head through c's faces until a half-edge whose twin is missing or outside c.
inline uint32_t nextBoundaryHe(const std::vector<uint32_t>& twin, const std::vector<uint32_t>& label, uint32_t h,
                               uint32_t c) {
  uint32_t n = nextHe(h);
  while (true) {
    const uint32_t t = twin[n];
    if (t == kNone || label[t / 3] != c) return n;
    n = nextHe(t);
  }
}
inline uint32_t prevHe(uint32_t h) { return h - h % 3 + (h % 3 + 2) % 3; }

inline uint64_t mix64(uint64_t x) {
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdull;
  x ^= x >> 33;
  x *= 0xc4ceb9fe1a85ec53ull;
  x ^= x >> 33;
  return x;
}

// Exact-position weld table (open addressing). +0 and -0 are the same key. The slots index the
// caller's array of welded positions (no copy of the keys is kept).
class PositionWeld {
 public:
  explicit PositionWeld(size_t expected) {
    size_t cap = 16;
    while (cap < expected + expected / 2 + 16) cap *= 2;  // load <= 2/3
    slots_.assign(cap, kNone);
    mask_ = cap - 1;
  }
  // Returns the id of p: an earlier equal position's, or pos.size() after appending p.
  uint32_t insert(const glm::vec3& p, std::vector<glm::vec3>& pos) {
    const glm::vec3 q = p + 0.0f;
    const uint64_t hx = std::bit_cast<uint32_t>(q.x), hy = std::bit_cast<uint32_t>(q.y),
                   hz = std::bit_cast<uint32_t>(q.z);
    size_t i = mix64((hx << 32 | hy) ^ mix64(hz)) & mask_;
    while (true) {
      const uint32_t s = slots_[i];
      if (s == kNone) {
        const auto id = static_cast<uint32_t>(pos.size());
        slots_[i] = id;
        pos.push_back(p);
        return id;
      }
      if (pos[s] + 0.0f == q) return s;
      i = (i + 1) & mask_;
    }
  }

 private:
  std::vector<uint32_t> slots_;
  size_t mask_ = 0;
};

// The welded, repaired, manifold mesh with its adjacency.
struct Surface {
  std::vector<glm::vec3> positions;
  std::vector<glm::u8vec4> colours;
  std::vector<std::array<uint32_t, 3>> tris;
  std::vector<uint32_t> twin;  // per half-edge 3f+i (v[i] -> v[i+1]); kNone: open
  // Faces round a vertex: either vfStart / vfFaces (CSR, ascending faces; a block's sub-surface,
  // where a vertex may have several fans), or vHe (every vertex one fan, as weldAndRepair
  // leaves it): an outgoing half-edge, the open one if the fan is open, kNone if no face.
  std::vector<uint32_t> vHe;
  std::vector<uint32_t> vfStart;
  std::vector<uint32_t> vfFaces;
  uint32_t origin(uint32_t h) const { return tris[h / 3][h % 3]; }
  uint32_t dest(uint32_t h) const { return tris[h / 3][(h % 3 + 1) % 3]; }
  // Calls fn(face) for the faces round v until fn returns true.
  template <class Fn>
  void forFaces(uint32_t v, Fn&& fn) const {
    if (!vfStart.empty()) {
      for (uint32_t i = vfStart[v]; i < vfStart[v + 1]; ++i)
        if (fn(vfFaces[i])) return;
      return;
    }
    const uint32_t h0 = vHe[v];
    if (h0 == kNone) return;
    uint32_t h = h0;
    do {
      if (fn(h / 3)) return;
      h = twin[prevHe(h)];  // the next outgoing half-edge round v
    } while (h != kNone && h != h0);
  }
  // The faces round v in ascending order (as the CSR lists them).
  void facesAround(uint32_t v, std::vector<uint32_t>& out) const {
    out.clear();
    forFaces(v, [&](uint32_t f) {
      out.push_back(f);
      return false;
    });
    std::sort(out.begin(), out.end());
  }
  size_t bytes() const {
    return positions.size() * 12 + colours.size() * 4 + tris.size() * 12 + twin.size() * 4 + vHe.size() * 4 +
           vfStart.size() * 4 + vfFaces.size() * 4;
  }
};
// Step 1 of the repair, streamed: welds exactly equal positions as triangles are added, so that
// the caller can free its input as it goes. Ids are given in order of first reference.
struct Welder {
  explicit Welder(size_t expectedVertices) : table(expectedVertices) {}
  PositionWeld table;
  std::vector<glm::vec3> positions;  // first-referenced position of each welded vertex
  std::vector<glm::u8vec4> colours;  // likewise, if colours are welded
  std::vector<std::array<uint32_t, 3>> tris;
  uint64_t referenced = 0;  // input positions referenced (welded into an earlier one or not)
  // Id of an input position (remapping it for the triangles): a new one or an equal earlier one.
  uint32_t add(const glm::vec3& p, const glm::u8vec4* c) {
    ++referenced;
    const size_t before = positions.size();
    const uint32_t id = table.insert(p, positions);
    if (c && positions.size() != before) colours.push_back(*c);
    return id;
  }
};

// Steps 2-5 of weldAndRepair on welded triangles (w: positions, colours and triangles, the
// latter in input order, consumed). perTriangle: a value per input triangle, filtered as the
// triangles are (kept in step with Surface::tris).
Surface repairWelded(Welder&& w, ChartingStats& st, std::vector<uint32_t>* perTriangle = nullptr);

// Welds, drops degenerate and duplicate triangles, pairs half-edges (non-manifold edges: the
// first half-edges of each direction are paired, the rest stay open) and splits every vertex
// whose corners form more than one fan.
Surface weldAndRepair(const std::vector<glm::vec3>& inPos, const std::vector<glm::u8vec4>& inCol,
                      const std::vector<std::array<uint32_t, 3>>& inTris, ChartingStats& st);

// Area moments of a set of triangles, in normalised coordinates (bounding-box centre at 0,
// diagonal 1): area, first moment, second moment (xx xy xz yy yz zz), area-weighted normal.
struct Moments {
  double area = 0, m[3] = {0, 0, 0}, s[6] = {0, 0, 0, 0, 0, 0}, n[3] = {0, 0, 0};
  double nn[6] = {0, 0, 0, 0, 0, 0};  // sum of area * n n^T over the faces (unit normals n)
  void add(const Moments& o) {
    area += o.area;
    for (int i = 0; i < 3; ++i) m[i] += o.m[i], n[i] += o.n[i];
    for (int i = 0; i < 6; ++i) s[i] += o.s[i], nn[i] += o.nn[i];
  }
};

// The moments of triangle abc (normalised coordinates).
Moments triangleMoments(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c);

// Mean squared distance to the least-squares plane (normalised units).
double planeMsd(const Moments& M);

// Developability: the least variance of the unit normals along an axis (area-weighted, about
// their mean), min over unit a of mean (n.a - mean n.a)^2: the cone fit of D-Charts. 0 for a
// plane, a cylinder or a cone (all normals at one angle to the axis), about theta^4 / 48 for a
// spherical cap of half-angle theta (about its axis; a plane fit's normal spread is theta^2 / 4).
double coneFitVariance(const Moments& M);

// Normalised coordinates: bounding-box centre at 0, diagonal 1.
struct Frame {
  glm::dvec3 centre{0};
  double diag = 1;
};

// Fixes the sides of the clusters given by labels (a cluster per face) and returns the layout,
// with its statistics in st. Consumes the surface: its positions, colours and triangles move into
// the layout. clusterBytes: the clusterer's memory, for the peak estimate.
PatchLayout layoutFromLabels(Surface& s, std::vector<uint32_t> labels, const Frame& fr, const ChartingOptions& o,
                             ChartingStats& st, size_t clusterBytes);

}  // namespace gimlod::charting

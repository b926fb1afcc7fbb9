// Face clustering into a conforming layout of n-sided disk patches.
// Based on: Garland, Willmott, Heckbert, "Hierarchical Face Clustering on Polygonal Surfaces",
// I3D 2001 (dual-edge collapse, plane-fit quadric, compactness); Niski, Purnomo, Cohen, I3D
// 2007, section 5 (per-cell then global clustering); Purnomo, Cohen, Kumar, SGP 2004 (patches).
#include "atlas/mesh/charting.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <queue>
#include <string>
#include <unordered_map>
#include <utility>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "atlas/mesh/gridify.h"

namespace gimlod {
namespace {

using Clock = std::chrono::steady_clock;
constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
constexpr double kPi = 3.14159265358979323846;
// Planarity unit of the merge cost: 1% of the bounding-box diagonal (a mean squared plane
// distance of kTau^2 costs as much as a perfect disc's compactness at weight 1).
constexpr double kTau = 0.01;
// Weight of the normal-spread term 1 - |sum of area-weighted normals| / area (0 flat, 1 folded
// shut); it keeps clusters from wrapping round thin parts, where the plane fit alone is small.
constexpr double kNormalWeight = 4.0;

// Hands freed heap memory back to the system. The cells' results are many small blocks spread
// over the worker threads' malloc arenas; once they are freed, glibc keeps those pages (only
// the top of an arena is trimmed), which would count against the memory cap in later stages.
void releaseFreedMemory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

inline uint32_t nextHe(uint32_t h) { return h - h % 3 + (h % 3 + 1) % 3; }

// The boundary half-edge of cluster c (faces labelled c) that follows boundary half-edge h: turn
// around h's head through c's faces until a half-edge whose twin is missing or outside c.
inline uint32_t nextBoundaryHe(const std::vector<uint32_t>& twin, const std::vector<uint32_t>& label,
                               uint32_t h, uint32_t c) {
  uint32_t n = nextHe(h);
  while (true) {
    const uint32_t t = twin[n];
    if (t == kNone || label[t / 3] != c) return n;
    n = nextHe(t);
  }
}
inline uint32_t prevHe(uint32_t h) { return h - h % 3 + (h % 3 + 2) % 3; }

uint64_t mix64(uint64_t x) {
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
  std::vector<uint32_t> twin;     // per half-edge 3f+i (v[i] -> v[i+1]); kNone: open
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
    return positions.size() * 12 + colours.size() * 4 + tris.size() * 12 + twin.size() * 4 +
           vHe.size() * 4 + vfStart.size() * 4 + vfFaces.size() * 4;
  }
};

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  // The root of a set is its smallest element, and parent[x] <= x throughout.
  void unite(uint32_t a, uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
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
Surface repairWelded(Welder&& w, ChartingStats& st, std::vector<uint32_t>* perTriangle = nullptr) {
  const char* fn = "buildChartLayout";
  Surface s;
  std::vector<std::array<uint32_t, 3>> tris = std::move(w.tris);
  st.inputTriangles += tris.size();
  st.inputVertices += w.referenced;
  st.verticesWelded += w.referenced - w.positions.size();
  w.table = PositionWeld(0);  // the table is no longer needed
  // 2. Drop degenerate and duplicate triangles (first one kept). Triangles are bucketed by
  // their smallest vertex (counting sort), so each bucket holds a handful of candidates: O(n)
  // and 4 bytes per triangle, where one global sort of (vertex triple, index) keys would take 16.
  const uint32_t nw = static_cast<uint32_t>(w.positions.size());
  std::vector<uint8_t> keep(tris.size(), 0);
  {
    std::vector<uint32_t> start(size_t{nw} + 1, 0);
    auto sortedOf = [&](uint32_t i) {
      std::array<uint32_t, 3> t = tris[i];
      std::sort(t.begin(), t.end());
      return t;
    };
    for (uint32_t i = 0; i < tris.size(); ++i) {
      const std::array<uint32_t, 3> t = sortedOf(i);
      if (t[0] == t[1] || t[1] == t[2]) {
        ++st.droppedDegenerate;
        continue;
      }
      keep[i] = 1;
      ++start[t[0] + 1];
    }
    for (uint32_t v = 0; v < nw; ++v) start[v + 1] += start[v];
    std::vector<uint32_t> bucket(start[nw]);
    {
      std::vector<uint32_t> fill(start.begin(), start.end() - 1);
      for (uint32_t i = 0; i < tris.size(); ++i)
        if (keep[i]) bucket[fill[sortedOf(i)[0]]++] = i;
    }
    std::vector<std::pair<std::array<uint32_t, 3>, uint32_t>> group;
    for (uint32_t v = 0; v < nw; ++v) {
      const uint32_t b = start[v], e = start[v + 1];
      if (e - b < 2) continue;
      group.clear();
      for (uint32_t k = b; k < e; ++k) group.push_back({sortedOf(bucket[k]), bucket[k]});
      std::sort(group.begin(), group.end());
      for (size_t k = 1; k < group.size(); ++k)
        if (group[k].first == group[k - 1].first) {
          keep[group[k].second] = 0;
          ++st.droppedDuplicate;
        }
    }
  }
  {
    size_t n = 0;
    for (size_t i = 0; i < tris.size(); ++i) {
      if (!keep[i]) continue;
      tris[n] = tris[i];
      if (perTriangle) (*perTriangle)[n] = (*perTriangle)[i];
      ++n;
    }
    tris.resize(n);
    tris.shrink_to_fit();
    if (perTriangle) {
      perTriangle->resize(n);
      perTriangle->shrink_to_fit();
    }
  }
  std::vector<uint8_t>().swap(keep);
  const uint32_t nf = static_cast<uint32_t>(tris.size());
  if (nf == 0) throw InputError(std::string(fn) + ": no triangle left after welding");
  // 3. Pair half-edges by undirected edge: half-edges bucketed by their smaller vertex
  // (counting sort), each bucket ordered by (larger vertex, half-edge), which groups them
  // exactly as a global sort of (edge key, half-edge) would. The buckets are filled a range of
  // vertices at a time, so that the bucket array stays small on large meshes.
  auto org = [&](uint32_t h) { return tris[h / 3][h % 3]; };
  auto dst = [&](uint32_t h) { return tris[h / 3][(h % 3 + 1) % 3]; };
  s.twin.assign(size_t{nf} * 3, kNone);
  std::vector<std::vector<uint32_t>> badGroups;
  {
    std::vector<uint32_t> start(size_t{nw} + 1, 0);
    for (uint32_t h = 0; h < 3 * nf; ++h) ++start[std::min(org(h), dst(h)) + 1];
    for (uint32_t v = 0; v < nw; ++v) start[v + 1] += start[v];
    constexpr uint32_t kRange = uint32_t{1} << 23;  // half-edges (and vertices) per range
    std::vector<uint32_t> he, fill;
    auto far = [&](uint32_t h) { return std::max(org(h), dst(h)); };
    for (uint32_t lo = 0; lo < nw;) {
      uint32_t hi = lo + 1;
      while (hi < nw && hi - lo < kRange && start[hi + 1] - start[lo] <= kRange) ++hi;
      he.resize(start[hi] - start[lo]);
      fill.resize(hi - lo);
      for (uint32_t v = lo; v < hi; ++v) fill[v - lo] = start[v] - start[lo];
      for (uint32_t h = 0; h < 3 * nf; ++h) {  // h ascending in each bucket
        const uint32_t v = std::min(org(h), dst(h));
        if (v >= lo && v < hi) he[fill[v - lo]++] = h;
      }
      for (uint32_t v = lo; v < hi; ++v) {
        const auto b = he.begin() + (start[v] - start[lo]), e = he.begin() + (start[v + 1] - start[lo]);
        std::stable_sort(b, e, [&](uint32_t x, uint32_t y) { return far(x) < far(y); });
        for (auto i = b; i != e;) {
          auto j = i + 1;
          while (j != e && far(*j) == far(*i)) ++j;
          if (j - i == 2 && org(*i) != org(*(i + 1))) {
            s.twin[*i] = *(i + 1);
            s.twin[*(i + 1)] = *i;
          } else if (j - i >= 2) {
            ++st.nonManifoldEdges;
            std::vector<uint32_t> fw, bw, all;
            for (auto k = i; k != j; ++k) {
              const uint32_t h = *k;
              all.push_back(h);
              (org(h) < dst(h) ? fw : bw).push_back(h);
            }
            for (size_t k = 0; k < std::min(fw.size(), bw.size()); ++k) {
              s.twin[fw[k]] = bw[k];
              s.twin[bw[k]] = fw[k];
            }
            badGroups.push_back(std::move(all));
          }
          i = j;
        }
      }
      lo = hi;
    }
  }
  // 4. Split vertices into fans (corners linked across paired edges). Repeat if a split leaves
  // two edges between the same two vertices (a fan closing round a fin): detach that triangle.
  const uint32_t nv0 = nw;
  std::vector<uint32_t> newId, vertexOf;  // corner -> new vertex; new vertex -> welded
  uint64_t splitVertices = 0;
  for (int round = 0;; ++round) {
    {
      UnionFind uf(size_t{nf} * 3);
      for (uint32_t h = 0; h < 3 * nf; ++h) {
        const uint32_t t = s.twin[h];
        if (t == kNone || t < h) continue;
        uf.unite(h, nextHe(t));
        uf.unite(nextHe(h), t);
      }
      newId = std::move(uf.parent);
    }
    // Corners in ascending order: a root (the smallest corner of its fan) gets the fan's vertex
    // id; any other corner's parent is a smaller corner, already replaced by that id.
    std::vector<uint8_t> owned(nv0, 0);
    std::vector<uint8_t> counted(nv0, 0);
    vertexOf.resize(nv0);
    std::iota(vertexOf.begin(), vertexOf.end(), 0u);
    splitVertices = 0;
    uint64_t nonManifoldVertices = 0;
    for (uint32_t c = 0; c < 3 * nf; ++c) {
      if (newId[c] != c) {
        newId[c] = newId[newId[c]];
        continue;
      }
      const uint32_t v = org(c);
      if (!owned[v]) {
        owned[v] = 1;
        newId[c] = v;
      } else {
        newId[c] = static_cast<uint32_t>(vertexOf.size());
        vertexOf.push_back(v);
        ++splitVertices;
        if (!counted[v]) {
          counted[v] = 1;
          ++nonManifoldVertices;
        }
      }
    }
    bool changed = false;
    for (const auto& g : badGroups) {
      for (size_t a = 0; a < g.size(); ++a) {
        for (size_t b = 0; b < g.size(); ++b) {
          const uint32_t ha = g[a], hb = g[b];
          if (a == b || s.twin[ha] == hb) continue;
          const uint32_t a0 = newId[ha], a1 = newId[nextHe(ha)];
          const uint32_t b0 = newId[hb], b1 = newId[nextHe(hb)];
          if (!((a0 == b0 && a1 == b1) || (a0 == b1 && a1 == b0))) continue;
          const uint32_t f = ha / 3;
          for (uint32_t k = 0; k < 3; ++k) {
            const uint32_t h = 3 * f + k, t = s.twin[h];
            if (t == kNone) continue;
            s.twin[h] = s.twin[t] = kNone;
            changed = true;
          }
        }
      }
    }
    if (!changed || round > 64) {
      st.nonManifoldVertices += nonManifoldVertices;
      break;
    }
  }
  st.verticesSplit += splitVertices;
  // 5. Output arrays (vertex v < nw keeps its welded id; split copies come after).
  const uint32_t nv = static_cast<uint32_t>(vertexOf.size());
  s.tris = std::move(tris);  // renumbered in place
  for (uint32_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) s.tris[f][k] = newId[3 * f + k];
  std::vector<uint32_t>().swap(newId);
  s.positions = std::move(w.positions);
  s.positions.resize(nv);
  for (uint32_t v = nv0; v < nv; ++v) s.positions[v] = s.positions[vertexOf[v]];
  s.positions.shrink_to_fit();
  if (!w.colours.empty()) {
    s.colours = std::move(w.colours);
    s.colours.resize(nv);
    for (uint32_t v = nv0; v < nv; ++v) s.colours[v] = s.colours[vertexOf[v]];
    s.colours.shrink_to_fit();
  }
  std::vector<uint32_t>().swap(vertexOf);
  // One outgoing half-edge per vertex, the open one where the fan is open.
  s.vHe.assign(nv, kNone);
  for (uint32_t h = 0; h < 3 * nf; ++h) {
    uint32_t& e = s.vHe[s.origin(h)];
    if (e == kNone || s.twin[h] == kNone) e = h;
  }
  for (uint32_t t : s.twin) st.boundaryEdges += t == kNone;
  return s;
}

// Welds, drops degenerate and duplicate triangles, pairs half-edges (non-manifold edges: the
// first half-edges of each direction are paired, the rest stay open) and splits every vertex
// whose corners form more than one fan.
Surface weldAndRepair(const std::vector<glm::vec3>& inPos, const std::vector<glm::u8vec4>& inCol,
                      const std::vector<std::array<uint32_t, 3>>& inTris, ChartingStats& st) {
  const char* fn = "buildChartLayout";
  // 1. Weld referenced positions.
  Welder w(std::min(inPos.size(), inTris.size() * 3));
  {
    std::vector<uint32_t> remap(inPos.size(), kNone);
    w.tris.reserve(inTris.size());
    for (const auto& t : inTris) {
      std::array<uint32_t, 3> r;
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = t[k];
        if (v >= inPos.size())
          throw InputError(std::string(fn) + ": triangle index " + std::to_string(v) +
                           " outside the " + std::to_string(inPos.size()) + " positions");
        if (remap[v] == kNone) {
          const glm::vec3& p = inPos[v];
          if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
            throw InputError(std::string(fn) + ": vertex " + std::to_string(v) + " is not finite");
          remap[v] = w.add(p, inCol.empty() ? nullptr : &inCol[v]);
        }
        r[k] = remap[v];
      }
      w.tris.push_back(r);
    }
  }
  return repairWelded(std::move(w), st);
}

// Area moments of a set of triangles, in normalised coordinates (bounding-box centre at 0,
// diagonal 1): area, first moment, second moment (xx xy xz yy yz zz), area-weighted normal.
struct Moments {
  double area = 0, m[3] = {0, 0, 0}, s[6] = {0, 0, 0, 0, 0, 0}, n[3] = {0, 0, 0};
  void add(const Moments& o) {
    area += o.area;
    for (int i = 0; i < 3; ++i) m[i] += o.m[i], n[i] += o.n[i];
    for (int i = 0; i < 6; ++i) s[i] += o.s[i];
  }
};

Moments triangleMoments(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  Moments r;
  const glm::dvec3 e1 = b - a, e2 = c - a;
  const glm::dvec3 cr{e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z,
                      e1.x * e2.y - e1.y * e2.x};
  const double A = 0.5 * std::sqrt(cr.x * cr.x + cr.y * cr.y + cr.z * cr.z);
  const glm::dvec3 g = (a + b + c) / 3.0;
  r.area = A;
  for (int i = 0; i < 3; ++i) r.m[i] = A * g[i], r.n[i] = 0.5 * cr[i];
  // Integral of x x^T over the triangle: A/12 (sum v v^T + 9 g g^T).
  const glm::dvec3* v[3] = {&a, &b, &c};
  const int ij[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  for (int k = 0; k < 6; ++k) {
    double sum = 9.0 * g[ij[k][0]] * g[ij[k][1]];
    for (int t = 0; t < 3; ++t) sum += (*v[t])[ij[k][0]] * (*v[t])[ij[k][1]];
    r.s[k] = A / 12.0 * sum;
  }
  return r;
}

// Smallest eigenvalue of a symmetric 3x3 matrix (xx xy xz yy yz zz), closed form.
double minEigenvalue(const double c[6]) {
  const double a00 = c[0], a01 = c[1], a02 = c[2], a11 = c[3], a12 = c[4], a22 = c[5];
  const double p1 = a01 * a01 + a02 * a02 + a12 * a12;
  const double q = (a00 + a11 + a22) / 3.0;
  if (p1 <= 1e-300) return std::min({a00, a11, a22});
  const double p2 = (a00 - q) * (a00 - q) + (a11 - q) * (a11 - q) + (a22 - q) * (a22 - q) + 2 * p1;
  const double p = std::sqrt(p2 / 6.0);
  if (p <= 0) return q;
  const double b00 = (a00 - q) / p, b11 = (a11 - q) / p, b22 = (a22 - q) / p;
  const double b01 = a01 / p, b02 = a02 / p, b12 = a12 / p;
  const double det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) +
                     b02 * (b01 * b12 - b11 * b02);
  const double r = std::clamp(det / 2.0, -1.0, 1.0);
  const double phi = std::acos(r) / 3.0;
  return q + 2.0 * p * std::cos(phi + 2.0 * kPi / 3.0);
}

// Mean squared distance to the least-squares plane (normalised units).
double planeMsd(const Moments& M) {
  if (M.area <= 0) return 0;
  double c[6];
  const int ij[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  for (int k = 0; k < 6; ++k) c[k] = M.s[k] - M.m[ij[k][0]] * M.m[ij[k][1]] / M.area;
  return std::max(0.0, minEigenvalue(c) / M.area);
}

// Normalised coordinates: bounding-box centre at 0, diagonal 1.
struct Frame {
  glm::dvec3 centre{0};
  double diag = 1;
};

// Greedy dual-edge collapse over clusters of a Surface's faces.
class Clusterer {
 public:
  // Normalised positions ((p - centre) / diag, in double) are computed where needed, not
  // stored: 24 bytes a vertex saved.
  Clusterer(const Surface& s, const Frame& fr, std::vector<uint32_t> labels)
      : s_(s), fr_(fr), label_(std::move(labels)) {
    const uint32_t nf = static_cast<uint32_t>(s.tris.size());
    uint32_t nc = 0;
    for (uint32_t l : label_) nc = std::max(nc, l + 1);
    mom_.assign(nc, {});
    perim_.assign(nc, 0);
    count_.assign(nc, 0);
    head_.assign(nc, kNone);
    nextFace_.assign(nf, kNone);
    version_.assign(nc, 0);
    adj_.resize(nc);
    for (uint32_t f = nf; f-- > 0;) {
      const uint32_t c = label_[f];
      mom_[c].add(faceMoments(f));
      nextFace_[f] = head_[c];
      head_[c] = f;
      ++count_[c];
    }
    struct Link {
      uint32_t a, b;
      double len;
    };
    std::vector<Link> links;
    for (uint32_t h = 0; h < 3 * nf; ++h) {
      const uint32_t t = s.twin[h];
      const uint32_t c = label_[h / 3];
      if (t != kNone && label_[t / 3] == c) continue;
      const double len = edgeLength(h);
      perim_[c] += len;
      if (t != kNone && h < t) {
        const uint32_t d = label_[t / 3];
        links.push_back({std::min(c, d), std::max(c, d), len});
      }
    }
    std::sort(links.begin(), links.end(),
              [](const Link& x, const Link& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; });
    for (size_t i = 0; i < links.size();) {
      size_t j = i;
      Adj e{links[i].b, 0, 0};
      while (j < links.size() && links[j].a == links[i].a && links[j].b == links[i].b) {
        ++e.edges;
        e.length += links[j].len;
        ++j;
      }
      adj_[links[i].a].push_back(e);
      adj_[e.other].push_back({links[i].a, e.edges, e.length});
      i = j;
    }
    for (uint32_t c = 0; c < nc; ++c) {
      if (count_[c] > 0) ++alive_;
      totalArea_ += mom_[c].area;
    }
    totalArea_ = std::max(totalArea_, 1e-300);
    pos_.assign(nc, kNone);
    vstamp_.assign(s.positions.size(), 0);
  }

  // Merges until `target` clusters remain (0: no count target) or no allowed merge is left.
  // maxRms: largest RMS plane distance of a merged cluster (normalised units), or infinity.
  void run(uint32_t target, double maxRms, double weight) {
    weight_ = weight;
    maxRms_ = maxRms;
    for (uint32_t c = 0; c < adj_.size(); ++c)
      for (const Adj& e : adj_[c])
        if (c < e.other) push(c, e);
    while (!heap_.empty() && alive_ > std::max(target, 1u)) {
      std::pop_heap(heap_.begin(), heap_.end(), std::greater<Cand>());
      const Cand k = heap_.back();
      heap_.pop_back();
      if (stale(k)) continue;
      if (!mergeKeepsDisk(k.a, k.b)) {
        ++refused_;
        continue;
      }
      merge(k.a, k.b);
    }
  }

  // True if the cluster's faces form a closed topological disk (connected, V - E + F = 1, one
  // simple boundary loop).
  bool isDisk(uint32_t c) {
    ++stamp_;
    uint64_t F = 0, E2 = 0, V = 0, B = 0;
    uint32_t start = kNone;
    for (uint32_t f = head_[c]; f != kNone; f = nextFace_[f]) {
      ++F;
      for (uint32_t k = 0; k < 3; ++k) {
        const uint32_t h = 3 * f + k, t = s_.twin[h];
        const bool bnd = t == kNone || label_[t / 3] != c;
        E2 += bnd ? 2 : 1;
        if (bnd) ++B, start = h;
        const uint32_t v = s_.tris[f][k];
        if (vstamp_[v] != stamp_) vstamp_[v] = stamp_, ++V;
      }
    }
    if (F == 0 || start == kNone) return false;
    if (static_cast<int64_t>(V) - static_cast<int64_t>(E2 / 2) + static_cast<int64_t>(F) != 1)
      return false;
    // Connected: flood over interior edges (marks in a bit per face, cleared afterwards).
    if (faceSeen_.size() != (s_.tris.size() + 63) / 64) faceSeen_.assign((s_.tris.size() + 63) / 64, 0);
    auto seen = [&](uint32_t f) { return (faceSeen_[f >> 6] >> (f & 63)) & 1; };
    auto see = [&](uint32_t f) { faceSeen_[f >> 6] |= uint64_t{1} << (f & 63); };
    std::vector<uint32_t> stack{head_[c]};
    see(head_[c]);
    uint64_t reached = 0;
    while (!stack.empty()) {
      const uint32_t f = stack.back();
      stack.pop_back();
      ++reached;
      for (uint32_t k = 0; k < 3; ++k) {
        const uint32_t t = s_.twin[3 * f + k];
        if (t == kNone || label_[t / 3] != c || seen(t / 3)) continue;
        see(t / 3);
        stack.push_back(t / 3);
      }
    }
    for (uint32_t f = head_[c]; f != kNone; f = nextFace_[f]) faceSeen_[f >> 6] = 0;
    if (reached != F) return false;
    // One simple loop through all boundary half-edges.
    ++stamp_;
    uint64_t len = 0;
    uint32_t h = start;
    do {
      const uint32_t v = s_.origin(h);
      if (vstamp_[v] == stamp_) return false;
      vstamp_[v] = stamp_;
      ++len;
      h = nextBoundary(h, c);
    } while (h != start && len <= B);
    return len == B && h == start;
  }

  // Replaces every non-disk cluster's labels by single-triangle clusters; `dissolved` counts
  // those clusters. Returns true if any was: then the clusterer is spent (its labels changed
  // under it), and a new one is to be built from takeLabels().
  bool dissolveNonDisks(uint32_t& dissolved) {
    dissolved = 0;
    const uint32_t nc = static_cast<uint32_t>(count_.size());
    std::vector<uint32_t> bad;
    for (uint32_t c = 0; c < nc; ++c)
      if (count_[c] > 0 && !isDisk(c)) bad.push_back(c);
    std::vector<uint64_t>().swap(faceSeen_);
    uint32_t next = nc;
    for (uint32_t c : bad) {
      ++dissolved;
      for (uint32_t f = nextFace_[head_[c]]; f != kNone; f = nextFace_[f]) label_[f] = next++;
    }
    return !bad.empty();
  }

  uint32_t nextBoundary(uint32_t h, uint32_t c) const { return nextBoundaryHe(s_.twin, label_, h, c); }

  const std::vector<uint32_t>& labels() const { return label_; }
  std::vector<uint32_t> takeLabels() { return std::move(label_); }  // the clusterer is spent
  uint32_t alive() const { return alive_; }
  uint32_t refused() const { return refused_; }
  size_t bytes() const {
    return mom_.size() * (sizeof(Moments) + 8 + 4 + 4 + 4 + 4 + sizeof(std::vector<Adj>)) +
           nextFace_.size() * 8 + heapPeak_ * sizeof(Cand) + vstamp_.size() * 4;
  }

 private:
  struct Adj {
    uint32_t other;
    uint32_t edges;
    double length;
  };
  struct Cand {
    double cost;
    uint32_t a, b, va, vb;
    bool operator>(const Cand& o) const { return cost > o.cost; }
  };

  Moments faceMoments(uint32_t f) const {
    const auto& t = s_.tris[f];
    return triangleMoments(npos(t[0]), npos(t[1]), npos(t[2]));
  }
  double edgeLength(uint32_t h) const {
    return glm::length(npos(s_.origin(h)) - npos(s_.dest(h)));
  }
  glm::dvec3 npos(uint32_t v) const {
    return (glm::dvec3(s_.positions[v]) - fr_.centre) / fr_.diag;
  }

  void push(uint32_t a, const Adj& e) {
    const uint32_t b = e.other;
    Moments M = mom_[a];
    M.add(mom_[b]);
    const double msd = planeMsd(M);
    if (msd > maxRms_ * maxRms_) return;
    const double perim = std::max(0.0, perim_[a] + perim_[b] - 2.0 * e.length);
    const double area = std::max(M.area, 1e-300);
    const double nlen = std::sqrt(M.n[0] * M.n[0] + M.n[1] * M.n[1] + M.n[2] * M.n[2]);
    const double spread = std::max(0.0, 1.0 - nlen / area);
    const double compact = perim * perim / (4.0 * kPi * area);
    const double cost =
        (area / totalArea_) * (msd / (kTau * kTau) + kNormalWeight * spread + weight_ * compact);
    heap_.push_back({cost, a, b, version_[a], version_[b]});
    std::push_heap(heap_.begin(), heap_.end(), std::greater<Cand>());
    heapPeak_ = std::max(heapPeak_, heap_.size());
    if (heap_.size() >= purgeAt_) purge();
  }

  // The union of two disks is a disk iff they meet in exactly one boundary arc: shared
  // vertices = shared edges + 1 (a full shared loop gives 0, several arcs or touching corners
  // give more).
  bool mergeKeepsDisk(uint32_t a, uint32_t b) {
    if (count_[a] > count_[b]) std::swap(a, b);
    ++stamp_;
    uint64_t sharedEdges = 0, sharedVertices = 0;
    for (uint32_t f = head_[a]; f != kNone; f = nextFace_[f]) {
      for (uint32_t k = 0; k < 3; ++k) {
        const uint32_t h = 3 * f + k, t = s_.twin[h];
        if (t != kNone && label_[t / 3] == a) continue;
        if (t != kNone && label_[t / 3] == b) ++sharedEdges;
        const uint32_t v = s_.tris[f][k];
        if (vstamp_[v] == stamp_) continue;
        vstamp_[v] = stamp_;
        s_.forFaces(v, [&](uint32_t g) {
          if (label_[g] != b) return false;
          ++sharedVertices;
          return true;
        });
      }
    }
    return sharedEdges > 0 && sharedVertices == sharedEdges + 1;
  }

  bool stale(const Cand& k) const {
    return count_[k.a] == 0 || count_[k.b] == 0 || version_[k.a] != k.va || version_[k.b] != k.vb;
  }

  // Every merge leaves the candidates of both clusters stale and pushes the merged cluster's
  // anew, so most of a large heap is stale: popping each costs O(log n) cache misses. Once the
  // heap has doubled since the last purge (and holds at least kPurgeMin entries: small meshes
  // never purge), the stale entries are dropped and the heap rebuilt in O(n). The valid
  // candidates and their costs are unchanged, so the same merges are made (up to the order of
  // exactly equal costs).
  static constexpr size_t kPurgeMin = size_t{1} << 16;
  void purge() {
    std::erase_if(heap_, [&](const Cand& k) { return stale(k); });
    std::make_heap(heap_.begin(), heap_.end(), std::greater<Cand>());
    purgeAt_ = std::max(kPurgeMin, 2 * heap_.size());
  }

  void merge(uint32_t a, uint32_t b) {
    if (count_[a] > count_[b]) std::swap(a, b);  // a (smaller) into b
    uint32_t last = kNone;
    for (uint32_t f = head_[a]; f != kNone; f = nextFace_[f]) {
      label_[f] = b;
      last = f;
    }
    nextFace_[last] = head_[b];
    head_[b] = head_[a];
    head_[a] = kNone;
    count_[b] += count_[a];
    count_[a] = 0;
    mom_[b].add(mom_[a]);
    std::vector<Adj>& ab = adj_[b];
    double shared = 0;
    for (size_t i = 0; i < ab.size(); ++i) {
      if (ab[i].other == a) {
        shared = ab[i].length;
        ab[i] = ab.back();
        ab.pop_back();
        break;
      }
    }
    perim_[b] = std::max(0.0, perim_[a] + perim_[b] - 2.0 * shared);
    for (size_t i = 0; i < ab.size(); ++i) pos_[ab[i].other] = static_cast<uint32_t>(i);
    for (const Adj& e : adj_[a]) {
      const uint32_t x = e.other;
      if (x == b) continue;
      std::vector<Adj>& ax = adj_[x];
      if (pos_[x] != kNone) {
        ab[pos_[x]].edges += e.edges;
        ab[pos_[x]].length += e.length;
        // x lists both a and b: fold a's entry into b's.
        size_t ia = kNone, ib = kNone;
        for (size_t i = 0; i < ax.size(); ++i) {
          if (ax[i].other == a) ia = i;
          if (ax[i].other == b) ib = i;
        }
        ax[ib].edges += ax[ia].edges;
        ax[ib].length += ax[ia].length;
        ax[ia] = ax.back();
        ax.pop_back();
      } else {
        pos_[x] = static_cast<uint32_t>(ab.size());
        ab.push_back(e);
        for (Adj& y : ax)
          if (y.other == a) y.other = b;
      }
    }
    for (const Adj& e : ab) pos_[e.other] = kNone;
    std::vector<Adj>().swap(adj_[a]);
    ++version_[a];
    ++version_[b];
    --alive_;
    for (const Adj& e : ab) push(b, e);
  }

  const Surface& s_;
  const Frame fr_;
  std::vector<uint32_t> label_;
  std::vector<Moments> mom_;
  std::vector<double> perim_;
  std::vector<uint32_t> count_, head_, nextFace_, version_, pos_, vstamp_;
  std::vector<uint64_t> faceSeen_;  // isDisk's flood marks, a bit per face
  std::vector<std::vector<Adj>> adj_;
  // A binary min-heap on cost (std::push_heap / pop_heap, as std::priority_queue does), kept
  // as a vector so that stale candidates can be purged in one pass.
  std::vector<Cand> heap_;
  size_t purgeAt_ = kPurgeMin;
  size_t heapPeak_ = 0;
  uint32_t alive_ = 0, refused_ = 0, stamp_ = 0;
  double totalArea_ = 0, weight_ = 1, maxRms_ = std::numeric_limits<double>::infinity();
};

void checkOptions(const ChartingOptions& o) {
  const char* fn = "charting options";
  if (o.minSides < 3)
    throw InputError(std::string(fn) + ": minSides must be at least 3");
  if (o.maxSides < std::max(4u, 2 * o.minSides - 3))
    throw InputError(std::string(fn) + ": maxSides must be at least max(4, 2 * minSides - 3)");
  if (o.targetCharts == 0 && !(o.maxError > 0 && std::isfinite(o.maxError)))
    throw InputError(std::string(fn) + ": maxError must be positive when targetCharts is 0");
  if (!(o.compactnessWeight >= 0 && std::isfinite(o.compactnessWeight)))
    throw InputError(std::string(fn) + ": compactnessWeight must be finite and >= 0");
}

Frame frameOf(const std::vector<glm::vec3>& p) {
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (const auto& q : p) lo = glm::min(lo, glm::dvec3(q)), hi = glm::max(hi, glm::dvec3(q));
  Frame fr;
  if (p.empty()) return fr;
  fr.centre = 0.5 * (lo + hi);
  fr.diag = glm::length(hi - lo);
  if (!(fr.diag > 0)) fr.diag = 1;
  return fr;
}

// ---- Sides: corners, corner insertion, splitting, output ----

class LayoutBuilder {
 public:
  // labels: a cluster per face (any ids), renumbered in place by first face.
  LayoutBuilder(const Surface& s, std::vector<uint32_t> labels, const ChartingOptions& o,
                ChartingStats& st)
      : s_(s), o_(o), st_(st), label_(std::move(labels)) {
    const uint32_t nf = static_cast<uint32_t>(s.tris.size());
    {
      uint32_t maxLabel = 0;
      for (uint32_t l : label_) maxLabel = std::max(maxLabel, l);
      std::vector<uint32_t> compact(size_t{maxLabel} + 1, kNone), count;
      for (uint32_t f = 0; f < nf; ++f) {
        uint32_t& c = compact[label_[f]];
        if (c == kNone) c = static_cast<uint32_t>(count.size()), count.push_back(0);
        label_[f] = c;
        ++count[c];
      }
      faces_.resize(count.size());
      for (size_t c = 0; c < count.size(); ++c) faces_[c].reserve(count[c]);
      for (uint32_t f = 0; f < nf; ++f) faces_[label_[f]].push_back(f);
    }
    const uint32_t nv = static_cast<uint32_t>(s.positions.size());
    corner_.assign(nv, 0);
    std::vector<uint8_t> open(nv, 0);
    for (uint32_t h = 0; h < 3 * nf; ++h)
      if (s.twin[h] == kNone) open[s.origin(h)] = open[s.dest(h)] = 1;
    for (uint32_t v = 0; v < nv; ++v) {
      uint32_t first = kNone, second = kNone;
      bool three = false;
      s.forFaces(v, [&](uint32_t f) {
        const uint32_t c = label_[f];
        if (first == kNone || c == first) first = c;
        else if (second == kNone || c == second) second = c;
        else three = true;
        return three;
      });
      corner_[v] = three || (open[v] && second != kNone);
    }
  }

  void fix() {
    // Corner insertion for patches with too few sides.
    for (uint32_t p = 0; p < faces_.size(); ++p) insertCorners(p);
    // Split patches with too many sides (halves have at least minSides and fewer sides).
    std::vector<uint32_t> work(faces_.size());
    std::iota(work.begin(), work.end(), 0u);
    size_t budget = 64 * faces_.size() + 10000;  // guards against ping-pong of new corners
    while (!work.empty() && budget-- > 0) {
      const uint32_t p = work.back();
      work.pop_back();
      const std::vector<uint32_t> loop = boundaryLoop(p);
      uint32_t corners = 0;
      for (uint32_t h : loop) corners += corner_[s_.origin(h)];
      if (corners <= o_.maxSides) continue;
      const uint32_t q = split(p, loop, work);
      if (q == kNone) continue;
      ++st_.patchesSplit;
      work.push_back(p);
      work.push_back(q);
    }
    // Patches still out of range (no cut found, or the budget ran out).
    unfixed_ = 0;
    for (uint32_t p = 0; p < faces_.size(); ++p) {
      uint32_t corners = 0;
      for (uint32_t h : boundaryLoop(p)) corners += corner_[s_.origin(h)];
      unfixed_ += corners > o_.maxSides || corners < o_.minSides;
    }
  }

  ChartLayout output() {
    // Patches only: the caller moves the surface's positions, colours and triangles in.
    ChartLayout out;
    const uint32_t np = static_cast<uint32_t>(faces_.size());
    out.patches.resize(np);
    std::unordered_map<uint32_t, uint32_t> sideOf;  // patch-boundary half-edge -> side index
    sideOf.reserve(size_t{np} * 64);
    std::vector<std::vector<uint32_t>> firstHe(np);
    for (uint32_t p = 0; p < np; ++p) {
      Patch& P = out.patches[p];
      const std::vector<uint32_t> loop = boundaryLoop(p);
      P.triangles = std::move(faces_[p]);  // faces_ is not used after output()
      std::sort(P.triangles.begin(), P.triangles.end());
      size_t start = 0;
      while (start < loop.size() && !corner_[s_.origin(loop[start])]) ++start;
      if (start == loop.size()) start = 0;  // no corner (only if insertion failed)
      for (size_t i = 0; i < loop.size(); ++i) {
        const uint32_t h = loop[(start + i) % loop.size()];
        if (i == 0 || corner_[s_.origin(h)]) {
          P.sides.emplace_back();
          P.sides.back().vertices.push_back(s_.origin(h));
          const uint32_t t = s_.twin[h];
          P.sides.back().neighbourPatch = t == kNone ? -1 : static_cast<int32_t>(label_[t / 3]);
          firstHe[p].push_back(h);
        }
        P.sides.back().vertices.push_back(s_.dest(h));
        sideOf[h] = static_cast<uint32_t>(P.sides.size() - 1);
      }
    }
    for (uint32_t p = 0; p < np; ++p) {
      for (size_t i = 0; i < out.patches[p].sides.size(); ++i) {
        PatchSide& side = out.patches[p].sides[i];
        if (side.neighbourPatch < 0) continue;
        side.neighbourSide = sideOf.at(s_.twin[firstHe[p][i]]);
        side.reversed = true;
      }
    }
    return out;
  }

  uint32_t unfixed() const { return unfixed_; }
  const std::vector<uint32_t>& labels() const { return label_; }
  size_t bytes() const {
    return label_.size() * 8 + corner_.size() + local_.size() * 4 +
           ldist_.capacity() * 8 + (lprev_.capacity() + lvisit_.capacity() + lpos_.capacity()) * 4;
  }

 private:
  uint32_t nextBoundary(uint32_t h, uint32_t c) const { return nextBoundaryHe(s_.twin, label_, h, c); }

  std::vector<uint32_t> boundaryLoop(uint32_t p) const {
    std::vector<uint32_t> loop;
    uint32_t start = kNone;
    for (uint32_t f : faces_[p]) {
      for (uint32_t k = 0; k < 3 && start == kNone; ++k) {
        const uint32_t h = 3 * f + k, t = s_.twin[h];
        if (t == kNone || label_[t / 3] != p) start = h;
      }
      if (start != kNone) break;
    }
    if (start == kNone) return loop;
    uint32_t h = start;
    do {
      loop.push_back(h);
      h = nextBoundary(h, p);
    } while (h != start && loop.size() <= 3 * faces_[p].size());
    return loop;
  }

  double length(uint32_t h) const {
    return glm::length(glm::dvec3(s_.positions[s_.origin(h)]) -
                       glm::dvec3(s_.positions[s_.dest(h)]));
  }

  // Adds corners at the middle (by length) of the longest runs until the patch has minSides.
  void insertCorners(uint32_t p) {
    const std::vector<uint32_t> loop = boundaryLoop(p);
    const size_t L = loop.size();
    std::vector<double> cum(L + 1, 0);
    for (size_t i = 0; i < L; ++i) cum[i + 1] = cum[i] + length(loop[i]);
    auto isCorner = [&](size_t i) { return corner_[s_.origin(loop[i % L])] != 0; };
    uint32_t corners = 0;
    for (size_t i = 0; i < L; ++i) corners += isCorner(i);
    if (corners >= o_.minSides) return;
    if (corners == 0) {
      // Spread minSides corners evenly by length.
      const double total = cum[L];
      size_t j = 0;
      for (uint32_t k = 0; k < o_.minSides && j < L; ++k) {
        const double target = total * k / o_.minSides;
        while (j + 1 < L && cum[j] < target) ++j;
        if (!isCorner(j)) {
          corner_[s_.origin(loop[j])] = 1;
          ++st_.cornersInserted;
        }
        ++j;
      }
      corners = 0;
      for (size_t i = 0; i < L; ++i) corners += isCorner(i);
    }
    while (corners < o_.minSides) {
      // Longest run (in edges >= 2) between consecutive corners.
      size_t first = 0;
      while (!isCorner(first)) ++first;
      size_t bestA = kNone, bestB = 0;
      double bestLen = -1;
      size_t a = first;
      for (size_t step = 0; step < corners; ++step) {
        size_t b = a + 1;
        while (!isCorner(b)) ++b;
        const double len = b <= L ? cum[b] - cum[a] : cum[L] - cum[a] + cum[b - L];
        if (b - a >= 2 && len > bestLen) bestLen = len, bestA = a, bestB = b;
        a = b;
      }
      if (bestA == kNone) return;  // cannot happen on a loop of >= 3 edges
      auto at = [&](size_t i) {
        return i <= L ? cum[i] : cum[L] + cum[i - L];
      };
      const double mid = 0.5 * (at(bestA) + at(bestB));
      size_t pick = bestA + 1;
      double bestD = std::abs(at(pick) - mid);
      for (size_t i = bestA + 2; i < bestB; ++i)
        if (std::abs(at(i) - mid) < bestD) bestD = std::abs(at(i) - mid), pick = i;
      corner_[s_.origin(loop[pick % L])] = 1;
      ++st_.cornersInserted;
      ++corners;
    }
  }

  // Local numbering of patch p's vertices for split()'s work arrays (sized to the patch, not
  // the mesh); undone by clearLocal().
  void numberLocal(uint32_t p) {
    if (local_.empty()) local_.assign(s_.positions.size(), kNone);
    lverts_.clear();
    for (uint32_t f : faces_[p])
      for (uint32_t v : s_.tris[f])
        if (local_[v] == kNone) local_[v] = static_cast<uint32_t>(lverts_.size()), lverts_.push_back(v);
    const size_t n = lverts_.size();
    ldist_.assign(n, 0);
    lprev_.assign(n, kNone);
    lvisit_.assign(n, 0);
    lpos_.assign(n, kNone);  // position on the boundary loop; kNone: not on it
    lrun_ = 0;
  }
  void clearLocal() {
    for (uint32_t v : lverts_) local_[v] = kNone;
    lverts_.clear();
  }

  // Shortest paths from boundary vertex a through the interior of patch p (interior vertices
  // and interior edges only) to every boundary vertex it reaches; returns those vertices.
  // ldist_ / lprev_ hold the paths for this run (lvisit_ == the returned run id).
  std::vector<uint32_t> shortestFrom(uint32_t p, uint32_t a, uint32_t& run) {
    run = ++lrun_;
    using Item = std::pair<double, uint32_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> q;
    std::vector<uint32_t> reached;
    const uint32_t la = local_[a];
    ldist_[la] = 0;
    lprev_[la] = kNone;
    lvisit_[la] = run;
    q.push({0, a});
    while (!q.empty()) {
      const auto [d, u] = q.top();
      q.pop();
      if (d > ldist_[local_[u]]) continue;
      if (u != a && lpos_[local_[u]] != kNone) {  // boundary vertices end paths
        reached.push_back(u);
        continue;
      }
      s_.facesAround(u, around_);
      for (const uint32_t f : around_) {
        if (label_[f] != p) continue;
        for (uint32_t k = 0; k < 3; ++k) {
          const uint32_t h = 3 * f + k;
          uint32_t w;
          if (s_.origin(h) == u) w = s_.dest(h);
          else if (s_.dest(h) == u) w = s_.origin(h);
          else continue;
          const uint32_t t = s_.twin[h];
          if (t == kNone || label_[t / 3] != p || w == a) continue;  // boundary edge
          const double nd = d + length(h);
          const uint32_t lw = local_[w];
          if (lvisit_[lw] != run || nd < ldist_[lw]) {
            lvisit_[lw] = run;
            ldist_[lw] = nd;
            lprev_[lw] = u;
            q.push({nd, w});
          }
        }
      }
    }
    return reached;
  }

  // Splits patch p along a shortest interior path between two boundary vertices so that both
  // halves have minSides..maxSides sides (or at least fewer than p). Tries, in order: corner to
  // corner; corner to any boundary vertex; any boundary vertex to any. A non-corner endpoint
  // becomes a corner (the neighbour across gains a side; its patches are queued in `touched`).
  // Returns the new patch (p keeps the other half), or kNone if no cut was found.
  uint32_t split(uint32_t p, const std::vector<uint32_t>& loop, std::vector<uint32_t>& touched) {
    numberLocal(p);
    const uint32_t q = splitNumbered(p, loop, touched);
    clearLocal();
    return q;
  }

  uint32_t splitNumbered(uint32_t p, const std::vector<uint32_t>& loop,
                         std::vector<uint32_t>& touched) {
    const size_t L = loop.size();
    std::vector<uint32_t> cc(2 * L + 1, 0);  // corners among loop positions [0, t)
    for (size_t t = 0; t < L; ++t) lpos_[local_[s_.origin(loop[t])]] = static_cast<uint32_t>(t);
    for (size_t t = 0; t < 2 * L; ++t) cc[t + 1] = cc[t] + corner_[s_.origin(loop[t % L])];
    const uint32_t k = cc[L];
    std::vector<uint32_t> cornerPos, allPos;
    for (size_t t = 0; t < L; ++t) {
      if (corner_[s_.origin(loop[t])]) cornerPos.push_back(static_cast<uint32_t>(t));
    }
    const size_t stride = std::max<size_t>(1, L / 64);
    for (size_t t = 0; t < L; t += stride) allPos.push_back(static_cast<uint32_t>(t));
    for (int level = 0; level < 3; ++level) {
      const std::vector<uint32_t>& starts = level < 2 ? cornerPos : allPos;
      double bestScore = std::numeric_limits<double>::infinity();
      std::vector<uint32_t> best;
      for (uint32_t i : starts) {
        const uint32_t a = s_.origin(loop[i]);
        uint32_t run = 0;
        const std::vector<uint32_t> reached = shortestFrom(p, a, run);
        for (uint32_t b : reached) {
          const uint32_t j = lpos_[local_[b]];
          if (level == 0 && !corner_[b]) continue;
          // Sides of the two halves: corners on each closed loop segment, endpoints included.
          const uint32_t i2 = i, j2 = j < i ? j + static_cast<uint32_t>(L) : j;
          const uint32_t inner1 = cc[j2] - cc[i2 + 1];
          const uint32_t inner2 = k - inner1 - corner_[a] - corner_[b];
          const uint32_t s1 = inner1 + 2, s2 = inner2 + 2;
          if (s1 < o_.minSides || s2 < o_.minSides) continue;
          const uint32_t worst = std::max(s1, s2);
          if (worst >= std::max<uint32_t>(k, o_.maxSides + 1) && worst > o_.maxSides) continue;
          const double over = worst > o_.maxSides ? double(worst - o_.maxSides) : 0.0;
          const double score = ldist_[local_[b]] * (1.0 + 0.25 * std::abs(double(s1) - double(s2))) *
                               (1.0 + 10.0 * over);
          if (score < bestScore) {
            bestScore = score;
            best.clear();
            for (uint32_t v = b; v != kNone; v = lprev_[local_[v]]) best.push_back(v);
          }
        }
      }
      if (best.size() < 2) continue;
      std::reverse(best.begin(), best.end());
      const uint32_t q = applyCut(p, best);
      if (q == kNone) continue;
      for (uint32_t v : {best.front(), best.back()}) {
        if (corner_[v]) continue;
        corner_[v] = 1;
        ++st_.cornersInserted;
        s_.facesAround(v, around_);
        for (uint32_t f : around_) touched.push_back(label_[f]);
      }
      return q;
    }
    return kNone;
  }

  uint32_t applyCut(uint32_t p, const std::vector<uint32_t>& path) {
    std::vector<uint32_t> marked;  // the path's half-edges, both directions
    uint32_t seedFace = kNone, otherFace = kNone;
    for (size_t i = 0; i + 1 < path.size(); ++i) {
      const uint32_t x = path[i], y = path[i + 1];
      s_.facesAround(x, around_);
      for (const uint32_t f : around_) {
        if (label_[f] != p) continue;
        for (uint32_t k = 0; k < 3; ++k) {
          const uint32_t h = 3 * f + k;
          if (s_.origin(h) == x && s_.dest(h) == y) {
            marked.push_back(h);
            if (seedFace == kNone) seedFace = f, otherFace = s_.twin[h] / 3;
          } else if (s_.origin(h) == y && s_.dest(h) == x) {
            marked.push_back(h);
          }
        }
      }
    }
    std::sort(marked.begin(), marked.end());
    uint32_t result = kNone;
    if (seedFace != kNone) {
      // Flood p's faces from the seed without crossing the cut; reached faces are relabelled
      // to the would-be new patch (so the label test also marks them visited).
      const auto mark = static_cast<uint32_t>(faces_.size());
      std::vector<uint32_t> stack{seedFace}, side;
      label_[seedFace] = mark;
      while (!stack.empty()) {
        const uint32_t f = stack.back();
        stack.pop_back();
        side.push_back(f);
        for (uint32_t k = 0; k < 3; ++k) {
          const uint32_t h = 3 * f + k, t = s_.twin[h];
          if (t == kNone || label_[t / 3] != p ||
              std::binary_search(marked.begin(), marked.end(), h))
            continue;
          label_[t / 3] = mark;
          stack.push_back(t / 3);
        }
      }
      if (label_[otherFace] != mark && side.size() < faces_[p].size()) {
        result = mark;
        faces_.emplace_back();
        faces_[result] = std::move(side);
        std::vector<uint32_t> rest;
        for (uint32_t f : faces_[p])
          if (label_[f] == p) rest.push_back(f);
        faces_[p] = std::move(rest);
      } else {
        for (uint32_t f : side) label_[f] = p;
      }
    }
    return result;
  }

  const Surface& s_;
  const ChartingOptions& o_;
  ChartingStats& st_;
  std::vector<uint32_t> label_;
  std::vector<std::vector<uint32_t>> faces_;
  std::vector<uint8_t> corner_;
  // split()'s work arrays: local_ maps a vertex to its index in the patch being split (kNone
  // elsewhere); the l* arrays are indexed by that.
  std::vector<uint32_t> local_, lverts_, lprev_, lvisit_, lpos_, around_;
  std::vector<double> ldist_;
  uint32_t lrun_ = 0, unfixed_ = 0;
};

// Fills the final statistics from the layout's patches.
void finishStats(const Surface& s, const ChartLayout& out,
                 const Frame& fr, ChartingStats& st) {
  st.outputTriangles = s.tris.size();
  st.outputVertices = s.positions.size();
  st.charts = static_cast<uint32_t>(out.patches.size());
  st.sidesHistogram.assign(1, 0);
  auto npos = [&](uint32_t v) { return (glm::dvec3(s.positions[v]) - fr.centre) / fr.diag; };
  double sum = 0, area = 0;
  st.maxPlanarityError = 0;
  for (const Patch& p : out.patches) {
    const size_t n = p.sides.size();
    if (st.sidesHistogram.size() <= n) st.sidesHistogram.resize(n + 1, 0);
    ++st.sidesHistogram[n];
    Moments M;
    for (uint32_t f : p.triangles)
      M.add(triangleMoments(npos(s.tris[f][0]), npos(s.tris[f][1]), npos(s.tris[f][2])));
    const double rms = std::sqrt(planeMsd(M));
    st.maxPlanarityError = std::max(st.maxPlanarityError, rms);
    sum += rms * M.area;
    area += M.area;
  }
  st.meanPlanarityError = area > 0 ? sum / area : 0;
}

// Consumes the surface: its positions, colours and triangles move into the layout.
ChartLayout layoutFromLabels(Surface& s, std::vector<uint32_t> labels,
                             const Frame& fr, const ChartingOptions& o, ChartingStats& st,
                             size_t clusterBytes) {
  const auto t0 = Clock::now();
  ChartLayout out;
  {
    LayoutBuilder lb(s, std::move(labels), o, st);
    lb.fix();
    out = lb.output();
    st.peakBytesEstimate =
        std::max<uint64_t>(st.peakBytesEstimate, s.bytes() + std::max(clusterBytes, lb.bytes()));
    st.patchesUnfixed = lb.unfixed();
  }
  finishStats(s, out, fr, st);
  out.positions = std::move(s.positions);
  out.colours = std::move(s.colours);
  out.triangles = std::move(s.tris);
  st.sidesSeconds += since(t0);
  return out;
}

}  // namespace

namespace {

// Faces of a block of a Surface as a Surface of its own (edges to other blocks open; vertex
// identity kept, so a closed disk there is a closed disk in the whole surface).
// faceLocal: each face's index in its block.
Surface subSurface(const Surface& s, const std::vector<uint32_t>& faces,
                   const std::vector<uint32_t>& faceBlock, const std::vector<uint32_t>& faceLocal,
                   uint32_t block) {
  Surface r;
  std::vector<uint32_t> verts;
  verts.reserve(faces.size() * 3);
  for (uint32_t f : faces)
    for (uint32_t v : s.tris[f]) verts.push_back(v);
  std::sort(verts.begin(), verts.end());
  verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
  auto local = [&](uint32_t v) {
    return static_cast<uint32_t>(std::lower_bound(verts.begin(), verts.end(), v) - verts.begin());
  };
  r.positions.resize(verts.size());
  for (size_t i = 0; i < verts.size(); ++i) r.positions[i] = s.positions[verts[i]];
  r.tris.resize(faces.size());
  r.twin.assign(faces.size() * 3, kNone);
  for (size_t i = 0; i < faces.size(); ++i) {
    const uint32_t f = faces[i];
    for (uint32_t k = 0; k < 3; ++k) {
      r.tris[i][k] = local(s.tris[f][k]);
      const uint32_t t = s.twin[3 * f + k];
      if (t != kNone && faceBlock[t / 3] == block) r.twin[3 * i + k] = 3 * faceLocal[t / 3] + t % 3;
    }
  }
  const uint32_t nv = static_cast<uint32_t>(verts.size());
  r.vfStart.assign(size_t{nv} + 1, 0);
  for (const auto& t : r.tris)
    for (uint32_t v : t) ++r.vfStart[v + 1];
  for (uint32_t v = 0; v < nv; ++v) r.vfStart[v + 1] += r.vfStart[v];
  r.vfFaces.resize(r.tris.size() * 3);
  std::vector<uint32_t> fill(r.vfStart.begin(), r.vfStart.end() - 1);
  for (uint32_t f = 0; f < r.tris.size(); ++f)
    for (uint32_t v : r.tris[f]) r.vfFaces[fill[v]++] = f;
  return r;
}

// Per-cell clusters of about `clusterTris` triangles (error mode: within maxRms too).
double cellClusterTriangles(const ChartingOptions& o, uint64_t triangles) {
  return o.targetCharts > 0
             ? std::clamp(double(triangles) / (4.0 * o.targetCharts), 1.0, 4096.0)
             : 1024.0;
}

unsigned threadCount(const ChartingOptions& o) {
  return o.threads ? o.threads : static_cast<unsigned>(tbb::this_task_arena::max_concurrency());
}

// Meshes above this many triangles are clustered in spatial blocks first (like the cells of
// buildChartLayoutFromCells): same or better charts, several times faster (small heaps).
constexpr uint64_t kBlockedAbove = 32768;
constexpr uint32_t kBlockTriangles = 8192;

// Initial labels for the global merge: each block of the surface clustered on its own.
std::vector<uint32_t> blockLabels(const Surface& s, const Frame& fr, const ChartingOptions& o,
                                  ChartingStats& st, size_t& peakBytes) {
  const uint32_t nf = static_cast<uint32_t>(s.tris.size());
  MeshBounds bounds;
  for (const glm::vec3& p : s.positions) bounds.extend(p);
  const std::array<uint32_t, 3> dims = chooseGridDims(bounds, nf, kBlockTriangles);
  GridManifest grid;
  grid.dims = dims;
  for (int a = 0; a < 3; ++a) {
    grid.origin[a] = bounds.min[a];
    grid.cellSize[a] = std::max((double(bounds.max[a]) - bounds.min[a]) / dims[a], 1e-30);
  }
  std::vector<uint32_t> faceBlock(nf), faceLocal(nf);
  std::unordered_map<uint32_t, uint32_t> blockIndex;
  std::vector<std::vector<uint32_t>> blocks;
  for (uint32_t f = 0; f < nf; ++f) {
    MeshTriangle t;
    for (int k = 0; k < 3; ++k) t.p[k] = s.positions[s.tris[f][k]];
    const uint32_t id = grid.cellId(grid.cellOf(t));
    auto [it, added] = blockIndex.try_emplace(id, static_cast<uint32_t>(blocks.size()));
    if (added) blocks.emplace_back();
    faceBlock[f] = it->second;
    faceLocal[f] = static_cast<uint32_t>(blocks[it->second].size());
    blocks[it->second].push_back(f);
  }
  const double clusterTris = cellClusterTriangles(o, nf);
  const double maxRms =
      o.targetCharts > 0 ? std::numeric_limits<double>::infinity() : o.maxError;
  std::vector<std::vector<uint32_t>> local(blocks.size());
  std::vector<uint32_t> clusters(blocks.size(), 0);
  std::vector<size_t> bytes(blocks.size(), 0);
  tbb::task_arena arena(static_cast<int>(std::max(1u, threadCount(o))));
  arena.execute([&] {
    tbb::parallel_for(size_t{0}, blocks.size(), [&](size_t b) {
      const Surface sub =
          subSurface(s, blocks[b], faceBlock, faceLocal, static_cast<uint32_t>(b));
      std::vector<uint32_t> labels(sub.tris.size());
      std::iota(labels.begin(), labels.end(), 0u);
      Clusterer cl(sub, fr, std::move(labels));
      const auto target = static_cast<uint32_t>(std::ceil(double(sub.tris.size()) / clusterTris));
      cl.run(std::max(1u, target), maxRms, o.compactnessWeight);
      clusters[b] = cl.alive();
      bytes[b] = sub.bytes() + cl.bytes();
      local[b] = cl.labels();
    });
  });
  std::vector<uint32_t> labels(nf);
  uint32_t offset = 0;
  for (size_t b = 0; b < blocks.size(); ++b) {
    for (size_t i = 0; i < blocks[b].size(); ++i) labels[blocks[b][i]] = offset + local[b][i];
    offset += static_cast<uint32_t>(blocks[b].size());  // local labels are face indices
    st.cellClusters += clusters[b];
    peakBytes = std::max(peakBytes, bytes[b] * std::max(1u, threadCount(o)));
  }
  st.cells = static_cast<uint32_t>(blocks.size());
  return labels;
}

}  // namespace

ChartLayout buildChartLayout(const IndexedMesh& mesh, const ChartingOptions& options,
                             ChartingStats* statsOut) {
  const auto t0 = Clock::now();
  checkOptions(options);
  ChartingStats st;
  if (!mesh.colours.empty() && mesh.colours.size() != mesh.positions.size())
    throw InputError("buildChartLayout: colours must be empty or one per position");
  Surface s = weldAndRepair(mesh.positions, mesh.colours, mesh.triangles, st);
  const Frame fr = frameOf(s.positions);
  st.weldSeconds = since(t0);
  const auto t1 = Clock::now();
  std::vector<uint32_t> labels(s.tris.size());
  std::iota(labels.begin(), labels.end(), 0u);
  size_t blockBytes = 0;
  if (s.tris.size() > kBlockedAbove) {
    labels = blockLabels(s, fr, options, st, blockBytes);
    st.cellSeconds = since(t1);
  }
  std::optional<Clusterer> cl(std::in_place, s, fr, std::move(labels));
  cl->run(options.targetCharts,
          options.targetCharts > 0 ? std::numeric_limits<double>::infinity() : options.maxError,
          options.compactnessWeight);
  st.clusterSeconds = since(t1);
  st.chartsBeforeFixing = cl->alive();
  st.mergesRefusedNotDisk = cl->refused();
  st.peakBytesEstimate = s.bytes() + blockBytes;
  // The clusterer goes before the sides are fixed.
  const size_t clusterBytes = cl->bytes();
  std::vector<uint32_t> finalLabels = cl->takeLabels();
  cl.reset();
  ChartLayout out = layoutFromLabels(s, std::move(finalLabels), fr, options, st, clusterBytes);
  st.seconds = since(t0);
  if (statsOut) *statsOut = std::move(st);
  return out;
}

ChartLayout buildChartLayoutFromCells(const std::filesystem::path& gridDir,
                                      const ChartingOptions& options, ChartingStats* statsOut) {
  const auto t0 = Clock::now();
  checkOptions(options);
  releaseFreedMemory();  // whatever the caller freed before (gridify's cell buffers)
  const GridManifest manifest = readGridManifest(gridDir);
  ChartingStats st;
  st.cells = static_cast<uint32_t>(manifest.cells.size());
  // Frame of the whole mesh, so that per-cell errors are in the global units.
  Frame fr;
  if (!manifest.bounds.empty()) {
    const glm::dvec3 lo(manifest.bounds.min), hi(manifest.bounds.max);
    fr.centre = 0.5 * (lo + hi);
    fr.diag = glm::length(hi - lo);
    if (!(fr.diag > 0)) fr.diag = 1;
  }
  const uint64_t total = std::max<uint64_t>(manifest.triangles, 1);
  // Cell clusters of about a quarter of the final chart size (error mode: 1024 triangles).
  const double clusterTris =
      options.targetCharts > 0
          ? std::clamp(double(total) / (4.0 * options.targetCharts), 1.0, 4096.0)
          : 1024.0;
  const double maxRms =
      options.targetCharts > 0 ? std::numeric_limits<double>::infinity() : options.maxError;

  // Each cell hands on its welded vertices and kept triangles (an indexed mesh: about a sixth
  // of the bytes of the 3 corners per triangle of the cell file), with a cluster per triangle.
  struct CellResult {
    std::vector<glm::vec3> pos;  // the cell's welded (and fan-split) vertices
    std::vector<glm::u8vec4> col;
    std::vector<std::array<uint32_t, 3>> tris;  // kept triangles, in cell-file order
    std::vector<uint32_t> label;  // cell-local cluster per kept triangle
    uint32_t clusters = 0;
    ChartingStats st;
    size_t bytes = 0;
  };
  std::vector<CellResult> cells(manifest.cells.size());
  const auto tCells = Clock::now();
  const unsigned threads =
      options.threads ? options.threads
                      : static_cast<unsigned>(tbb::this_task_arena::max_concurrency());
  tbb::task_arena arena(static_cast<int>(std::max(1u, threads)));
  // Largest cells first, one task each, so that no large cell is left to run alone at the end.
  std::vector<uint32_t> order(manifest.cells.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    return manifest.cells[a].triangles > manifest.cells[b].triangles;
  });
  auto clusterCell = [&](size_t ci) {
    CellResult& r = cells[ci];
    Surface s;
    {
      // Every corner of the cell file is an input position of its own; the weld joins them.
      const std::vector<MeshTriangle> tris = readCell(gridDir, manifest, manifest.cells[ci]);
      if (tris.empty()) return;
      Welder w(tris.size() * 3);
      w.tris.reserve(tris.size());
      for (const MeshTriangle& t : tris) {
        std::array<uint32_t, 3> idx;
        for (int k = 0; k < 3; ++k) {
          const glm::vec3& p = t.p[k];
          if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
            return;  // as weldAndRepair would refuse it: nothing from this cell
          idx[k] = w.add(p, manifest.hasColours ? &t.c[k] : nullptr);
        }
        w.tris.push_back(idx);
      }
      try {
        s = repairWelded(std::move(w), r.st);
      } catch (const InputError&) {
        return;  // every triangle degenerate: nothing from this cell
      }
    }
    std::vector<uint32_t> labels(s.tris.size());
    std::iota(labels.begin(), labels.end(), 0u);
    Clusterer cl(s, fr, std::move(labels));
    const auto target = static_cast<uint32_t>(std::ceil(double(s.tris.size()) / clusterTris));
    cl.run(std::max(1u, target), maxRms, options.compactnessWeight);
    r.clusters = cl.alive();
    r.bytes = s.bytes() + cl.bytes();
    // Hand on the kept triangles with their cluster (compact ids). The global weld joins
    // equal positions again, so vertices split here by the repair are welded back there.
    std::vector<uint32_t> compact(s.tris.size(), kNone);
    uint32_t next = 0;
    r.label.reserve(s.tris.size());
    for (size_t f = 0; f < s.tris.size(); ++f) {
      uint32_t& c = compact[cl.labels()[f]];
      if (c == kNone) c = next++;
      r.label.push_back(c);
    }
    r.pos = std::move(s.positions);
    r.col = std::move(s.colours);
    r.tris = std::move(s.tris);
  };
  arena.execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, order.size(), 1),
        [&](const tbb::blocked_range<size_t>& range) {
          for (size_t i = range.begin(); i != range.end(); ++i) clusterCell(order[i]);
        },
        tbb::simple_partitioner());
  });
  st.clusterSeconds = since(tCells);
  st.cellSeconds = st.clusterSeconds;
  // Global stage: weld all cells together, a cell at a time (each freed once welded, so the
  // cells' vertices and the welded ones are never all held at once); start from the cell
  // clusters.
  const auto tWeld = Clock::now();
  size_t cellPeak = 0, cellVertices = 0, cellTriangles = 0;
  for (const CellResult& r : cells) {
    cellVertices += r.pos.size();
    cellTriangles += r.tris.size();
  }
  ChartingStats gst;
  Surface s;
  std::vector<uint32_t> labels;  // cell cluster of each triangle, then of each kept triangle
  {
    Welder w(cellVertices);
    w.positions.reserve(cellVertices);
    if (manifest.hasColours) w.colours.reserve(cellVertices);
    w.tris.reserve(cellTriangles);
    labels.reserve(cellTriangles);
    uint32_t offset = 0;
    std::vector<uint32_t> remap;
    for (CellResult& r : cells) {
      st.inputTriangles += r.st.inputTriangles;
      st.inputVertices += r.st.inputVertices;
      st.droppedDegenerate += r.st.droppedDegenerate;
      st.droppedDuplicate += r.st.droppedDuplicate;
      cellPeak = std::max(cellPeak, r.bytes);
      remap.assign(r.pos.size(), kNone);
      for (size_t i = 0; i < r.tris.size(); ++i) {
        std::array<uint32_t, 3> t;
        for (int k = 0; k < 3; ++k) {
          const uint32_t v = r.tris[i][k];
          if (remap[v] == kNone) remap[v] = w.add(r.pos[v], manifest.hasColours ? &r.col[v] : nullptr);
          t[k] = remap[v];
        }
        w.tris.push_back(t);
        labels.push_back(offset + r.label[i]);
      }
      offset += r.clusters;
      st.cellClusters += r.clusters;
      r = CellResult{};
    }
    std::vector<CellResult>().swap(cells);
    releaseFreedMemory();
    s = repairWelded(std::move(w), gst, &labels);
  }
  // Corners of the cell files in, vertices of the global weld out (cell welds included).
  st.verticesWelded = st.inputVertices - (gst.inputVertices - gst.verticesWelded);
  st.nonManifoldEdges = gst.nonManifoldEdges;
  st.nonManifoldVertices = gst.nonManifoldVertices;
  st.verticesSplit = gst.verticesSplit;
  st.boundaryEdges = gst.boundaryEdges;
  st.droppedDegenerate += gst.droppedDegenerate;
  st.droppedDuplicate += gst.droppedDuplicate;
  st.weldSeconds = since(tWeld);
  const auto t1 = Clock::now();
  std::optional<Clusterer> cl(std::in_place, s, fr, std::move(labels));
  if (cl->dissolveNonDisks(st.cellClustersDissolved)) cl.emplace(s, fr, cl->takeLabels());
  cl->run(options.targetCharts, maxRms, options.compactnessWeight);
  st.clusterSeconds += since(t1);
  st.chartsBeforeFixing = cl->alive();
  st.mergesRefusedNotDisk = cl->refused();
  st.peakBytesEstimate = cellPeak * std::max(1u, threads);
  // The clusterer goes before the sides are fixed.
  const size_t clusterBytes = cl->bytes();
  std::vector<uint32_t> finalLabels = cl->takeLabels();
  cl.reset();
  ChartLayout out = layoutFromLabels(s, std::move(finalLabels), fr, options, st, clusterBytes);
  st.inputTriangles = manifest.triangles;
  st.seconds = since(t0);
  if (statsOut) *statsOut = std::move(st);
  return out;
}

std::vector<std::string> validateChartLayout(const ChartLayout& L, uint32_t minSides,
                                             uint32_t maxSides) {
  std::vector<std::string> errs;
  auto addErr = [&](const std::string& m) {
    if (errs.size() < 100) errs.push_back(m);
  };
  const size_t nv = L.positions.size(), nt = L.triangles.size();
  if (!L.colours.empty() && L.colours.size() != nv) addErr("colours: not one per position");
  for (size_t f = 0; f < nt; ++f)
    for (uint32_t v : L.triangles[f])
      if (v >= nv) {
        addErr("triangle " + std::to_string(f) + ": vertex out of range");
        return errs;
      }
  // Global use counts (undirected) of the edges of open sides only: the one global check.
  auto key = [](uint32_t a, uint32_t b) { return uint64_t{std::min(a, b)} << 32 | std::max(a, b); };
  std::unordered_map<uint64_t, uint32_t> edgeUse;
  for (const Patch& P : L.patches)
    for (const PatchSide& S : P.sides)
      if (S.neighbourPatch < 0)
        for (size_t i = 0; i + 1 < S.vertices.size(); ++i) edgeUse[key(S.vertices[i], S.vertices[i + 1])] = 0;
  if (!edgeUse.empty())
    for (const auto& t : L.triangles)
      for (int k = 0; k < 3; ++k) {
        const auto it = edgeUse.find(key(t[k], t[(k + 1) % 3]));
        if (it != edgeUse.end()) ++it->second;
      }
  std::vector<int32_t> owner(nt, -1);
  for (size_t p = 0; p < L.patches.size(); ++p) {
    for (uint32_t f : L.patches[p].triangles) {
      if (f >= nt) {
        addErr("patch " + std::to_string(p) + ": triangle index out of range");
        continue;
      }
      if (owner[f] >= 0)
        addErr("triangle " + std::to_string(f) + ": in patches " + std::to_string(owner[f]) +
             " and " + std::to_string(p));
      owner[f] = static_cast<int32_t>(p);
    }
  }
  for (size_t f = 0; f < nt; ++f)
    if (owner[f] < 0) addErr("triangle " + std::to_string(f) + ": in no patch");
  std::vector<int32_t>().swap(owner);
  // Patches are checked in parallel, each into its own list; the lists are joined in order.
  std::vector<std::vector<std::string>> patchErrs(L.patches.size());
  tbb::parallel_for(size_t{0}, L.patches.size(), [&](size_t pi) {
    std::vector<std::string>& pe = patchErrs[pi];
    auto fail = [&](const std::string& m) {
      if (pe.size() < 100) pe.push_back(m);
    };
    const Patch& P = L.patches[pi];
    const std::string name = "patch " + std::to_string(pi);
    if (P.triangles.empty()) {
      fail(name + ": no triangles");
      return;
    }
    // Directed edges inside the patch; boundary = directed edges whose reverse is absent.
    std::unordered_map<uint64_t, uint32_t> directed;  // (a<<32|b) -> count
    std::unordered_map<uint32_t, uint32_t> verts;
    for (uint32_t f : P.triangles) {
      if (f >= nt) continue;
      const auto& t = L.triangles[f];
      for (int k = 0; k < 3; ++k) {
        ++directed[uint64_t{t[k]} << 32 | t[(k + 1) % 3]];
        verts[t[k]] = 0;
      }
    }
    std::unordered_map<uint32_t, uint32_t> nextB;  // boundary: origin -> dest
    size_t undirected2 = 0, bcount = 0;
    bool bad = false;
    for (const auto& [k, c] : directed) {
      if (c > 1) bad = true;
      const uint32_t a = static_cast<uint32_t>(k >> 32), b = static_cast<uint32_t>(k);
      const bool hasRev = directed.count(uint64_t{b} << 32 | a) > 0;
      undirected2 += hasRev ? 1 : 2;
      if (!hasRev) {
        ++bcount;
        if (!nextB.emplace(a, b).second) bad = true;  // vertex on the loop twice
      }
    }
    if (bad) fail(name + ": repeated directed edge or boundary vertex visited twice");
    const int64_t chi = int64_t(verts.size()) - int64_t(undirected2 / 2) + int64_t(P.triangles.size());
    if (chi != 1) fail(name + ": Euler characteristic " + std::to_string(chi) + ", not 1");
    // One loop.
    if (nextB.empty()) {
      fail(name + ": no boundary");
      return;
    }
    {
      uint32_t v = nextB.begin()->first;
      size_t len = 0;
      do {
        auto it = nextB.find(v);
        if (it == nextB.end()) break;
        v = it->second;
        ++len;
      } while (v != nextB.begin()->first && len <= bcount);
      if (len != bcount) fail(name + ": boundary is not a single loop");
    }
    if (P.sides.size() < minSides || P.sides.size() > maxSides)
      fail(name + ": " + std::to_string(P.sides.size()) + " sides");
    // Sides chain along the loop.
    size_t covered = 0;
    for (size_t si = 0; si < P.sides.size(); ++si) {
      const PatchSide& S = P.sides[si];
      const std::string sn = name + " side " + std::to_string(si);
      if (S.vertices.size() < 2) {
        fail(sn + ": fewer than 2 vertices");
        continue;
      }
      const PatchSide& N = P.sides[(si + 1) % P.sides.size()];
      if (!N.vertices.empty() && N.vertices.front() != S.vertices.back())
        fail(sn + ": does not end where the next side starts");
      for (size_t i = 0; i + 1 < S.vertices.size(); ++i) {
        auto it = nextB.find(S.vertices[i]);
        if (it == nextB.end() || it->second != S.vertices[i + 1]) {
          fail(sn + ": edge " + std::to_string(i) + " is not a boundary edge in loop order");
          break;
        }
        ++covered;
        if (S.neighbourPatch < 0 && edgeUse.at(key(S.vertices[i], S.vertices[i + 1])) != 1)
          fail(sn + ": open side on an interior edge");
      }
      if (S.neighbourPatch >= 0) {
        if (size_t(S.neighbourPatch) >= L.patches.size() ||
            S.neighbourSide >= L.patches[S.neighbourPatch].sides.size()) {
          fail(sn + ": neighbour out of range");
          continue;
        }
        const PatchSide& O = L.patches[S.neighbourPatch].sides[S.neighbourSide];
        if (O.neighbourPatch != int32_t(pi) || O.neighbourSide != si)
          fail(sn + ": neighbour side does not point back");
        std::vector<uint32_t> rev(S.vertices.rbegin(), S.vertices.rend());
        if (O.vertices != rev || !S.reversed) fail(sn + ": neighbour vertices not reversed");
      }
    }
    if (covered != bcount) fail(name + ": sides do not cover the boundary loop exactly");
  });
  for (const auto& pe : patchErrs)
    for (const std::string& m : pe) addErr(m);
  return errs;
}

}  // namespace gimlod

// Face clustering into a conforming layout of n-sided disk patches.
// Based on: Garland, Willmott, Heckbert, "Hierarchical Face Clustering on Polygonal Surfaces",
// I3D 2001 (dual-edge collapse, plane-fit quadric, compactness); Niski, Purnomo, Cohen, I3D
// 2007, section 5 (per-cell then global clustering); Purnomo, Cohen, Kumar, SGP 2004 (patches).
#include "atlas/mesh/charting.h"
#include "atlas/mesh/portable_math.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <numeric>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "atlas/mesh/charting_internal.h"
#include "atlas/mesh/gridify.h"
#include "core/stage_meter.h"

namespace gimlod {

using namespace charting;

namespace {

constexpr double kPi = 3.14159265358979323846;
// Planarity unit of the merge cost: 1% of the bounding-box diagonal (a mean squared plane
// distance of kTau^2 costs as much as a perfect disc's compactness at weight 1).
constexpr double kTau = 0.01;
// Weight of the normal-spread term 1 - |sum of area-weighted normals| / area (0 flat, 1 folded
// shut); it keeps clusters from wrapping round thin parts, where the plane fit alone is small.
constexpr double kNormalWeight = 4.0;
// ChartMetric::kDevelopable: the unit of the cone-fit variance (coneFitVariance; 0.01 is a normal
// spread of about 0.1 rad off the best cone), and the spread's weight beside it (lower than
// kNormalWeight: a half cylinder, spread 0.36, is fine; it still keeps clusters from closing round
// a thin part, whose normals lie on a great circle and so fit a cone).
constexpr double kConeUnit = 0.01;
constexpr double kDevelopableSpreadWeight = 1.0;

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
  const double det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02);
  const double r = std::clamp(det / 2.0, -1.0, 1.0);
  const double phi = pmath::acos(r) / 3.0;
  return q + 2.0 * p * pmath::cos(phi + 2.0 * kPi / 3.0);
}

}  // namespace

namespace charting {

Moments triangleMoments(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  Moments r;
  const glm::dvec3 e1 = b - a, e2 = c - a;
  const glm::dvec3 cr{e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x};
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
    if (A > 0) r.nn[k] = r.n[ij[k][0]] * r.n[ij[k][1]] / A;
  }
  return r;
}

namespace {

// The least variance along an axis of a quantity whose area-weighted first and second moments
// (sum of A x, sum of A x x^T as xx xy xz yy yz zz) over `area` are given.
double leastVariance(const double first[3], const double second[6], double area) {
  if (area <= 0) return 0;
  double c[6];
  const int ij[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  for (int k = 0; k < 6; ++k) c[k] = second[k] - first[ij[k][0]] * first[ij[k][1]] / area;
  return std::max(0.0, minEigenvalue(c) / area);
}

}  // namespace

double planeMsd(const Moments& M) { return leastVariance(M.m, M.s, M.area); }

double coneFitVariance(const Moments& M) { return leastVariance(M.n, M.nn, M.area); }

}  // namespace charting

namespace {

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
  void run(uint32_t target, double maxRms, double weight, ChartMetric metric) {
    weight_ = weight;
    metric_ = metric;
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
    if (static_cast<int64_t>(V) - static_cast<int64_t>(E2 / 2) + static_cast<int64_t>(F) != 1) return false;
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
    return mom_.size() * (sizeof(Moments) + 8 + 4 + 4 + 4 + 4 + sizeof(std::vector<Adj>)) + nextFace_.size() * 8 +
           heapPeak_ * sizeof(Cand) + vstamp_.size() * 4;
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
  double edgeLength(uint32_t h) const { return glm::length(npos(s_.origin(h)) - npos(s_.dest(h))); }
  glm::dvec3 npos(uint32_t v) const { return (glm::dvec3(s_.positions[v]) - fr_.centre) / fr_.diag; }

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
    const double shape = metric_ == ChartMetric::kDevelopable
                             ? coneFitVariance(M) / kConeUnit + kDevelopableSpreadWeight * spread
                             : msd / (kTau * kTau) + kNormalWeight * spread;
    const double cost = (area / totalArea_) * (shape + weight_ * compact);
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
  ChartMetric metric_ = ChartMetric::kPlanar;
};

void checkOptions(const ChartingOptions& o) {
  const char* fn = "charting options";
  if (o.minSides < 3) throw InputError(std::string(fn) + ": minSides must be at least 3");
  if (o.maxSides < std::max(4u, 2 * o.minSides - 3))
    throw InputError(std::string(fn) + ": maxSides must be at least max(4, 2 * minSides - 3)");
  if (o.targetPatches == 0 && !(o.maxError > 0 && std::isfinite(o.maxError)))
    throw InputError(std::string(fn) + ": maxError must be positive when targetPatches is 0");
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

// Faces of a block of a Surface as a Surface of its own (edges to other blocks open; vertex
// identity kept, so a closed disk there is a closed disk in the whole surface).
// faceLocal: each face's index in its block.
Surface subSurface(const Surface& s, const std::vector<uint32_t>& faces, const std::vector<uint32_t>& faceBlock,
                   const std::vector<uint32_t>& faceLocal, uint32_t block) {
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
  return o.targetPatches > 0 ? std::clamp(double(triangles) / (4.0 * o.targetPatches), 1.0, 4096.0) : 1024.0;
}

unsigned threadCount(const ChartingOptions& o) {
  return o.threads ? o.threads : static_cast<unsigned>(tbb::this_task_arena::max_concurrency());
}

// Meshes above this many triangles are clustered in spatial blocks first (like the cells of
// buildPatchLayoutFromCells): same or better charts, several times faster (small heaps).
constexpr uint64_t kBlockedAbove = 32768;
constexpr uint32_t kBlockTriangles = 8192;

// Initial labels for the global merge: each block of the surface clustered on its own.
std::vector<uint32_t> blockLabels(const Surface& s, const Frame& fr, const ChartingOptions& o, ChartingStats& st,
                                  size_t& peakBytes) {
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
  const double maxRms = o.targetPatches > 0 ? std::numeric_limits<double>::infinity() : o.maxError;
  std::vector<std::vector<uint32_t>> local(blocks.size());
  std::vector<uint32_t> clusters(blocks.size(), 0);
  std::vector<size_t> bytes(blocks.size(), 0);
  tbb::task_arena arena(static_cast<int>(std::max(1u, threadCount(o))));
  arena.execute([&] {
    tbb::parallel_for(size_t{0}, blocks.size(), [&](size_t b) {
      const Surface sub = subSurface(s, blocks[b], faceBlock, faceLocal, static_cast<uint32_t>(b));
      std::vector<uint32_t> labels(sub.tris.size());
      std::iota(labels.begin(), labels.end(), 0u);
      Clusterer cl(sub, fr, std::move(labels));
      const auto target = static_cast<uint32_t>(std::ceil(double(sub.tris.size()) / clusterTris));
      cl.run(std::max(1u, target), maxRms, o.compactnessWeight, o.metric);
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

PatchLayout buildPatchLayout(const IndexedMesh& mesh, const ChartingOptions& options, ChartingStats* statsOut) {
  const auto t0 = Clock::now();
  checkOptions(options);
  ChartingStats st;
  if (!mesh.colours.empty() && mesh.colours.size() != mesh.positions.size())
    throw InputError("buildPatchLayout: colours must be empty or one per position");
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
  cl->run(options.targetPatches, options.targetPatches > 0 ? std::numeric_limits<double>::infinity() : options.maxError,
          options.compactnessWeight, options.metric);
  st.clusterSeconds = since(t1);
  st.chartsBeforeFixing = cl->alive();
  st.mergesRefusedNotDisk = cl->refused();
  st.peakBytesEstimate = s.bytes() + blockBytes;
  // The clusterer goes before the sides are fixed.
  const size_t clusterBytes = cl->bytes();
  std::vector<uint32_t> finalLabels = cl->takeLabels();
  cl.reset();
  PatchLayout out = layoutFromLabels(s, std::move(finalLabels), fr, options, st, clusterBytes);
  st.seconds = since(t0);
  if (statsOut) *statsOut = std::move(st);
  return out;
}

PatchLayout buildPatchLayoutFromCells(const std::filesystem::path& gridDir, const ChartingOptions& options,
                                      ChartingStats* statsOut) {
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
      options.targetPatches > 0 ? std::clamp(double(total) / (4.0 * options.targetPatches), 1.0, 4096.0) : 1024.0;
  const double maxRms = options.targetPatches > 0 ? std::numeric_limits<double>::infinity() : options.maxError;

  // Each cell hands on its welded vertices and kept triangles (an indexed mesh: about a sixth
  // of the bytes of the 3 corners per triangle of the cell file), with a cluster per triangle.
  struct CellResult {
    std::vector<glm::vec3> pos;  // the cell's welded (and fan-split) vertices
    std::vector<glm::u8vec4> col;
    std::vector<std::array<uint32_t, 3>> tris;  // kept triangles, in cell-file order
    std::vector<uint32_t> label;                // cell-local cluster per kept triangle
    uint32_t clusters = 0;
    ChartingStats st;
    size_t bytes = 0;
  };
  std::vector<CellResult> cells(manifest.cells.size());
  const auto tCells = Clock::now();
  const unsigned threads =
      options.threads ? options.threads : static_cast<unsigned>(tbb::this_task_arena::max_concurrency());
  tbb::task_arena arena(static_cast<int>(std::max(1u, threads)));
  // Largest cells first, one task each, so that no large cell is left to run alone at the end.
  std::vector<uint32_t> order(manifest.cells.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return manifest.cells[a].triangles > manifest.cells[b].triangles; });
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
    cl.run(std::max(1u, target), maxRms, options.compactnessWeight, options.metric);
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
  cl->run(options.targetPatches, maxRms, options.compactnessWeight, options.metric);
  st.clusterSeconds += since(t1);
  st.chartsBeforeFixing = cl->alive();
  st.mergesRefusedNotDisk = cl->refused();
  st.peakBytesEstimate = cellPeak * std::max(1u, threads);
  // The clusterer goes before the sides are fixed.
  const size_t clusterBytes = cl->bytes();
  std::vector<uint32_t> finalLabels = cl->takeLabels();
  cl.reset();
  PatchLayout out = layoutFromLabels(s, std::move(finalLabels), fr, options, st, clusterBytes);
  st.inputTriangles = manifest.triangles;
  st.seconds = since(t0);
  if (statsOut) *statsOut = std::move(st);
  return out;
}

}  // namespace gimlod

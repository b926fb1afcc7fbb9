// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (parameterize); Floater 2003 (mean-value
// weights); Sander et al. 2001 (stretch); Yoshizawa, Belyaev, Seidel 2004 (stretch reweighting).
#include "atlas/mesh/patch_param.h"
#include "atlas/mesh/portable_math.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <span>
#include <numbers>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include <Eigen/Sparse>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseLU>
#include <glm/geometric.hpp>
#include <spdlog/spdlog.h>

namespace gimlod {
namespace {

[[noreturn]] void fail(uint32_t patch, const std::string& what) {
  throw std::invalid_argument("parameterizePatch: patch " + std::to_string(patch) + ": " + what);
}

uint64_t edgeKey(uint32_t a, uint32_t b) { return (uint64_t{a} << 32) | b; }

// Per-triangle stretch of the map param -> surface (Sander et al. 2001), unnormalized.
struct TriangleStretch {
  double areaParam = 0.0;  // signed
  double area3D = 0.0;
  double l2sq = 0.0;     // (a + c) / 2
  double gammaSq = 0.0;  // largest singular value squared
  bool degenerate = false;
};

TriangleStretch triangleStretch(const glm::dvec2& p1, const glm::dvec2& p2, const glm::dvec2& p3, const glm::dvec3& q1,
                                const glm::dvec3& q2, const glm::dvec3& q3) {
  TriangleStretch r;
  const glm::dvec2 e1 = p2 - p1, e2 = p3 - p1;
  const double twice = e1.x * e2.y - e2.x * e1.y;
  r.areaParam = 0.5 * twice;
  const glm::dvec3 f1 = q2 - q1, f2 = q3 - q1;
  r.area3D = 0.5 * glm::length(glm::cross(f1, f2));
  const double scaleParam = glm::dot(e1, e1) + glm::dot(e2, e2);
  const double scale3D = glm::dot(f1, f1) + glm::dot(f2, f2);
  if (!(std::abs(twice) > 1e-14 * scaleParam) || !(2.0 * r.area3D > 1e-14 * scale3D)) {
    r.degenerate = true;
    return r;
  }
  const glm::dvec3 ss = (q1 * (p2.y - p3.y) + q2 * (p3.y - p1.y) + q3 * (p1.y - p2.y)) / twice;
  const glm::dvec3 st = (q1 * (p3.x - p2.x) + q2 * (p1.x - p3.x) + q3 * (p2.x - p1.x)) / twice;
  const double a = glm::dot(ss, ss), b = glm::dot(ss, st), c = glm::dot(st, st);
  r.l2sq = 0.5 * (a + c);
  r.gammaSq = 0.5 * ((a + c) + std::sqrt((a - c) * (a - c) + 4.0 * b * b));
  return r;
}

// The patch as a local triangle mesh with its boundary loop, after validation.
struct LocalPatch {
  std::vector<uint32_t> vertices;                  // local -> global
  std::vector<std::array<uint32_t, 3>> triangles;  // local ids
  std::vector<glm::dvec3> xyz;                     // per local vertex
  std::vector<uint32_t> boundary;                  // local ids, CCW, starting at corner 0
  std::vector<uint32_t> cornerIndex;               // position of corner i in boundary
};

LocalPatch buildLocalPatch(const PatchLayout& layout, uint32_t patchId) {
  if (patchId >= layout.patches.size()) fail(patchId, "no such patch");
  const Patch& patch = layout.patches[patchId];
  const uint32_t n = uint32_t(patch.sides.size());
  if (n < 3 || n > kMaxPatchSides)
    fail(patchId, std::to_string(n) + " sides (3.." + std::to_string(kMaxPatchSides) + " supported)");
  if (patch.triangles.empty()) fail(patchId, "no triangles");

  LocalPatch lp;
  const uint32_t nv = uint32_t(layout.positions.size());
  for (uint32_t t : patch.triangles) {
    if (t >= layout.triangles.size()) fail(patchId, "triangle " + std::to_string(t) + " out of range");
    for (const uint32_t v : layout.triangles[t]) {
      if (v >= nv) fail(patchId, "vertex " + std::to_string(v) + " out of range");
    }
  }
  const std::unordered_map<uint32_t, uint32_t> local = numberPatchVertices(layout, patch, lp.vertices, lp.triangles);
  for (size_t k = 0; k < lp.triangles.size(); ++k) {
    const auto& lt = lp.triangles[k];
    if (lt[0] == lt[1] || lt[1] == lt[2] || lt[0] == lt[2]) {
      fail(patchId, "triangle " + std::to_string(patch.triangles[k]) + " repeats a vertex");
    }
  }
  lp.xyz.reserve(lp.vertices.size());
  for (uint32_t v : lp.vertices) lp.xyz.emplace_back(layout.positions[v]);

  // Directed edges, sorted: each at most once (manifold, consistently oriented).
  std::vector<uint64_t> directed;
  directed.reserve(lp.triangles.size() * 3);
  for (const auto& t : lp.triangles) {
    for (int c = 0; c < 3; ++c) directed.push_back(edgeKey(t[c], t[(c + 1) % 3]));
  }
  std::sort(directed.begin(), directed.end());
  if (auto twice = std::adjacent_find(directed.begin(), directed.end()); twice != directed.end()) {
    fail(patchId, "non-manifold or inconsistently oriented edge " + std::to_string(lp.vertices[*twice >> 32]) + "-" +
                      std::to_string(lp.vertices[uint32_t(*twice)]));
  }
  const auto hasEdge = [&](uint32_t a, uint32_t b) {
    return std::binary_search(directed.begin(), directed.end(), edgeKey(a, b));
  };
  uint32_t boundaryEdges = 0;
  for (const uint64_t k : directed) {
    if (!hasEdge(uint32_t(k), uint32_t(k >> 32))) ++boundaryEdges;
  }

  // The boundary loop from the sides.
  lp.cornerIndex.resize(n);
  std::vector<uint8_t> seen(lp.vertices.size(), 0);
  for (uint32_t i = 0; i < n; ++i) {
    const PatchSide& s = patch.sides[i];
    if (s.vertices.size() < 2) fail(patchId, "side " + std::to_string(i) + " has < 2 vertices");
    if (s.vertices.back() != patch.sides[(i + 1) % n].vertices.front()) {
      fail(patchId,
           "side " + std::to_string(i) + " does not end where side " + std::to_string((i + 1) % n) + " starts");
    }
    lp.cornerIndex[i] = uint32_t(lp.boundary.size());
    for (size_t k = 0; k + 1 < s.vertices.size(); ++k) {
      auto it = local.find(s.vertices[k]);
      if (it == local.end()) {
        fail(patchId,
             "side " + std::to_string(i) + " vertex " + std::to_string(s.vertices[k]) + " is not in the patch");
      }
      if (seen[it->second]++) {
        fail(patchId, "boundary vertex " + std::to_string(s.vertices[k]) + " repeats");
      }
      lp.boundary.push_back(it->second);
    }
  }
  const size_t nb = lp.boundary.size();
  for (size_t k = 0; k < nb; ++k) {
    const uint32_t a = lp.boundary[k], b = lp.boundary[(k + 1) % nb];
    if (!hasEdge(a, b) || hasEdge(b, a)) {
      fail(patchId, "sides do not follow the boundary (edge " + std::to_string(lp.vertices[a]) + "-" +
                        std::to_string(lp.vertices[b]) + ")");
    }
  }
  if (boundaryEdges != nb) {
    fail(patchId, "not a disk: " + std::to_string(boundaryEdges) + " boundary edges, sides hold " + std::to_string(nb));
  }
  // Euler characteristic of a disk, and connectivity.
  const int64_t v = int64_t(lp.vertices.size()), f = int64_t(lp.triangles.size());
  const int64_t e = (int64_t(directed.size()) + boundaryEdges) / 2;
  if (v - e + f != 1) fail(patchId, "not a disk (Euler characteristic " + std::to_string(v - e + f) + ")");
  std::vector<uint32_t> parent(lp.vertices.size());
  for (uint32_t i = 0; i < parent.size(); ++i) parent[i] = i;
  auto find = [&](uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  uint32_t components = uint32_t(parent.size());
  for (const auto& t : lp.triangles) {
    for (int c = 0; c < 2; ++c) {
      const uint32_t a = find(t[c]), b = find(t[c + 1]);
      if (a != b) parent[a] = b, --components;
    }
  }
  if (components != 1) fail(patchId, "not connected");
  return lp;
}

// The weights to each vertex's neighbours, in compressed rows: row i's neighbours are
// j[begin[i]] .. j[begin[i + 1] - 1], sorted, with their weights in w. One array each, so a patch
// of n vertices holds about 76 n bytes of them.
struct Weights {
  std::vector<uint32_t> begin;  // one per vertex, and the end
  std::vector<uint32_t> j;
  std::vector<double> w;
};

// Where each vertex's row starts in compressed rows holding `perCorner` entries for every triangle
// corner at the vertex; one start per vertex and the end.
std::vector<uint32_t> cornerRowStarts(const LocalPatch& lp, uint32_t perCorner) {
  std::vector<uint32_t> starts(lp.vertices.size() + 1, 0);
  for (const auto& t : lp.triangles) {
    for (uint32_t v : t) starts[v + 1] += perCorner;
  }
  for (size_t v = 0; v < lp.vertices.size(); ++v) starts[v + 1] += starts[v];
  return starts;
}

// Floater's mean-value weights w_ij = (tan(a/2) + tan(b/2)) / |x_j - x_i|, from 3D angles.
Weights meanValueWeights(const LocalPatch& lp) {
  const size_t n = lp.vertices.size();
  // Each corner of a triangle gives its vertex two entries, one per neighbour in the triangle;
  // a neighbour in two triangles is listed twice and summed below.
  const std::vector<uint32_t> at = cornerRowStarts(lp, 2);
  std::vector<std::pair<uint32_t, double>> acc(at[n]);
  {
    std::vector<uint32_t> next(at.begin(), at.end() - 1);
    for (const auto& t : lp.triangles) {
      for (int c = 0; c < 3; ++c) {
        const uint32_t i = t[c], j = t[(c + 1) % 3], k = t[(c + 2) % 3];
        const glm::dvec3 e1 = lp.xyz[j] - lp.xyz[i], e2 = lp.xyz[k] - lp.xyz[i];
        const double l1 = glm::length(e1), l2 = glm::length(e2);
        const double sinPart = glm::length(glm::cross(e1, e2));
        const double denom = l1 * l2 + glm::dot(e1, e2);  // tan(theta/2) = |e1 x e2| / denom
        double tanHalf = denom > 1e-300 ? sinPart / denom : 0.0;
        if (!std::isfinite(tanHalf)) tanHalf = 0.0;
        acc[next[i]++] = {j, l1 > 0 ? tanHalf / l1 : 0.0};
        acc[next[i]++] = {k, l2 > 0 ? tanHalf / l2 : 0.0};
      }
    }
  }
  // Row by row: sorted, repeats summed in place at the row's start; then compacted.
  Weights out;
  out.begin.assign(n + 1, 0);
  for (size_t i = 0; i < n; ++i) {
    const auto first = acc.begin() + at[i], last = acc.begin() + at[i + 1];
    std::sort(first, last);
    auto kept = first;  // one past the last merged entry
    double sum = 0.0;
    for (auto e = first; e != last; ++e) {
      if (kept != first && (kept - 1)->first == e->first) {
        (kept - 1)->second += e->second;
      } else {
        *kept++ = *e;
      }
      sum += e->second;
    }
    // note: a vertex whose triangles are all degenerate in 3D has no meaningful angles; it
    // falls back to uniform (Tutte) weights, still positive.
    if (!(sum > 0.0) || !std::isfinite(sum)) {
      for (auto e = first; e != kept; ++e) e->second = 1.0;
    }
    // A tiny uniform floor keeps every weight strictly positive (slivers give tan(theta/2) = 0).
    const double floor = 1e-9 * (sum > 0 && std::isfinite(sum) ? sum / double(kept - first) : 1.0);
    for (auto e = first; e != kept; ++e) e->second = std::max(e->second, floor);
    out.begin[i + 1] = out.begin[i] + uint32_t(kept - first);
  }
  out.j.resize(out.begin[n]);
  out.w.resize(out.begin[n]);
  for (size_t i = 0; i < n; ++i) {
    for (uint32_t e = out.begin[i], k = at[i]; e < out.begin[i + 1]; ++e, ++k) {
      out.j[e] = acc[k].first;
      out.w[e] = acc[k].second;
    }
  }
  return out;
}

// Solves the barycentric system with the boundary fixed; writes interior uv.
class InteriorSolver {
 public:
  InteriorSolver(const LocalPatch& lp, const std::vector<uint8_t>& isBoundary, uint32_t singlePrecisionFrom)
      : isBoundary_(isBoundary), unknown_(lp.vertices.size(), ~0u) {
    for (uint32_t i = 0; i < lp.vertices.size(); ++i) {
      if (!isBoundary[i]) {
        unknown_[i] = uint32_t(interior_.size());
        interior_.push_back(i);
      }
    }
    single_ = interior_.size() >= singlePrecisionFrom;
  }

  // Returns false if the factorization failed.
  bool solve(const Weights& weights, std::vector<glm::dvec2>& uv) {
    const Eigen::Index m = Eigen::Index(interior_.size());
    if (m == 0) return true;
    // Rows are scaled to sum to 1, so the matrix is well conditioned whatever the weights' scale.
    // The matrix is written row by row, then copied into columns (sorted, as the LU wants them).
    Eigen::SparseMatrix<double, Eigen::RowMajor> rows(m, m);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(m, 2);
    {
      Eigen::Index entries = m;
      for (const uint32_t i : interior_) {
        for (uint32_t e = weights.begin[i]; e < weights.begin[i + 1]; ++e) entries += !isBoundary_[weights.j[e]];
      }
      rows.reserve(entries);
    }
    for (Eigen::Index r = 0; r < m; ++r) {
      const uint32_t i = interior_[size_t(r)];
      double diag = 0.0;
      for (uint32_t e = weights.begin[i]; e < weights.begin[i + 1]; ++e) diag += weights.w[e];
      rows.startVec(r);
      bool diagonalPlaced = false;
      for (uint32_t e = weights.begin[i]; e < weights.begin[i + 1]; ++e) {
        const uint32_t j = weights.j[e];
        const double w = weights.w[e] / diag;
        if (isBoundary_[j]) {
          rhs(r, 0) += w * uv[j].x;
          rhs(r, 1) += w * uv[j].y;
          continue;
        }
        const Eigen::Index c = Eigen::Index(unknown_[j]);
        if (!diagonalPlaced && c > r) {
          rows.insertBack(r, r) = 1.0;
          diagonalPlaced = true;
        }
        rows.insertBack(r, c) = -w;
      }
      if (!diagonalPlaced) rows.insertBack(r, r) = 1.0;
    }
    rows.finalize();
    // The ordered matrix only is kept through the factorization (the matrix in the patch's order
    // is freed first).
    Eigen::SparseMatrix<double> ordered;
    {
      Eigen::SparseMatrix<double> a = rows;
      rows = Eigen::SparseMatrix<double, Eigen::RowMajor>();
      a.makeCompressed();
      if (!orderFound_) {
        // The weights' pattern is the mesh's edges, so symmetric: AMD on it orders the unknowns
        // with about 0.6 times the fill of the LU's own column ordering (COLAMD), and the
        // factorization takes about half the time.
        Eigen::AMDOrdering<int> amd;
        amd(a, order_);
        orderFound_ = true;
      }
      ordered = order_.transpose() * a * order_;
    }
    const Eigen::MatrixXd b = order_.transpose() * rhs;
    Eigen::MatrixXd x;
    bool solved = single_ && solveRefined(ordered, b, x);
    if (!solved) solved = solveDouble(ordered, b, x);
    if (!solved) return false;
    const Eigen::MatrixXd inPatchOrder = order_ * x;
    for (Eigen::Index r = 0; r < m; ++r) uv[interior_[size_t(r)]] = {inPatchOrder(r, 0), inPatchOrder(r, 1)};
    return true;
  }

  size_t unknowns() const { return interior_.size(); }
  // Entries of the last factorization's L and U, and whether it was in double precision.
  uint64_t factorEntries() const { return factorEntries_; }
  bool inDouble() const { return !single_; }

 private:
  // The LU in single precision, which holds the factors in about 0.6 times the memory, then
  // iterative refinement with residuals in double precision (Wilkinson; Moler 1967): the matrix is
  // an M-matrix with rows summing to at most 1, so each step gains several digits, and the result
  // is as accurate as a double factorization's. False when the refinement stalls short of that.
  bool solveRefined(const Eigen::SparseMatrix<double>& a, const Eigen::MatrixXd& b, Eigen::MatrixXd& x) {
    const Eigen::SparseMatrix<float> af = a.cast<float>();
    if (!float_) {
      float_ = std::make_unique<Eigen::SparseLU<Eigen::SparseMatrix<float>, Eigen::NaturalOrdering<int>>>();
      float_->analyzePattern(af);
    }
    float_->factorize(af);
    if (float_->info() != Eigen::Success) return false;
    factorEntries_ = uint64_t(float_->nnzL() + float_->nnzU());
    x = Eigen::MatrixXf(float_->solve(Eigen::MatrixXf(b.cast<float>()))).cast<double>();
    double last = std::numeric_limits<double>::infinity();
    for (uint32_t step = 0; step < kRefinementSteps; ++step) {
      const Eigen::MatrixXd r = b - a * x;
      const double residual = r.cwiseAbs().maxCoeff();
      if (!std::isfinite(residual) || residual > last * 0.5) break;
      if (residual <= kResidual) return x.allFinite();
      last = residual;
      x += Eigen::MatrixXf(float_->solve(Eigen::MatrixXf(r.cast<float>()))).cast<double>();
    }
    return false;
  }

  // The LU in double precision: for a small patch, and for this and the later solves once the
  // refinement has stalled.
  bool solveDouble(const Eigen::SparseMatrix<double>& a, const Eigen::MatrixXd& b, Eigen::MatrixXd& x) {
    if (!double_) {
      single_ = false;
      float_.reset();
      double_ = std::make_unique<Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::NaturalOrdering<int>>>();
      double_->analyzePattern(a);
    }
    double_->factorize(a);
    if (double_->info() != Eigen::Success) return false;
    factorEntries_ = uint64_t(double_->nnzL() + double_->nnzU());
    x = double_->solve(b);
    return double_->info() == Eigen::Success && x.allFinite();
  }

  // Largest residual taken as solved: about what a double factorization leaves (uv lie in the
  // unit disc and the rows sum to 1).
  static constexpr double kResidual = 1e-14;
  static constexpr uint32_t kRefinementSteps = 8;

  const std::vector<uint8_t>& isBoundary_;
  std::vector<uint32_t> unknown_;
  std::vector<uint32_t> interior_;
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> order_;
  bool single_ = false;  // factored in single precision and refined
  std::unique_ptr<Eigen::SparseLU<Eigen::SparseMatrix<float>, Eigen::NaturalOrdering<int>>> float_;
  std::unique_ptr<Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::NaturalOrdering<int>>> double_;
  bool orderFound_ = false;
  uint64_t factorEntries_ = 0;
};

// Area-weighted RMS of the triangles' L2 stretch around each vertex, divided by its mean.
std::vector<double> vertexStretch(const LocalPatch& lp, const std::vector<glm::dvec2>& uv) {
  std::vector<double> num(lp.vertices.size(), 0.0), den(lp.vertices.size(), 0.0);
  for (const auto& t : lp.triangles) {
    const TriangleStretch s = triangleStretch(uv[t[0]], uv[t[1]], uv[t[2]], lp.xyz[t[0]], lp.xyz[t[1]], lp.xyz[t[2]]);
    if (s.degenerate || s.areaParam <= 0.0) continue;
    for (uint32_t v : t) {
      num[v] += s.area3D * s.l2sq;
      den[v] += s.area3D;
    }
  }
  std::vector<double> sigma(lp.vertices.size(), 0.0);
  double sum = 0.0;
  uint32_t count = 0;
  for (size_t v = 0; v < sigma.size(); ++v) {
    if (den[v] > 0.0) {
      sigma[v] = std::sqrt(num[v] / den[v]);
      sum += sigma[v];
      ++count;
    }
  }
  const double mean = count ? sum / count : 1.0;
  for (double& s : sigma) s = s > 0.0 && mean > 0.0 ? s / mean : 1.0;
  return sigma;
}

// The stretch energy of the triangles around vertex v with v at `at`, from their Gram matrices;
// infinite if a parameter triangle would flip or collapse (Sander's barrier). With `gradient`,
// also its exact derivative there.
double ringEnergy(const LocalPatch& lp, const std::vector<glm::dvec2>& uv, std::span<const uint32_t> ring, uint32_t v,
                  const glm::dvec2& at, const std::vector<TriangleGram>& grams, double k2,
                  glm::dvec2* gradient = nullptr) {
  double e = 0.0;
  if (gradient) *gradient = glm::dvec2(0.0);
  for (uint32_t t : ring) {
    const auto& tri = lp.triangles[t];
    const int moving = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
    const glm::dvec2 p0 = moving == 0 ? at : uv[tri[0]];
    const glm::dvec2 p1 = moving == 1 ? at : uv[tri[1]];
    const glm::dvec2 p2 = moving == 2 ? at : uv[tri[2]];
    glm::dvec2 g(0.0);
    e += gramStretchEnergy(grams[t], p0, p1, p2, k2, moving, gradient ? &g : nullptr);
    if (!std::isfinite(e)) return std::numeric_limits<double>::infinity();
    if (gradient) *gradient += g;
  }
  return e;
}

// Sander et al. 2001 style: per interior vertex, a line search along the negative gradient of the
// ring's stretch energy (symmetric Dirichlet or L2), never accepting a step that flips a triangle. Gauss-Seidel sweeps
// until the total energy stops dropping. Returns the sweeps run.
uint32_t optimizeStretchLocally(const LocalPatch& lp, const std::vector<uint8_t>& isBoundary,
                                const std::vector<glm::dvec2>& slide, uint32_t maxSweeps, bool symmetric,
                                std::vector<glm::dvec2>& uv) {
  // Each vertex's triangles, in compressed rows: ring v is rings[ringAt[v]] .. rings[ringAt[v + 1] - 1].
  const std::vector<uint32_t> ringAt = cornerRowStarts(lp, 1);
  std::vector<uint32_t> rings(ringAt.back());
  std::vector<TriangleGram> grams(lp.triangles.size());
  {
    std::vector<uint32_t> next(ringAt.begin(), ringAt.end() - 1);
    for (uint32_t t = 0; t < lp.triangles.size(); ++t) {
      const auto& tri = lp.triangles[t];
      grams[t] = triangleGram(lp.xyz[tri[0]], lp.xyz[tri[1]], lp.xyz[tri[2]]);
      for (uint32_t v : tri) rings[next[v]++] = t;
    }
  }
  // k^2 scales 3D lengths to the domain's (parameter area over surface area), for the symmetric
  // energy; 0 selects Sander's L2 energy.
  double k2 = 0.0;
  if (symmetric) {
    const ParamQuality q = measureStretch(uv, lp.xyz, lp.triangles);
    if (q.area3D > 0.0 && q.areaParam > 0.0) k2 = q.areaParam / q.area3D;
  }
  uint32_t sweeps = 0;
  for (; sweeps < maxSweeps; ++sweeps) {
    double before = 0.0, after = 0.0;
    for (uint32_t v = 0; v < lp.vertices.size(); ++v) {
      const bool slides = isBoundary[v] && slide[v] != glm::dvec2(0.0);
      if (isBoundary[v] && !slides) continue;
      const std::span<const uint32_t> ring(rings.data() + ringAt[v], ringAt[v + 1] - ringAt[v]);
      const glm::dvec2 p = uv[v];
      glm::dvec2 g(0.0);
      const double e0 = ringEnergy(lp, uv, ring, v, p, grams, k2, &g);
      if (slides) g = glm::dot(g, slide[v]) * slide[v];  // along its polygon edge only
      if (!std::isfinite(e0)) continue;                  // a flipped start: leave it to the counts
      before += e0;
      double scale = 0.0;  // mean distance to the ring's vertices in the parameter domain
      for (uint32_t t : ring) {
        for (uint32_t w : lp.triangles[t]) scale += glm::length(uv[w] - p);
      }
      scale /= 2.0 * double(ring.size());
      const double gl = glm::length(g);
      double best = e0;
      if (std::isfinite(gl) && gl > 0.0) {
        const glm::dvec2 d = -g / gl;
        for (double step = 0.25 * scale; step > 1e-4 * scale; step *= 0.5) {
          const glm::dvec2 q = p + d * step;
          const double e = ringEnergy(lp, uv, ring, v, q, grams, k2);
          if (e < best) {
            best = e;
            uv[v] = q;
            break;
          }
        }
      }
      after += best;
    }
    if (!(before > 0.0) || before - after < 1e-4 * before) {
      ++sweeps;
      break;
    }
  }
  return sweeps;
}

}  // namespace

TriangleGram triangleGram(const glm::dvec3& q0, const glm::dvec3& q1, const glm::dvec3& q2) {
  const glm::dvec3 e1 = q1 - q0, e2 = q2 - q0;
  const double cross = glm::length(glm::cross(e1, e2));
  return {glm::dot(e1, e1), glm::dot(e1, e2), glm::dot(e2, e2), cross * cross, 0.5 * cross};
}

// With d1, d2 the parameter edges and T = det [d1 d2], the metric's
// tr M = (g11 |d2|^2 - 2 g12 d1.d2 + g22 |d1|^2) / T^2 and det M = det G / T^2.
double gramStretchEnergy(const TriangleGram& g, const glm::dvec2& p0, const glm::dvec2& p1, const glm::dvec2& p2,
                         double k2, int moving, glm::dvec2* gradient) {
  const glm::dvec2 d1 = p1 - p0, d2 = p2 - p0;
  const double l1 = glm::dot(d1, d1), l2 = glm::dot(d2, d2), d12 = glm::dot(d1, d2);
  const double twice = d1.x * d2.y - d2.x * d1.y;
  if (!(twice > 1e-14 * (l1 + l2))) return std::numeric_limits<double>::infinity();
  const double t2 = twice * twice;
  // N = T^2 tr M; the symmetric energy is area (k2 N / T^2 + N / (k2 det G)), L2 area N / (2 T^2).
  const double n = g.g11 * l2 - 2.0 * g.g12 * d12 + g.g22 * l1;
  const double tr = n / t2;
  if (k2 > 0.0 && !(k2 * k2 * g.det / t2 > 0.0)) return std::numeric_limits<double>::infinity();
  if (gradient) {
    // d N and d T along d1 and d2; the moving corner's derivative is the one of its edge (corner 0
    // moves both edges, backwards).
    const glm::dvec2 dn1 = 2.0 * (g.g22 * d1 - g.g12 * d2), dn2 = 2.0 * (g.g11 * d2 - g.g12 * d1);
    const glm::dvec2 dt1(d2.y, -d2.x), dt2(-d1.y, d1.x);
    const glm::dvec2 dn = moving == 1 ? dn1 : moving == 2 ? dn2 : -(dn1 + dn2);
    const glm::dvec2 dt = moving == 1 ? dt1 : moving == 2 ? dt2 : -(dt1 + dt2);
    const glm::dvec2 dtr = dn / t2 - 2.0 * n * dt / (t2 * twice);
    *gradient = k2 > 0.0 ? g.area3D * (k2 * dtr + dn / (k2 * g.det)) : g.area3D * 0.5 * dtr;
  }
  if (k2 > 0.0) return g.area3D * (k2 * tr + n / (k2 * g.det));
  return g.area3D * 0.5 * tr;
}

glm::dvec2 polygonCorner(uint32_t n, uint32_t i) {
  const double a = 2.0 * std::numbers::pi * double(i % n) / double(n);
  return {pmath::cos(a), pmath::sin(a)};
}

namespace {

// Central angles theta_i = clamp(s * 2 pi L_i / sum L, lo, hi), s chosen so they sum to 2 pi (then
// made to close exactly).
std::vector<double> proportionalAngles(const std::vector<double>& lengths, double lo, double hi) {
  const size_t n = lengths.size();
  const double regular = 2.0 * std::numbers::pi / double(n);
  double total = 0.0;
  for (double l : lengths) total += l;
  std::vector<double> theta(n, regular);
  if (total > 0.0 && std::isfinite(total)) {
    // The scale is found by bisection: the sum grows with it from n lo < 2 pi to n hi > 2 pi.
    auto angles = [&](double scale) {
      double sum = 0.0;
      for (size_t i = 0; i < n; ++i) {
        theta[i] = std::clamp(scale * 2.0 * std::numbers::pi * lengths[i] / total, lo, hi);
        sum += theta[i];
      }
      return sum;
    };
    double below = 0.0, above = 1.0;
    while (angles(above) < 2.0 * std::numbers::pi && above < 1e30) above *= 2.0;
    for (int it = 0; it < 200 && above - below > 1e-15 * above; ++it) {
      const double mid = 0.5 * (below + above);
      (angles(mid) < 2.0 * std::numbers::pi ? below : above) = mid;
    }
    angles(above);
  }
  double sum = 0.0;
  for (double t : theta) sum += t;
  for (double& t : theta) t *= 2.0 * std::numbers::pi / sum;  // exact closure
  return theta;
}

}  // namespace

std::vector<glm::dvec2> patchPolygon(const std::vector<double>& sideLengths, bool paired) {
  const size_t n = sideLengths.size();
  std::vector<double> theta;
  if (paired && n == 4) {
    // One quad, the chart itself: the square, so the bilinear map adds no distortion and the
    // stretch the parameterization minimizes is the chart's.
    theta.assign(4, 0.5 * std::numbers::pi);
  } else if (paired && n >= 6 && n % 2 == 0) {
    // Each pair of sides (2j, 2j+1) is one quad with the centre: its angle there is the pair's,
    // proportional to the pair's length within [0.4, 1.8] times the regular one and below 3/4 pi
    // (a convex quad, not near a triangle); the middle corner splits it by the two sides' lengths
    // within [0.2, 0.8] of it.
    std::vector<double> pairs(n / 2);
    for (size_t j = 0; j < n / 2; ++j) pairs[j] = sideLengths[2 * j] + sideLengths[2 * j + 1];
    const double regular = 2.0 * std::numbers::pi / double(n / 2);
    const std::vector<double> phi =
        proportionalAngles(pairs, 0.4 * regular, std::min(1.8 * regular, 0.75 * std::numbers::pi));
    theta.resize(n);
    for (size_t j = 0; j < n / 2; ++j) {
      const double f =
          pairs[j] > 0.0 && std::isfinite(pairs[j]) ? std::clamp(sideLengths[2 * j] / pairs[j], 0.2, 0.8) : 0.5;
      theta[2 * j] = phi[j] * f;
      theta[2 * j + 1] = phi[j] - theta[2 * j];
    }
  } else {
    const double regular = 2.0 * std::numbers::pi / double(n);
    theta = proportionalAngles(sideLengths, 0.4 * regular, std::min(1.8 * regular, 0.9 * std::numbers::pi));
  }
  std::vector<glm::dvec2> corners(n);
  double angle = 0.0;
  for (size_t i = 0; i < n; ++i) {
    corners[i] = {pmath::cos(angle), pmath::sin(angle)};
    angle += theta[i];
  }
  return corners;
}

ParamQuality measureStretch(const std::vector<glm::dvec2>& uv, const std::vector<glm::dvec3>& xyz,
                            const std::vector<std::array<uint32_t, 3>>& triangles) {
  ParamQuality q;
  double l2num = 0.0, gammaMax = 0.0;
  for (const auto& t : triangles) {
    const TriangleStretch s = triangleStretch(uv[t[0]], uv[t[1]], uv[t[2]], xyz[t[0]], xyz[t[1]], xyz[t[2]]);
    if (s.degenerate) {
      ++q.degenerateTriangles;
      continue;
    }
    if (s.areaParam < 0.0) {
      ++q.flippedTriangles;
      continue;
    }
    q.area3D += s.area3D;
    q.areaParam += s.areaParam;
    l2num += s.area3D * s.l2sq;
    gammaMax = std::max(gammaMax, s.gammaSq);
  }
  if (q.areaParam > 0.0 && q.area3D > 0.0) {
    const double scale = std::sqrt(q.area3D / q.areaParam);  // isometric stretch after scaling
    q.stretchL2 = std::sqrt(l2num / q.area3D) / scale;
    q.stretchLinf = std::sqrt(gammaMax) / scale;
  }
  return q;
}

ParamQuality combineQuality(const std::vector<ParamQuality>& parts) {
  // note: each part is normalized by its own scale (charts are scaled independently), so the
  // combined L2 is the 3D-area-weighted RMS of the normalized figures.
  return combineStretch(parts, [](ParamQuality& q, const ParamQuality& p) {
    q.areaParam += p.areaParam;
    q.flippedTriangles += p.flippedTriangles;
    q.degenerateTriangles += p.degenerateTriangles;
  });
}

namespace {

// What solveMeanValue did, for the debug line.
struct SolveFigures {
  bool solved = false;
  size_t unknowns = 0;
  uint64_t factorEntries = 0;
  bool inDouble = true;
};

// The mean-value map of the patch onto its polygon (out.uv holds the boundary's places), then up
// to options.stretchIterations reweightings w_ij <- w_ij / sigma_j^eta, keeping the best pass and
// stopping when one stops helping. Sets out's uv, initial, quality and iterationsUsed. Its
// weights and factors are freed on return, before the local sweeps need their own arrays.
SolveFigures solveMeanValue(const LocalPatch& lp, const std::vector<uint8_t>& isBoundary, const ParamOptions& options,
                            PatchParameterization& out) {
  Weights weights = meanValueWeights(lp);
  InteriorSolver solver(lp, isBoundary, options.singlePrecisionFrom);
  SolveFigures figures;
  if (!solver.solve(weights, out.uv)) return figures;
  figures.solved = true;
  out.initial = measureStretch(out.uv, lp.xyz, lp.triangles);
  out.quality = out.initial;
  std::vector<glm::dvec2> trial = out.uv;
  for (uint32_t it = 0; it < options.stretchIterations; ++it) {
    const std::vector<double> sigma = vertexStretch(lp, trial);
    for (size_t e = 0; e < weights.w.size(); ++e)
      weights.w[e] /= pmath::pow(sigma[weights.j[e]], options.stretchExponent);
    if (!solver.solve(weights, trial)) break;
    const ParamQuality q = measureStretch(trial, lp.xyz, lp.triangles);
    const bool better = q.flippedTriangles <= out.quality.flippedTriangles &&
                        q.degenerateTriangles <= out.quality.degenerateTriangles &&
                        q.stretchL2 < out.quality.stretchL2 * (1.0 - 1e-4);
    if (!better) break;
    out.uv = trial;
    out.quality = q;
    out.iterationsUsed = it + 1;
  }
  figures.unknowns = solver.unknowns();
  figures.factorEntries = solver.factorEntries();
  figures.inDouble = solver.inDouble();
  return figures;
}

}  // namespace

std::unordered_map<uint32_t, uint32_t> numberPatchVertices(const PatchLayout& layout, const Patch& patch,
                                                           std::vector<uint32_t>& vertices,
                                                           std::vector<std::array<uint32_t, 3>>& triangles) {
  vertices.clear();
  triangles.clear();
  std::unordered_map<uint32_t, uint32_t> local;
  local.reserve(patch.triangles.size());
  triangles.reserve(patch.triangles.size());
  for (const uint32_t t : patch.triangles) {
    std::array<uint32_t, 3> lt;
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = layout.triangles[t][c];
      const auto [it, inserted] = local.try_emplace(v, uint32_t(vertices.size()));
      if (inserted) vertices.push_back(v);
      lt[c] = it->second;
    }
    triangles.push_back(lt);
  }
  return local;
}

PatchParameterization parameterizePatch(const PatchLayout& layout, uint32_t patch, const ParamOptions& options) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point start = Clock::now();
  LocalPatch lp = buildLocalPatch(layout, patch);
  const uint32_t n = uint32_t(layout.patches[patch].sides.size());

  PatchParameterization out;
  out.patch = patch;
  out.sides = n;
  out.uv.assign(lp.vertices.size(), glm::dvec2(0.0));

  // Boundary: side i on the polygon edge from corner i to corner i+1, by normalized arc length.
  std::vector<uint8_t> isBoundary(lp.vertices.size(), 0);
  // Open sides' inner vertices may slide along their polygon edge in the local optimization.
  std::vector<glm::dvec2> slide(lp.vertices.size(), glm::dvec2(0.0));
  const size_t nb = lp.boundary.size();
  std::vector<std::vector<double>> arc(n);  // per side, cumulative 3D length at each vertex
  std::vector<double> sideLength(n);
  for (uint32_t i = 0; i < n; ++i) {
    const size_t begin = lp.cornerIndex[i];
    const size_t end = i + 1 < n ? lp.cornerIndex[i + 1] : nb;  // exclusive; corner i+1 at end
    std::vector<double>& cum = arc[i];
    cum.assign(1, 0.0);
    for (size_t k = begin; k < end; ++k) {
      cum.push_back(cum.back() + glm::length(lp.xyz[lp.boundary[(k + 1) % nb]] - lp.xyz[lp.boundary[k]]));
    }
    sideLength[i] = cum.back();
    if (!(sideLength[i] > 0.0)) fail(patch, "side " + std::to_string(i) + " has zero length");
  }
  if (options.proportionalPolygon) {
    out.corners = patchPolygon(sideLength, options.pairedSides);
  } else {
    for (uint32_t i = 0; i < n; ++i) out.corners.push_back(polygonCorner(n, i));
  }
  for (uint32_t i = 0; i < n; ++i) {
    const size_t begin = lp.cornerIndex[i];
    const size_t end = i + 1 < n ? lp.cornerIndex[i + 1] : nb;
    const std::vector<double>& cum = arc[i];
    const double total = sideLength[i];
    const glm::dvec2 c0 = out.corners[i], c1 = out.corners[(i + 1) % n];
    for (size_t k = begin; k < end; ++k) {
      const double f = cum[k - begin] / total;
      const uint32_t v = lp.boundary[k];
      out.uv[v] = k == begin ? c0 : c0 + (c1 - c0) * f;
      isBoundary[v] = 1;
      if (k != begin && options.slideOpenSides && layout.patches[patch].sides[i].neighbourPatch < 0) {
        slide[v] = glm::normalize(c1 - c0);
      }
    }
  }

  const SolveFigures solve = solveMeanValue(lp, isBoundary, options, out);
  if (!solve.solved) fail(patch, "mean-value system could not be solved");

  const Clock::time_point solved = Clock::now();
  if (options.stretchSweeps > 0) {
    std::vector<glm::dvec2> trial = out.uv;
    out.sweepsUsed =
        optimizeStretchLocally(lp, isBoundary, slide, options.stretchSweeps, options.symmetricEnergy, trial);
    const ParamQuality q = measureStretch(trial, lp.xyz, lp.triangles);
    // The symmetric energy trades a little L2 stretch for no spread-out slivers; it only ever
    // lowers its own energy, so it is kept unless it flips something.
    if (q.flippedTriangles <= out.quality.flippedTriangles &&
        (options.symmetricEnergy || q.stretchL2 <= out.quality.stretchL2)) {
      out.uv = std::move(trial);
      out.quality = q;
    }
  }

  const auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  spdlog::debug(
      "parameterized patch {} ({} triangles, {} sides): solves {:.2f} s ({} reweightings; LU of {} "
      "unknowns, {} entries in {} precision), {} sweeps {:.2f} s, L2 stretch {:.3f} -> {:.3f}",
      patch, lp.triangles.size(), n, seconds(solved - start), out.iterationsUsed, solve.unknowns, solve.factorEntries,
      solve.inDouble ? "double" : "single", out.sweepsUsed, seconds(Clock::now() - solved), out.initial.stretchL2,
      out.quality.stretchL2);
  out.vertices = std::move(lp.vertices);
  out.triangles = std::move(lp.triangles);
  out.boundary = std::move(lp.boundary);
  out.cornerIndex = std::move(lp.cornerIndex);
  return out;
}

ParamQuality mapDiskOntoDomain(const std::vector<glm::dvec3>& xyz,
                               const std::vector<std::array<uint32_t, 3>>& triangles, const std::vector<uint8_t>& fixed,
                               const ParamOptions& options, std::vector<glm::dvec2>& uv) {
  if (fixed.size() != xyz.size() || uv.size() != xyz.size()) {
    throw std::invalid_argument("mapDiskOntoDomain: xyz, fixed and uv must have one entry per vertex");
  }
  LocalPatch lp;
  lp.vertices.resize(xyz.size());
  for (uint32_t v = 0; v < lp.vertices.size(); ++v) lp.vertices[v] = v;
  lp.triangles = triangles;
  lp.xyz = xyz;
  InteriorSolver solver(lp, fixed, options.singlePrecisionFrom);
  if (!solver.solve(meanValueWeights(lp), uv)) {
    throw std::invalid_argument("mapDiskOntoDomain: the mean-value system could not be solved");
  }
  ParamQuality quality = measureStretch(uv, lp.xyz, lp.triangles);
  if (options.stretchSweeps > 0) {
    std::vector<glm::dvec2> trial = uv;
    optimizeStretchLocally(lp, fixed, std::vector<glm::dvec2>(xyz.size(), glm::dvec2(0.0)), options.stretchSweeps,
                           options.symmetricEnergy, trial);
    const ParamQuality q = measureStretch(trial, lp.xyz, lp.triangles);
    if (q.flippedTriangles <= quality.flippedTriangles) {
      uv = std::move(trial);
      quality = q;
    }
  }
  return quality;
}

}  // namespace gimlod

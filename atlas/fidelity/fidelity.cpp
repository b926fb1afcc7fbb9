#include "atlas/fidelity/fidelity.h"
#include "core/progress.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>

#include <CGAL/AABB_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/Simple_cartesian.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/task_arena.h>

#include "atlas/mesh/gridify.h"
#include "atlas/mesh/mesh_atlas.h"
#include "core/atlas_format.h"
#include "core/stage_meter.h"

namespace gimlod {
namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Face = std::array<uint32_t, 3>;

// A surface's non-degenerate triangles, each as its corners' floats (36 bytes), widened to the same
// doubles a stored Triangle_3 would hold when one is needed: no double-precision copy is kept.
struct FloatTriangle {
  float v[9];
  Triangle triangle() const {
    return Triangle(Point(v[0], v[1], v[2]), Point(v[3], v[4], v[5]), Point(v[6], v[7], v[8]));
  }
};
struct FloatBox {
  float lo[3], hi[3];
};

// The tree's primitive is a run of a few consecutive triangles (the last run may be shorter), boxed
// together: a fourth as many tree nodes to build and hold where the runs are four long. It pays
// where consecutive triangles lie together (an atlas's come a chart's grid row at a time); where
// they do not (a scan's triangles may come in any order), the runs are single triangles. The
// closest point over the runs is the closest over the triangles either way: the answer is the same.
constexpr size_t kRun = 4;

struct GroupDatumMap {  // CGAL's primitive wants a datum: the run's first triangle (the search below reads the whole
                        // run)
  using key_type = uint32_t;
  using value_type = Triangle;
  using reference = Triangle;
  using category = boost::readable_property_map_tag;
  const FloatTriangle* t = nullptr;
  size_t run = 1;
  friend Triangle get(const GroupDatumMap& m, uint32_t g) { return m.t[g * m.run].triangle(); }
};
struct GroupCentreMap {  // where the build sorts a run: its box's centre
  using key_type = uint32_t;
  using value_type = Point;
  using reference = Point;
  using category = boost::readable_property_map_tag;
  const FloatBox* b = nullptr;
  friend Point get(const GroupCentreMap& m, uint32_t g) {
    const FloatBox& b = m.b[g];
    return Point(0.5 * (double(b.lo[0]) + b.hi[0]), 0.5 * (double(b.lo[1]) + b.hi[1]),
                 0.5 * (double(b.lo[2]) + b.hi[2]));
  }
};
struct GroupBoxMap {
  using key_type = uint32_t;
  using value_type = CGAL::Bbox_3;
  using reference = CGAL::Bbox_3;
  using category = boost::readable_property_map_tag;
  const FloatBox* b = nullptr;
  friend CGAL::Bbox_3 get(const GroupBoxMap& m, uint32_t g) {
    const FloatBox& b = m.b[g];
    return CGAL::Bbox_3(b.lo[0], b.lo[1], b.lo[2], b.hi[0], b.hi[1], b.hi[2]);
  }
};
using Primitive = CGAL::AABB_primitive<uint32_t, GroupDatumMap, GroupCentreMap, CGAL::Tag_true, CGAL::Tag_false>;
using Traits = CGAL::AABB_traits<Kernel, Primitive, GroupBoxMap>;
using Tree = CGAL::AABB_tree<Traits>;

// The non-degenerate triangles (as a stored Triangle_3 judges them), in input order. keepSlots:
// each degenerate triangle's slot takes a copy of the nearest non-degenerate one before it (after
// it, for the first) instead of closing up, so runs of neighbouring triangles (a chart's grid
// rows) stay aligned and the Forest's groups small; a copy changes no closest point.
std::vector<FloatTriangle> nonDegenerate(const std::vector<glm::vec3>& p, const std::vector<Face>& t,
                                         bool keepSlots = false) {
  std::vector<FloatTriangle> out(t.size());
  std::vector<uint8_t> keep(t.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, t.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      FloatTriangle& ft = out[i];
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) ft.v[3 * k + c] = p[t[i][k]][c];
      keep[i] = !ft.triangle().is_degenerate();
    }
  });
  if (keepSlots) {
    const auto first = std::find(keep.begin(), keep.end(), uint8_t(1));
    if (first == keep.end()) return {};
    const FloatTriangle* last = &out[size_t(first - keep.begin())];
    for (size_t i = 0; i < t.size(); ++i) {
      if (keep[i])
        last = &out[i];
      else
        out[i] = *last;
    }
    return out;
  }
  size_t n = 0;
  for (size_t i = 0; i < t.size(); ++i)
    if (keep[i]) out[n++] = out[i];
  out.resize(n);
  return out;
}

// A surface as a few CGAL trees over spatially split parts of its runs of triangles, built in
// parallel (one tree builds on one thread); the closest point to the surface is the closest over
// the trees.
class Forest {
 public:
  explicit Forest(const std::vector<FloatTriangle>& tris) : tris_(tris.data()), n_(tris.size()) {
    // Runs of kRun where their boxes stay small next to their triangles' (on the mean diagonal).
    const double tri = boxDiagonalSum(1), four = boxDiagonalSum(kRun);
    run_ = four <= 2.5 * tri * double((n_ + kRun - 1) / kRun) / double(n_) ? kRun : 1;
    const size_t groups = (n_ + run_ - 1) / run_;
    boxes_.resize(groups);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, groups, 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t g = r.begin(); g != r.end(); ++g) boxes_[g] = box(g, run_);
    });
    std::vector<uint32_t> ids(groups);
    for (uint32_t g = 0; g < groups; ++g) ids[g] = g;
    std::vector<std::pair<size_t, size_t>> parts;
    split(ids, 0, groups, size_t(std::max(1, tbb::this_task_arena::max_concurrency())), parts);
    trees_.resize(parts.size());
    tbb::parallel_for(size_t(0), parts.size(), [&](size_t i) {
      trees_[i] = std::make_unique<Tree>(Traits(GroupBoxMap{boxes_.data()}));
      trees_[i]->insert(ids.begin() + parts[i].first, ids.begin() + parts[i].second, GroupDatumMap{tris_, run_},
                        GroupCentreMap{boxes_.data()});
      trees_[i]->build();
    });
  }
  template <class Traversal>
  void traverse(const Point& q, Traversal& traversal) const {
    for (const auto& t : trees_) t->traversal_with_priority(q, traversal);
  }
  // The triangles of run g.
  const FloatTriangle* begin(uint32_t g) const { return tris_ + g * run_; }
  const FloatTriangle* end(uint32_t g) const { return tris_ + std::min(n_, (g + 1) * run_); }

 private:
  FloatBox box(size_t g, size_t run) const {
    FloatBox b;
    for (int c = 0; c < 3; ++c) b.lo[c] = std::numeric_limits<float>::infinity(), b.hi[c] = -b.lo[c];
    for (size_t i = g * run; i < std::min(n_, (g + 1) * run); ++i)
      for (int k = 0; k < 9; ++k)
        b.lo[k % 3] = std::min(b.lo[k % 3], tris_[i].v[k]), b.hi[k % 3] = std::max(b.hi[k % 3], tris_[i].v[k]);
    return b;
  }
  double boxDiagonalSum(size_t run) const {
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, (n_ + run - 1) / run, 4096), 0.0,
        [&](const tbb::blocked_range<size_t>& r, double sum) {
          for (size_t g = r.begin(); g != r.end(); ++g) {
            const FloatBox b = box(g, run);
            sum += std::sqrt(double(b.hi[0] - b.lo[0]) * (b.hi[0] - b.lo[0]) +
                             double(b.hi[1] - b.lo[1]) * (b.hi[1] - b.lo[1]) +
                             double(b.hi[2] - b.lo[2]) * (b.hi[2] - b.lo[2]));
          }
          return sum;
        },
        std::plus<double>());
  }

  // Halves [b, e) at the median of the runs' centres along their longest extent until there are at
  // least `parts` pieces (or pieces too small to be worth a tree of their own).
  void split(std::vector<uint32_t>& ids, size_t b, size_t e, size_t parts,
             std::vector<std::pair<size_t, size_t>>& out) const {
    if (parts <= 1 || e - b < 16384) {
      if (e > b) out.emplace_back(b, e);
      return;
    }
    auto centre = [&](uint32_t g, int c) { return boxes_[g].lo[c] + boxes_[g].hi[c]; };
    float lo[3], hi[3];
    for (int c = 0; c < 3; ++c) lo[c] = hi[c] = centre(ids[b], c);
    for (size_t i = b; i < e; ++i)
      for (int c = 0; c < 3; ++c)
        lo[c] = std::min(lo[c], centre(ids[i], c)), hi[c] = std::max(hi[c], centre(ids[i], c));
    int axis = 0;
    for (int c = 1; c < 3; ++c)
      if (hi[c] - lo[c] > hi[axis] - lo[axis]) axis = c;
    const size_t m = b + (e - b) / 2;
    std::nth_element(ids.begin() + b, ids.begin() + m, ids.begin() + e,
                     [&](uint32_t x, uint32_t y) { return centre(x, axis) < centre(y, axis); });
    split(ids, b, m, (parts + 1) / 2, out);
    split(ids, m, e, (parts + 1) / 2, out);
  }
  const FloatTriangle* tris_;
  size_t n_, run_ = 1;
  std::vector<FloatBox> boxes_;  // of each run
  std::vector<std::unique_ptr<Tree>> trees_;
};

struct Acc {
  double max = 0.0, sum = 0.0;
  std::vector<uint32_t> beyond;  // samples with nothing within the margin (in neither max nor sum)
};

// The closest point of a forest's surface to one query, as traversal traits for its CGAL trees
// (CGAL's own closest-point traits visit children in a fixed order and recompute the bound at every
// box; these visit the nearer box first). A box is entered only when it could hold a point strictly
// closer than the best so far; each triangle is projected onto with CGAL's projection, as
// AABB_tree::closest_point does. Starting from a hint (a point on the surface, or none) only bounds
// the search: the answer is the exact closest point over every triangle whatever the hint.
class Nearest {
 public:
  using Priority = double;
  explicit Nearest(const Forest& f) : f_(f), closest_(CGAL::ORIGIN), d2_(std::numeric_limits<double>::infinity()) {}
  Nearest(const Forest& f, const Point& q, const Point& hint)
      : f_(f), closest_(hint), d2_(CGAL::squared_distance(q, hint)) {}
  // Only points closer than sqrt(bound2) are sought (closest() stays the origin if none is).
  Nearest(const Forest& f, double bound2) : f_(f), closest_(CGAL::ORIGIN), d2_(bound2) {}
  bool go_further() const { return true; }
  template <class P>
  void intersection(const Point& q, const P& primitive) {
    for (const FloatTriangle* t = f_.begin(primitive.id()); t != f_.end(primitive.id()); ++t) {
      if (triangleBoxDistance2(q, *t) >= d2_) continue;  // a cheap bound first: nothing closer in there
      const Point c = Kernel::Construct_projected_point_3()(t->triangle(), q);
      const double d2 = CGAL::squared_distance(q, c);
      if (d2 < d2_) {
        d2_ = d2;
        closest_ = c;
      }
    }
  }
  template <class Node>
  bool do_intersect(const Point& q, const Node& n) const {
    return boxDistance2(q, n.bbox()) < d2_;
  }
  template <class Node>
  std::pair<bool, double> do_intersect_with_priority(const Point& q, const Node& n) const {
    const double d = boxDistance2(q, n.bbox());
    return {d < d2_, -d};
  }
  const Point& closest() const { return closest_; }
  double squaredDistance() const { return d2_; }

  static double boxDistance2(const Point& q, const FloatBox& b) {
    return boxDistance2(q, CGAL::Bbox_3(b.lo[0], b.lo[1], b.lo[2], b.hi[0], b.hi[1], b.hi[2]));
  }

 private:
  static double triangleBoxDistance2(const Point& q, const FloatTriangle& t) {
    double d2 = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double lo = std::min({t.v[k], t.v[k + 3], t.v[k + 6]}) - q[k];
      const double hi = q[k] - std::max({t.v[k], t.v[k + 3], t.v[k + 6]});
      const double d = lo > 0.0 ? lo : (hi > 0.0 ? hi : 0.0);
      d2 += d * d;
    }
    return d2;
  }
  static double boxDistance2(const Point& q, const CGAL::Bbox_3& b) {
    double d2 = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double lo = b.min(k) - q[k], hi = q[k] - b.max(k);
      const double d = lo > 0.0 ? lo : (hi > 0.0 ? hi : 0.0);
      d2 += d * d;
    }
    return d2;
  }
  const Forest& f_;
  Point closest_;
  double d2_;
};

// Distances from every sample to the forest's surface (in parallel; the forest is read-only). Each
// sample's search starts from the previous sample's closest point in its block as the hint: the
// samples come in a spatially coherent order (an atlas's a chart at a time, a mesh's in input order),
// so the hint is already close and the search prunes almost everything. No KD-tree of hints needed.
// A sample farther than `margin` from the forest's surface is listed in beyond (in order) instead
// of counted: the forest may hold only the part of a surface within the margin around the samples.
template <class Sample>
Acc distances(const Forest& forest, size_t count, const Sample& sample,
              double margin = std::numeric_limits<double>::infinity(), float* perSample = nullptr,
              glm::vec3* closestOut = nullptr) {
  const progress::ProgressStage stage("distances", count);
  Acc acc = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, count, 1024), Acc{},
      [&](const tbb::blocked_range<size_t>& r, Acc a) {
        progress::advance(r.size());
        Point hint(CGAL::ORIGIN);
        for (size_t i = r.begin(); i != r.end(); ++i) {
          const Point q = sample(i);
          Nearest n = i == r.begin() ? Nearest(forest) : Nearest(forest, q, hint);
          forest.traverse(q, n);
          hint = n.closest();
          const double d = std::sqrt(n.squaredDistance());
          if (perSample) perSample[i] = float(d);
          if (closestOut) closestOut[i] = glm::vec3(float(hint.x()), float(hint.y()), float(hint.z()));
          if (d > margin) {
            a.beyond.push_back(uint32_t(i));
            continue;
          }
          a.max = std::max(a.max, d);
          a.sum += d;
        }
        return a;
      },
      [](Acc a, const Acc& b) {
        a.max = std::max(a.max, b.max);
        a.sum += b.sum;
        a.beyond.insert(a.beyond.end(), b.beyond.begin(), b.beyond.end());
        return a;
      });
  std::sort(acc.beyond.begin(), acc.beyond.end());
  return acc;
}

// The figures from the two sides' maxima and sums (the sample counts and diagonal already set).
void setFigures(FidelityStats& st, double atlasMax, double atlasSum, double meshMax, double meshSum,
                std::chrono::steady_clock::time_point t0) {
  st.maxAtlasToMesh = atlasMax;
  st.meanAtlasToMesh = atlasSum / double(std::max<uint64_t>(st.atlasSamples, 1));
  st.maxMeshToAtlas = meshMax;
  st.meanMeshToAtlas = meshSum / double(std::max<uint64_t>(st.meshSamples, 1));
  st.hausdorff = std::max(atlasMax, meshMax);
  st.hausdorffPercent = st.diagonal > 0 ? 100.0 * st.hausdorff / st.diagonal : 0.0;
  st.meanPercent = st.diagonal > 0 ? 100.0 * 0.5 * (st.meanAtlasToMesh + st.meanMeshToAtlas) / st.diagonal : 0.0;
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The diagonal of the box of the vertices the triangles use.
double usedDiagonal(const std::vector<glm::vec3>& p, const std::vector<Face>& t) {
  glm::vec3 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
  for (const auto& f : t)
    for (uint32_t i : f) {
      lo = {std::min(lo.x, p[i].x), std::min(lo.y, p[i].y), std::min(lo.z, p[i].z)};
      hi = {std::max(hi.x, p[i].x), std::max(hi.y, p[i].y), std::max(hi.z, p[i].z)};
    }
  return std::sqrt(double(hi.x - lo.x) * (hi.x - lo.x) + double(hi.y - lo.y) * (hi.y - lo.y) +
                   double(hi.z - lo.z) * (hi.z - lo.z));
}

// The mesh side's samples: every vertex a triangle uses, then every non-degenerate triangle's
// centroid (`mesh`), in input order (coherent, for the hints).
std::vector<Point> meshSamplePoints(const std::vector<glm::vec3>& p, const std::vector<Face>& t,
                                    const std::vector<FloatTriangle>& mesh) {
  std::vector<Point> out;
  std::vector<bool> used(p.size(), false);
  for (const auto& f : t)
    for (uint32_t i : f) used[i] = true;
  out.reserve(p.size() + mesh.size());
  for (size_t i = 0; i < p.size(); ++i)
    if (used[i]) out.emplace_back(p[i].x, p[i].y, p[i].z);
  for (const FloatTriangle& f : mesh) out.push_back(CGAL::centroid(f.triangle()));
  return out;
}

}  // namespace

FidelityStats measureFidelity(const std::vector<glm::vec3>& meshPositions,
                              const std::vector<std::array<uint32_t, 3>>& meshTriangles,
                              const std::vector<glm::vec3>& atlasPositions,
                              const std::vector<std::array<uint32_t, 3>>& atlasTriangles, FidelityDetail* detail) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<FloatTriangle> mesh, atlas;
  tbb::parallel_invoke([&] { mesh = nonDegenerate(meshPositions, meshTriangles); },
                       [&] { atlas = nonDegenerate(atlasPositions, atlasTriangles, true); });
  if (mesh.empty() || atlas.empty()) throw std::invalid_argument("measureFidelity: a surface has no triangles");
  FidelityStats st;
  st.diagonal = usedDiagonal(meshPositions, meshTriangles);
  const std::vector<Point> meshSamples = meshSamplePoints(meshPositions, meshTriangles, mesh);

  if (detail) detail->atlasDistances.assign(atlasPositions.size(), 0.f);
  // The atlas trees build while the mesh trees build and answer the atlas samples (one CGAL tree
  // builds on one thread, so this keeps both cores busy).
  std::unique_ptr<Forest> atlasForest;
  Acc a;
  tbb::parallel_invoke(
      [&] { atlasForest = std::make_unique<Forest>(atlas); },
      [&] {
        const Forest meshForest(mesh);
        a = distances(
            meshForest, atlasPositions.size(),
            [&](size_t i) { return Point(atlasPositions[i].x, atlasPositions[i].y, atlasPositions[i].z); },
            std::numeric_limits<double>::infinity(), detail ? detail->atlasDistances.data() : nullptr);
      });
  st.atlasSamples = atlasPositions.size();
  if (detail) {
    detail->meshSamples.resize(meshSamples.size());
    for (size_t i = 0; i < meshSamples.size(); ++i)
      detail->meshSamples[i] =
          glm::vec3(float(meshSamples[i].x()), float(meshSamples[i].y()), float(meshSamples[i].z()));
    detail->meshDistances.assign(meshSamples.size(), 0.f);
    detail->meshClosest.assign(meshSamples.size(), glm::vec3(0.f));
  }
  const Acc b = distances(
      *atlasForest, meshSamples.size(), [&](size_t i) { return meshSamples[i]; },
      std::numeric_limits<double>::infinity(), detail ? detail->meshDistances.data() : nullptr,
      detail ? detail->meshClosest.data() : nullptr);
  st.meshSamples = meshSamples.size();

  setFigures(st, a.max, a.sum, b.max, b.sum, t0);
  return st;
}

namespace {

// Working memory per input triangle and per atlas sample of a block: the float triangles (two per
// atlas sample), their boxes, tree nodes and samples, with some slack. The blocks are sized from
// these before anything is read; the cell is the smallest block, so a cell's worth is the floor.
constexpr uint64_t kBytesPerMeshTriangle = 220, kBytesPerAtlasSample = 160;

struct Box {
  double lo[3], hi[3];
  bool overlaps(const FloatBox& b) const {
    for (int k = 0; k < 3; ++k)
      if (b.hi[k] < lo[k] || b.lo[k] > hi[k]) return false;
    return true;
  }
};

FloatBox boxOf(const FloatTriangle& t) {
  FloatBox b;
  for (int c = 0; c < 3; ++c) {
    b.lo[c] = std::min({t.v[c], t.v[c + 3], t.v[c + 6]});
    b.hi[c] = std::max({t.v[c], t.v[c + 3], t.v[c + 6]});
  }
  return b;
}

void extend(FloatBox& b, const FloatBox& o) {
  for (int c = 0; c < 3; ++c) b.lo[c] = std::min(b.lo[c], o.lo[c]), b.hi[c] = std::max(b.hi[c], o.hi[c]);
}

void extend(FloatBox& b, const glm::vec3& p) {
  for (int c = 0; c < 3; ++c) b.lo[c] = std::min(b.lo[c], p[c]), b.hi[c] = std::max(b.hi[c], p[c]);
}

FloatTriangle floatTriangle(const MeshTriangle& t) {
  FloatTriangle f;
  for (int k = 0; k < 3; ++k)
    for (int c = 0; c < 3; ++c) f.v[3 * k + c] = t.p[k][c];
  return f;
}

FloatBox emptyBox() {
  FloatBox b;
  for (int c = 0; c < 3; ++c) b.lo[c] = std::numeric_limits<float>::infinity(), b.hi[c] = -b.lo[c];
  return b;
}

// Keeps the first of every run of equal points, in their order (so the samples stay coherent).
void dropRepeats(std::vector<Point>& p) {
  std::vector<uint32_t> order(p.size());
  for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  auto key = [&](uint32_t i) { return std::array<double, 3>{p[i].x(), p[i].y(), p[i].z()}; };
  std::sort(order.begin(), order.end(),
            [&](uint32_t a, uint32_t b) { return key(a) < key(b) || (key(a) == key(b) && a < b); });
  std::vector<uint8_t> keep(p.size(), 1);
  for (size_t i = 1; i < order.size(); ++i)
    if (key(order[i]) == key(order[i - 1])) keep[order[i]] = 0;
  size_t n = 0;
  for (size_t i = 0; i < p.size(); ++i)
    if (keep[i]) p[n++] = p[i];
  p.resize(n);
}

// The level-0 grid of one atlas chart as float triangles, split as readAtlasSurface splits it.
template <class Emit>
void chartTriangles(const std::vector<glm::vec3>& P, uint32_t s, const Emit& emit) {
  auto corner = [&](FloatTriangle& t, int k, uint32_t i) {
    t.v[3 * k] = P[i].x, t.v[3 * k + 1] = P[i].y, t.v[3 * k + 2] = P[i].z;
  };
  for (uint32_t v = 0; v + 1 < s; ++v)
    for (uint32_t u = 0; u + 1 < s; ++u) {
      const uint32_t a = v * s + u, b = a + 1, c = a + s + 1, d = a + s;
      FloatTriangle t1, t2;
      corner(t1, 0, a), corner(t1, 1, b), corner(t1, 2, c);
      corner(t2, 0, a), corner(t2, 1, c), corner(t2, 2, d);
      emit(t1);
      emit(t2);
    }
}

// One side of the measure: samples with nothing within the margin, kept with the closest point
// found so far (its squared distance infinite while none).
struct Pending {
  std::vector<Point> q, closest;
  std::vector<double> d2;
  uint64_t unresolved = 0;  // more than could be held: counted at the margin
};

// A block's share of one surface: its triangles near the block (within the margin), and its samples
// in the block.
struct BlockSurface {
  std::vector<FloatTriangle> tris;
  std::vector<Point> samples;
};

// One out-of-core measure (measureFidelityOutOfCore): the two surfaces on disk, where their parts
// lie, the blocks of cells they are measured in, and each side's figures so far. Its steps: survey
// the surfaces, choose the blocks, measure block by block, then resolve the samples left pending.
class OutOfCoreMeasure {
 public:
  OutOfCoreMeasure(const std::filesystem::path& gridDir, const std::filesystem::path& atlasDir, const GridManifest& gm,
                   const AtlasManifest& am, const OutOfCoreFidelityOptions& options)
      : gridDir_(gridDir), atlasDir_(atlasDir), gm_(gm), am_(am), options_(options) {
    const glm::vec3 e = gm.bounds.max - gm.bounds.min;
    st_.diagonal = std::sqrt(double(e.x) * e.x + double(e.y) * e.y + double(e.z) * e.z);
    margin_ = options.marginFraction * st_.diagonal;
  }

  FidelityStats run(std::chrono::steady_clock::time_point t0) {
    survey();
    chooseBlocks();
    pendingCap_ = options_.memoryBytes / 4 / (2 * sizeof(Point) + sizeof(double));
    for (uint32_t bz = 0; bz < bd_[2]; ++bz)
      for (uint32_t by = 0; by < bd_[1]; ++by)
        for (uint32_t bx = 0; bx < bd_[0]; ++bx) measureBlock({bx, by, bz});
    resolvePending();
    return finish(t0);
  }

 private:
  std::filesystem::path chartPath(uint32_t c) const { return atlasDir_ / am_.charts[c].file; }
  // A chart's finest samples (ChartInfo::finestLevel), am.chartFileSize(c) a side.
  std::vector<glm::vec3> readChart(uint32_t c) const {
    const ChartFileReader reader(chartPath(c));
    if (!reader.hasChannel(kChannelPositions))
      throw InputError(chartPath(c).string() + ": no positions in a geometry atlas chart");
    if (reader.chartSize() != am_.chartFileSize(c))
      throw InputError(chartPath(c).string() + ": chart size differs from the manifest's");
    return reader.readLevelPositions(0);
  }
  // Points go to the cell holding them, clamped into the grid (as GridManifest::cellOf places a
  // centroid), and so to exactly one block.
  uint32_t cellAxis(double x, int a) const {
    const double c = std::floor((x - gm_.origin[a]) / gm_.cellSize[a]);
    return c <= 0 ? 0u : c >= gm_.dims[a] - 1 ? gm_.dims[a] - 1 : static_cast<uint32_t>(c);
  }
  uint32_t cellIdOf(double x, double y, double z) const {
    return gm_.cellId({cellAxis(x, 0), cellAxis(y, 1), cellAxis(z, 2)});
  }
  uint32_t blockOf(double x, double y, double z) const {
    return cellAxis(x, 0) / g_ + bd_[0] * (cellAxis(y, 1) / g_ + bd_[1] * (cellAxis(z, 2) / g_));
  }

  // What is where: the box of every cell's triangles, and of every chart's samples; the atlas
  // samples in every cell (to size the blocks).
  void survey() {
    cellBoxes_.assign(gm_.cells.size(), emptyBox());
    chartBoxes_.assign(am_.charts.size(), emptyBox());
    gridCells_ = uint64_t(gm_.dims[0]) * gm_.dims[1] * gm_.dims[2];
    atlasInCell_ = std::vector<std::atomic<uint64_t>>(gridCells_);
    tbb::parallel_for(size_t(0), gm_.cells.size(), [&](size_t i) {
      for (const MeshTriangle& t : readCell(gridDir_, gm_, gm_.cells[i]))
        extend(cellBoxes_[i], boxOf(floatTriangle(t)));
    });
    tbb::parallel_for(uint32_t(0), uint32_t(am_.charts.size()), [&](uint32_t c) {
      const std::vector<glm::vec3> P = readChart(c);
      std::vector<uint32_t> cells(P.size());
      for (size_t i = 0; i < P.size(); ++i) {
        extend(chartBoxes_[c], P[i]);
        cells[i] = cellIdOf(P[i].x, P[i].y, P[i].z);
      }
      std::sort(cells.begin(), cells.end());
      for (size_t i = 0; i < cells.size();) {
        size_t j = i;
        while (j < cells.size() && cells[j] == cells[i]) ++j;
        atlasInCell_[cells[i]] += j - i;
        i = j;
      }
    });
  }

  std::array<uint32_t, 3> blockDims(uint32_t g) const {
    return std::array<uint32_t, 3>{(gm_.dims[0] + g - 1) / g, (gm_.dims[1] + g - 1) / g, (gm_.dims[2] + g - 1) / g};
  }
  // The estimated working memory of the fullest block of g^3 cells, its margin included.
  double fullestBlock(uint32_t g) const {
    const std::array<uint32_t, 3> bd = blockDims(g);
    std::vector<uint64_t> cost(size_t(bd[0]) * bd[1] * bd[2], 0);
    for (uint32_t z = 0; z < gm_.dims[2]; ++z)
      for (uint32_t y = 0; y < gm_.dims[1]; ++y)
        for (uint32_t x = 0; x < gm_.dims[0]; ++x)
          cost[x / g + bd[0] * (y / g + bd[1] * (z / g))] += cellCost_[gm_.cellId({x, y, z})];
    // The margin adds a shell: grow by the ratio of the widened block's face to its own.
    const double side = g * std::min({gm_.cellSize[0], gm_.cellSize[1], gm_.cellSize[2]});
    const double grow = side > 0 ? std::pow((side + 2 * margin_) / side, 2.0) : 1.0;
    return double(*std::max_element(cost.begin(), cost.end())) * grow;
  }
  // Blocks of g^3 cells: the largest g whose fullest block (with its margin) fits the memory.
  void chooseBlocks() {
    cellCost_.assign(gridCells_, 0);
    for (size_t i = 0; i < gm_.cells.size(); ++i)
      cellCost_[gm_.cells[i].id] = gm_.cells[i].triangles * kBytesPerMeshTriangle;
    for (uint64_t c = 0; c < gridCells_; ++c) cellCost_[c] += atlasInCell_[c] * kBytesPerAtlasSample;
    const uint32_t maxDim = std::max({gm_.dims[0], gm_.dims[1], gm_.dims[2]});
    uint32_t g = options_.maxBlockCells ? std::min(options_.maxBlockCells, maxDim) : maxDim;
    while (g > 1 && fullestBlock(g) > double(options_.memoryBytes)) g = (g + 1) / 2;
    g_ = g;
    bd_ = blockDims(g);
    blockUsed_.assign(size_t(bd_[0]) * bd_[1] * bd_[2], 0);
    for (uint32_t z = 0; z < gm_.dims[2]; ++z)
      for (uint32_t y = 0; y < gm_.dims[1]; ++y)
        for (uint32_t x = 0; x < gm_.dims[0]; ++x)
          if (cellCost_[gm_.cellId({x, y, z})]) blockUsed_[x / g + bd_[0] * (y / g + bd_[1] * (z / g))] = 1;
  }

  // The block's box widened by the margin; unbounded past the grid's faces, where points outside
  // the grid are clamped in.
  Box widenedBlock(const std::array<uint32_t, 3>& b) const {
    Box e;
    for (int a = 0; a < 3; ++a) {
      const double pad = margin_ * (1.0 + 1e-9) + 1e-30;
      e.lo[a] = b[a] == 0 ? -std::numeric_limits<double>::infinity()
                          : gm_.origin[a] + double(b[a] * g_) * gm_.cellSize[a] - pad;
      e.hi[a] = b[a] + 1 == bd_[a] ? std::numeric_limits<double>::infinity()
                                   : gm_.origin[a] + double((b[a] + 1) * g_) * gm_.cellSize[a] + pad;
    }
    return e;
  }
  // The input's triangles near the block, and its samples in the block, cell by cell in grid order
  // (each cell in file order).
  BlockSurface readMeshNear(uint32_t block, const Box& e) const {
    std::vector<uint32_t> cellsNear;
    for (uint32_t i = 0; i < gm_.cells.size(); ++i)
      if (e.overlaps(cellBoxes_[i])) cellsNear.push_back(i);
    std::vector<std::vector<FloatTriangle>> meshParts(cellsNear.size());
    std::vector<std::vector<Point>> meshSampleParts(cellsNear.size()), vertexParts(cellsNear.size());
    tbb::parallel_for(size_t(0), cellsNear.size(), [&](size_t k) {
      for (const MeshTriangle& t : readCell(gridDir_, gm_, gm_.cells[cellsNear[k]])) {
        const FloatTriangle f = floatTriangle(t);
        if (!e.overlaps(boxOf(f))) continue;
        for (int i = 0; i < 3; ++i)
          if (blockOf(t.p[i].x, t.p[i].y, t.p[i].z) == block) vertexParts[k].emplace_back(t.p[i].x, t.p[i].y, t.p[i].z);
        if (f.triangle().is_degenerate()) continue;
        meshParts[k].push_back(f);
        const Point centroid = CGAL::centroid(f.triangle());
        if (blockOf(centroid.x(), centroid.y(), centroid.z()) == block) meshSampleParts[k].push_back(centroid);
      }
    });
    BlockSurface s;
    for (size_t k = 0; k < cellsNear.size(); ++k) {
      s.tris.insert(s.tris.end(), meshParts[k].begin(), meshParts[k].end());
      s.samples.insert(s.samples.end(), vertexParts[k].begin(), vertexParts[k].end());
      std::vector<FloatTriangle>().swap(meshParts[k]);
    }
    dropRepeats(s.samples);  // a vertex is a corner of several triangles
    for (const auto& part : meshSampleParts) s.samples.insert(s.samples.end(), part.begin(), part.end());
    return s;
  }
  // The atlas's triangles near the block and its samples in the block, chart by chart.
  BlockSurface readAtlasNear(uint32_t block, const Box& e) const {
    std::vector<uint32_t> chartsNear;
    for (uint32_t c = 0; c < am_.charts.size(); ++c)
      if (e.overlaps(chartBoxes_[c])) chartsNear.push_back(c);
    std::vector<std::vector<FloatTriangle>> atlasParts(chartsNear.size());
    std::vector<std::vector<Point>> atlasSampleParts(chartsNear.size());
    tbb::parallel_for(size_t(0), chartsNear.size(), [&](size_t k) {
      const std::vector<glm::vec3> P = readChart(chartsNear[k]);
      for (const glm::vec3& q : P)
        if (blockOf(q.x, q.y, q.z) == block) atlasSampleParts[k].emplace_back(q.x, q.y, q.z);
      chartTriangles(P, am_.chartFileSize(chartsNear[k]), [&](const FloatTriangle& t) {
        if (e.overlaps(boxOf(t)) && !t.triangle().is_degenerate()) atlasParts[k].push_back(t);
      });
    });
    BlockSurface s;
    for (size_t k = 0; k < chartsNear.size(); ++k) {
      s.tris.insert(s.tris.end(), atlasParts[k].begin(), atlasParts[k].end());
      s.samples.insert(s.samples.end(), atlasSampleParts[k].begin(), atlasSampleParts[k].end());
      std::vector<FloatTriangle>().swap(atlasParts[k]);
    }
    dropRepeats(s.samples);  // seams: bit-identical samples in both charts
    return s;
  }

  // Samples (by index) with nothing within the margin, held for the second pass while there is room.
  void addPending(Pending& p, const std::vector<Point>& samples, const std::vector<uint32_t>& ids) {
    st_.samplesBeyondMargin += ids.size();
    for (uint32_t i : ids) {
      if (meshPending_.q.size() + atlasPending_.q.size() >= pendingCap_) {
        ++p.unresolved;
        continue;
      }
      p.q.push_back(samples[i]);
      p.closest.push_back(CGAL::ORIGIN);
      p.d2.push_back(std::numeric_limits<double>::infinity());
    }
  }
  // One side's samples against the other's triangles near the block.
  void measureSide(const std::vector<FloatTriangle>& tris, const std::vector<Point>& samples, double& max, double& sum,
                   Pending& pending) {
    if (samples.empty()) return;
    if (tris.empty()) {
      std::vector<uint32_t> all(samples.size());
      for (uint32_t i = 0; i < all.size(); ++i) all[i] = i;
      addPending(pending, samples, all);
      return;
    }
    const Forest forest(tris);
    const Acc a = distances(
        forest, samples.size(), [&](size_t i) { return samples[i]; }, margin_);
    max = std::max(max, a.max);
    sum += a.sum;
    addPending(pending, samples, a.beyond);
  }
  void measureBlock(const std::array<uint32_t, 3>& b) {
    const uint32_t block = b[0] + bd_[0] * (b[1] + bd_[1] * b[2]);
    if (!blockUsed_[block]) return;
    ++st_.blocks;
    const Box e = widenedBlock(b);
    BlockSurface mesh = readMeshNear(block, e);
    const BlockSurface atlas = readAtlasNear(block, e);
    st_.meshSamples += mesh.samples.size();
    st_.atlasSamples += atlas.samples.size();
    // Each side's samples against the other's triangles near the block.
    measureSide(mesh.tris, atlas.samples, atlasMax_, atlasSum_, atlasPending_);
    std::vector<FloatTriangle>().swap(mesh.tris);
    measureSide(atlas.tris, mesh.samples, meshMax_, meshSum_, meshPending_);
    // The next block's surfaces are as large: where the process already holds more than a block's
    // share, the heap hands this one's pages back first, or the blocks' arrays, freed on several
    // threads, pile up past options.memoryBytes. (Handing them back walks the whole heap: after each
    // of the 56 blocks of an 18.7M-triangle sphere it took the measure from 56 to 85 s, with the
    // process at 720 MiB of its 2 GiB.)
    if (residentBytes() > options_.memoryBytes) releaseFreedMemory();
  }

  // Pending samples against one part of the other surface.
  static void resolve(Pending& p, const std::vector<FloatTriangle>& part) {
    if (p.q.empty() || part.empty()) return;
    const Forest forest(part);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, p.q.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i != r.end(); ++i) {
        Nearest n = std::isfinite(p.d2[i]) ? Nearest(forest, p.q[i], p.closest[i]) : Nearest(forest);
        forest.traverse(p.q[i], n);
        if (n.squaredDistance() < p.d2[i]) p.d2[i] = n.squaredDistance(), p.closest[i] = n.closest();
      }
    });
  }
  // The other surface's non-degenerate triangles, item by item (cells or charts), in parts of
  // about partTriangles.
  template <class TrianglesOf>
  void resolveInParts(Pending& p, size_t items, const TrianglesOf& trianglesOf) const {
    if (p.q.empty()) return;
    const uint64_t partTriangles = std::max<uint64_t>(options_.memoryBytes / 2 / kBytesPerMeshTriangle, 1);
    std::vector<FloatTriangle> part;
    for (size_t i = 0; i < items; ++i) {
      trianglesOf(i, [&](const FloatTriangle& t) {
        if (!t.triangle().is_degenerate()) part.push_back(t);
      });
      if (part.size() >= partTriangles || i + 1 == items) {
        resolve(p, part);
        part.clear();
      }
    }
  }
  // Second pass: samples with nothing near, against the whole other surface, a part at a time.
  void resolvePending() {
    resolveInParts(atlasPending_, gm_.cells.size(), [&](size_t i, const auto& emit) {
      for (const MeshTriangle& t : readCell(gridDir_, gm_, gm_.cells[i])) emit(floatTriangle(t));
    });
    resolveInParts(meshPending_, am_.charts.size(), [&](size_t c, const auto& emit) {
      chartTriangles(readChart(uint32_t(c)), am_.chartFileSize(uint32_t(c)), emit);
    });
  }
  // Both passes' figures together; unresolved samples count at the margin.
  FidelityStats finish(std::chrono::steady_clock::time_point t0) {
    for (double d2 : atlasPending_.d2) atlasMax_ = std::max(atlasMax_, std::sqrt(d2)), atlasSum_ += std::sqrt(d2);
    for (double d2 : meshPending_.d2) meshMax_ = std::max(meshMax_, std::sqrt(d2)), meshSum_ += std::sqrt(d2);
    if (atlasPending_.unresolved)
      atlasMax_ = std::max(atlasMax_, margin_), atlasSum_ += margin_ * atlasPending_.unresolved;
    if (meshPending_.unresolved) meshMax_ = std::max(meshMax_, margin_), meshSum_ += margin_ * meshPending_.unresolved;
    st_.exact = !atlasPending_.unresolved && !meshPending_.unresolved;
    setFigures(st_, atlasMax_, atlasSum_, meshMax_, meshSum_, t0);
    return st_;
  }

  const std::filesystem::path& gridDir_;
  const std::filesystem::path& atlasDir_;
  const GridManifest& gm_;
  const AtlasManifest& am_;
  const OutOfCoreFidelityOptions& options_;
  FidelityStats st_;
  double margin_ = 0;
  std::vector<FloatBox> cellBoxes_, chartBoxes_;
  uint64_t gridCells_ = 0;
  std::vector<std::atomic<uint64_t>> atlasInCell_;
  std::vector<uint64_t> cellCost_;  // estimated working memory of every grid cell
  uint32_t g_ = 1;                  // cells a block side
  std::array<uint32_t, 3> bd_{};    // blocks along each axis
  std::vector<uint8_t> blockUsed_;
  Pending meshPending_, atlasPending_;  // input samples without atlas near, atlas samples without input near
  uint64_t pendingCap_ = 0;
  double atlasMax_ = 0, atlasSum_ = 0, meshMax_ = 0, meshSum_ = 0;
};

}  // namespace

FidelityStats measureFidelityOutOfCore(const std::filesystem::path& gridDir, const std::filesystem::path& atlasDir,
                                       const OutOfCoreFidelityOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!(options.marginFraction > 0.0 && options.marginFraction < 1.0) || options.memoryBytes < (16u << 20))
    throw std::invalid_argument(
        "measureFidelityOutOfCore: the margin must be in (0, 1) and the memory at least 16 MiB");
  const GridManifest gm = readGridManifest(gridDir);
  const AtlasManifest am = readManifest(atlasDir);
  if (am.kind != AtlasKind::Geometry)
    throw InputError((atlasDir / kManifestName).string() + ": a " + atlasKindName(am.kind) +
                     " atlas, not a geometry atlas");
  if (gm.triangles == 0 || gm.bounds.empty() || am.charts.empty())
    throw std::invalid_argument("measureFidelityOutOfCore: a surface has no triangles");
  OutOfCoreMeasure measure(gridDir, atlasDir, gm, am, options);
  return measure.run(t0);
}

namespace {

// Mesh samples bucketed in a uniform grid over their box, to find those within a box quickly.
class SampleGrid {
 public:
  explicit SampleGrid(const std::vector<Point>& p) {
    for (int k = 0; k < 3; ++k) lo_[k] = std::numeric_limits<double>::infinity(), hi_[k] = -lo_[k];
    for (const Point& q : p)
      for (int k = 0; k < 3; ++k) lo_[k] = std::min(lo_[k], q[k]), hi_[k] = std::max(hi_[k], q[k]);
    // No more cells than samples: the cells along the box's longest side grow with the cube root
    // of the count (samples spread over a surface fill a few cells of each column, a few tens a cell).
    const double longest = std::max({hi_[0] - lo_[0], hi_[1] - lo_[1], hi_[2] - lo_[2], 1e-300});
    const double cells = std::clamp(std::cbrt(double(p.size())), 1.0, 1024.0);
    for (int k = 0; k < 3; ++k) {
      dims_[k] = uint32_t(std::clamp(std::ceil(cells * (hi_[k] - lo_[k]) / longest), 1.0, 1024.0));
      step_[k] = std::max((hi_[k] - lo_[k]) / dims_[k], 1e-300);
    }
    std::vector<uint32_t> cellOf(p.size());
    start_.assign(size_t(dims_[0]) * dims_[1] * dims_[2] + 1, 0);
    for (size_t i = 0; i < p.size(); ++i) {
      cellOf[i] = cell(axis(p[i][0], 0), axis(p[i][1], 1), axis(p[i][2], 2));
      ++start_[cellOf[i] + 1];
    }
    for (size_t c = 1; c < start_.size(); ++c) start_[c] += start_[c - 1];
    order_.resize(p.size());
    std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
    for (size_t i = 0; i < p.size(); ++i) order_[fill[cellOf[i]]++] = uint32_t(i);
  }
  // Calls f(i) for every sample i in the cells that meet box b widened by margin.
  template <class F>
  void forEachNear(const FloatBox& b, double margin, F&& f) const {
    uint32_t from[3], to[3];
    for (int k = 0; k < 3; ++k) {
      if (double(b.lo[k]) - margin > hi_[k] || double(b.hi[k]) + margin < lo_[k]) return;
      from[k] = axis(double(b.lo[k]) - margin, k), to[k] = axis(double(b.hi[k]) + margin, k);
    }
    for (uint32_t z = from[2]; z <= to[2]; ++z)
      for (uint32_t y = from[1]; y <= to[1]; ++y) {
        const size_t row = cell(0, y, z);
        for (uint32_t i = start_[row + from[0]]; i < start_[row + to[0] + 1]; ++i) f(order_[i]);
      }
  }

 private:
  uint32_t axis(double x, int k) const {
    const double c = std::floor((x - lo_[k]) / step_[k]);
    return c <= 0.0 ? 0u : c >= dims_[k] - 1 ? dims_[k] - 1 : uint32_t(c);
  }
  size_t cell(uint32_t x, uint32_t y, uint32_t z) const { return x + size_t(dims_[0]) * (y + size_t(dims_[1]) * z); }
  double lo_[3], hi_[3], step_[3];
  uint32_t dims_[3];
  std::vector<uint32_t> start_, order_;
};

// A chart's drawn samples (side s a side) as the renderer triangulates its texels.
std::vector<FloatTriangle> chartFloatTriangles(const std::vector<glm::vec3>& P, uint32_t s) {
  std::vector<Face> faces;
  faces.reserve(size_t(s - 1) * (s - 1) * 2);
  for (uint32_t v = 0; v + 1 < s; ++v)
    for (uint32_t u = 0; u + 1 < s; ++u) {
      const uint32_t a = v * s + u, b = a + 1, c = a + s + 1, d = a + s;
      faces.push_back({a, b, c});
      faces.push_back({a, c, d});
    }
  return nonDegenerate(P, faces, true);
}

// Whether sample `i` of chart c is among those measured when a fraction `keep` (in 2^-64 units)
// of them are.
bool sampleKept(uint32_t c, size_t i, uint64_t keep) {
  uint64_t x = (uint64_t(c) << 40) ^ uint64_t(i);  // splitmix64
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return (x ^ (x >> 31)) < keep;
}

void atomicMin(std::atomic<double>& a, double v) {
  double cur = a.load(std::memory_order_relaxed);
  while (v < cur && !a.compare_exchange_weak(cur, v, std::memory_order_relaxed)) {}
}

}  // namespace

FidelityStats measureFidelityByCharts(const std::vector<glm::vec3>& meshPositions,
                                      const std::vector<std::array<uint32_t, 3>>& meshTriangles,
                                      const std::filesystem::path& atlasDir, const ChartFidelityOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!(options.marginFraction > 0.0 && options.marginFraction < 1.0) || options.atlasSamples == 0)
    throw std::invalid_argument(
        "measureFidelityByCharts: the margin must be in (0, 1) and some atlas samples measured");
  const AtlasManifest am = readManifest(atlasDir);
  if (am.kind != AtlasKind::Geometry)
    throw InputError((atlasDir / kManifestName).string() + ": a " + atlasKindName(am.kind) +
                     " atlas, not a geometry atlas");
  const std::vector<FloatTriangle> mesh = nonDegenerate(meshPositions, meshTriangles);
  if (mesh.empty() || am.charts.empty())
    throw std::invalid_argument("measureFidelityByCharts: a surface has no triangles");
  FidelityStats st;
  st.diagonal = usedDiagonal(meshPositions, meshTriangles);
  const std::vector<Point> meshSamples = meshSamplePoints(meshPositions, meshTriangles, mesh);
  st.meshSamples = meshSamples.size();
  const double margin = options.marginFraction * st.diagonal;
  for (const ChartInfo& c : am.charts) {
    const uint64_t side = ((am.chartSize - 1) >> c.finestLevel) + 1;
    st.atlasSamplesTotal += side * side;
  }
  const bool all = st.atlasSamplesTotal <= options.atlasSamples;
  const uint64_t keep =
      all ? ~0ull : uint64_t(std::ldexp(double(options.atlasSamples) / double(st.atlasSamplesTotal), 64));

  const Forest meshForest(mesh);
  const SampleGrid grid(meshSamples);
  std::vector<std::atomic<double>> best(meshSamples.size());
  for (auto& b : best) b.store(std::numeric_limits<double>::infinity(), std::memory_order_relaxed);
  std::vector<FloatBox> chartBoxes(am.charts.size(), emptyBox());
  struct AtlasSide {
    double max = 0.0, sum = 0.0;
    uint64_t count = 0;
  };
  tbb::enumerable_thread_specific<AtlasSide> atlasSide;
  // Measures the mesh samples `near` chart c's triangles could be closest to (those nearer its
  // box than their best so far) against them.
  auto meshSide = [&](const Forest& chart, const FloatBox& box, auto&& near) {
    near([&](uint32_t i) {
      const Point& q = meshSamples[i];
      const double b = best[i].load(std::memory_order_relaxed);
      const double b2 = b * b;
      if (Nearest::boxDistance2(q, box) >= b2) return;
      Nearest n(chart, b2);
      chart.traverse(q, n);
      if (n.squaredDistance() < b2) atomicMin(best[i], std::sqrt(n.squaredDistance()));
    });
  };
  const progress::ProgressStage stage("fidelity charts", am.charts.size());
  tbb::parallel_for(size_t(0), am.charts.size(), [&](size_t c) {
    const std::vector<glm::vec3> P = readDrawnChartLevel(atlasDir, am, c, 0);
    const uint32_t s = uint32_t(std::lround(std::sqrt(double(P.size()))));
    AtlasSide& a = atlasSide.local();
    Point hint(CGAL::ORIGIN);
    bool first = true;
    for (size_t i = 0; i < P.size(); ++i) {
      extend(chartBoxes[c], P[i]);
      if (!all && !sampleKept(uint32_t(c), i, keep)) continue;
      const Point q(P[i].x, P[i].y, P[i].z);
      Nearest n = first ? Nearest(meshForest) : Nearest(meshForest, q, hint);
      first = false;
      meshForest.traverse(q, n);
      hint = n.closest();
      const double d = std::sqrt(n.squaredDistance());
      a.max = std::max(a.max, d), a.sum += d, ++a.count;
    }
    // Isolated: a thread waiting inside the chart's tree build takes no other chart meanwhile, so
    // only as many charts as threads are held at once.
    tbb::this_task_arena::isolate([&] {
      const std::vector<FloatTriangle> tris = chartFloatTriangles(P, s);
      if (tris.empty()) return;
      const Forest chart(tris);
      meshSide(chart, chartBoxes[c], [&](auto&& f) { grid.forEachNear(chartBoxes[c], margin, f); });
    });
    progress::advance();
  });
  // Samples with nothing within the margin of a chart's box: against every chart nearer than
  // their best.
  std::vector<uint32_t> far;
  for (size_t i = 0; i < best.size(); ++i)
    if (!(best[i].load(std::memory_order_relaxed) <= margin)) far.push_back(uint32_t(i));
  st.samplesBeyondMargin = far.size();
  if (!far.empty()) {
    tbb::parallel_for(size_t(0), am.charts.size(), [&](size_t c) {
      tbb::this_task_arena::isolate([&] {
        const std::vector<glm::vec3> P = readDrawnChartLevel(atlasDir, am, c, 0);
        const std::vector<FloatTriangle> tris =
            chartFloatTriangles(P, uint32_t(std::lround(std::sqrt(double(P.size())))));
        if (tris.empty()) return;
        const Forest chart(tris);
        meshSide(chart, chartBoxes[c], [&](auto&& f) {
          for (uint32_t i : far) f(i);
        });
      });
    });
  }
  double meshMax = 0.0, meshSum = 0.0;
  for (const auto& b : best) {
    const double d = b.load(std::memory_order_relaxed);
    if (!std::isfinite(d)) throw std::invalid_argument("measureFidelityByCharts: the atlas has no triangles");
    meshMax = std::max(meshMax, d), meshSum += d;
  }
  AtlasSide a;
  for (const AtlasSide& t : atlasSide) a.max = std::max(a.max, t.max), a.sum += t.sum, a.count += t.count;
  st.atlasSamples = a.count;
  st.atlasFractionAbove = all ? 0.0 : std::log(100.0) / double(std::max<uint64_t>(a.count, 1));
  setFigures(st, a.max, a.sum, meshMax, meshSum, t0);
  return st;
}

}  // namespace gimlod

#include "atlas/fidelity.h"

#include <algorithm>
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
#include <tbb/task_arena.h>

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

struct GroupDatumMap {  // CGAL's primitive wants a datum: the run's first triangle (the search below reads the whole run)
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
    return Point(0.5 * (double(b.lo[0]) + b.hi[0]), 0.5 * (double(b.lo[1]) + b.hi[1]), 0.5 * (double(b.lo[2]) + b.hi[2]));
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

// The non-degenerate triangles (as a stored Triangle_3 judges them), in input order.
std::vector<FloatTriangle> nonDegenerate(const std::vector<glm::vec3>& p, const std::vector<Face>& t) {
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
      for (int k = 0; k < 9; ++k) b.lo[k % 3] = std::min(b.lo[k % 3], tris_[i].v[k]), b.hi[k % 3] = std::max(b.hi[k % 3], tris_[i].v[k]);
    return b;
  }
  double boxDiagonalSum(size_t run) const {
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, (n_ + run - 1) / run, 4096), 0.0,
        [&](const tbb::blocked_range<size_t>& r, double sum) {
          for (size_t g = r.begin(); g != r.end(); ++g) {
            const FloatBox b = box(g, run);
            sum += std::sqrt(double(b.hi[0] - b.lo[0]) * (b.hi[0] - b.lo[0]) + double(b.hi[1] - b.lo[1]) * (b.hi[1] - b.lo[1]) +
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
      for (int c = 0; c < 3; ++c) lo[c] = std::min(lo[c], centre(ids[i], c)), hi[c] = std::max(hi[c], centre(ids[i], c));
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
template <class Sample>
Acc distances(const Forest& forest, size_t count, const Sample& sample) {
  return tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, count, 1024), Acc{},
      [&](const tbb::blocked_range<size_t>& r, Acc a) {
        Point hint(CGAL::ORIGIN);
        for (size_t i = r.begin(); i != r.end(); ++i) {
          const Point q = sample(i);
          Nearest n = i == r.begin() ? Nearest(forest) : Nearest(forest, q, hint);
          forest.traverse(q, n);
          hint = n.closest();
          const double d = std::sqrt(n.squaredDistance());
          a.max = std::max(a.max, d);
          a.sum += d;
        }
        return a;
      },
      [](Acc a, const Acc& b) {
        a.max = std::max(a.max, b.max);
        a.sum += b.sum;
        return a;
      });
}

}  // namespace

FidelityStats measureFidelity(const std::vector<glm::vec3>& meshPositions,
                              const std::vector<std::array<uint32_t, 3>>& meshTriangles,
                              const std::vector<glm::vec3>& atlasPositions,
                              const std::vector<std::array<uint32_t, 3>>& atlasTriangles) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<FloatTriangle> mesh, atlas;
  tbb::parallel_invoke([&] { mesh = nonDegenerate(meshPositions, meshTriangles); },
                       [&] { atlas = nonDegenerate(atlasPositions, atlasTriangles); });
  if (mesh.empty() || atlas.empty()) throw std::invalid_argument("measureFidelity: a surface has no triangles");
  FidelityStats st;
  glm::vec3 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
  for (const auto& f : meshTriangles)
    for (uint32_t i : f) {
      lo = {std::min(lo.x, meshPositions[i].x), std::min(lo.y, meshPositions[i].y), std::min(lo.z, meshPositions[i].z)};
      hi = {std::max(hi.x, meshPositions[i].x), std::max(hi.y, meshPositions[i].y), std::max(hi.z, meshPositions[i].z)};
    }
  st.diagonal = std::sqrt(double(hi.x - lo.x) * (hi.x - lo.x) + double(hi.y - lo.y) * (hi.y - lo.y) +
                          double(hi.z - lo.z) * (hi.z - lo.z));

  // The mesh side's samples: every vertex a triangle uses, then every non-degenerate triangle's
  // centroid, in input order (coherent, for the hints).
  std::vector<Point> meshSamples;
  {
    std::vector<bool> used(meshPositions.size(), false);
    for (const auto& f : meshTriangles)
      for (uint32_t i : f) used[i] = true;
    meshSamples.reserve(meshPositions.size() + mesh.size());
    for (size_t i = 0; i < meshPositions.size(); ++i)
      if (used[i]) meshSamples.emplace_back(meshPositions[i].x, meshPositions[i].y, meshPositions[i].z);
    for (const FloatTriangle& t : mesh) meshSamples.push_back(CGAL::centroid(t.triangle()));
  }

  // The atlas trees build while the mesh trees build and answer the atlas samples (one CGAL tree
  // builds on one thread, so this keeps both cores busy).
  std::unique_ptr<Forest> atlasForest;
  Acc a;
  tbb::parallel_invoke([&] { atlasForest = std::make_unique<Forest>(atlas); },
                       [&] {
                         const Forest meshForest(mesh);
                         a = distances(meshForest, atlasPositions.size(), [&](size_t i) {
                           return Point(atlasPositions[i].x, atlasPositions[i].y, atlasPositions[i].z);
                         });
                       });
  st.atlasSamples = atlasPositions.size();
  const Acc b = distances(*atlasForest, meshSamples.size(), [&](size_t i) { return meshSamples[i]; });
  st.meshSamples = meshSamples.size();

  st.maxAtlasToMesh = a.max;
  st.meanAtlasToMesh = a.sum / double(std::max<uint64_t>(st.atlasSamples, 1));
  st.maxMeshToAtlas = b.max;
  st.meanMeshToAtlas = b.sum / double(std::max<uint64_t>(st.meshSamples, 1));
  st.hausdorff = std::max(a.max, b.max);
  st.hausdorffPercent = st.diagonal > 0 ? 100.0 * st.hausdorff / st.diagonal : 0.0;
  st.meanPercent = st.diagonal > 0 ? 100.0 * 0.5 * (st.meanAtlasToMesh + st.meanMeshToAtlas) / st.diagonal : 0.0;
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return st;
}

}  // namespace gimlod

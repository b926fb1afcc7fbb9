#include "atlas/fidelity.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

namespace gimlod {
namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;

std::vector<Triangle> toTriangles(const std::vector<glm::vec3>& p, const std::vector<std::array<uint32_t, 3>>& t) {
  std::vector<Triangle> out;
  out.reserve(t.size());
  auto pt = [&](uint32_t i) { return Point(p[i].x, p[i].y, p[i].z); };
  for (const auto& f : t) {
    const Triangle tri(pt(f[0]), pt(f[1]), pt(f[2]));
    if (!tri.is_degenerate()) out.push_back(tri);
  }
  return out;
}

struct Acc {
  double max = 0.0, sum = 0.0;
};

// Distances from every query point to the tree's surface (in parallel; the tree is read-only).
Acc distances(const Tree& tree, const std::vector<Point>& queries) {
  return tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, queries.size(), 1024), Acc{},
      [&](const tbb::blocked_range<size_t>& r, Acc a) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
          const double d = std::sqrt(tree.squared_distance(queries[i]));
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
  const std::vector<Triangle> mesh = toTriangles(meshPositions, meshTriangles);
  const std::vector<Triangle> atlas = toTriangles(atlasPositions, atlasTriangles);
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

  Tree meshTree(mesh.begin(), mesh.end());
  meshTree.accelerate_distance_queries();
  std::vector<Point> q;
  q.reserve(atlasPositions.size());
  for (const glm::vec3& p : atlasPositions) q.emplace_back(p.x, p.y, p.z);
  const Acc a = distances(meshTree, q);
  st.atlasSamples = q.size();

  Tree atlasTree(atlas.begin(), atlas.end());
  atlasTree.accelerate_distance_queries();
  q.clear();
  std::vector<bool> used(meshPositions.size(), false);
  for (const auto& f : meshTriangles)
    for (uint32_t i : f) used[i] = true;
  for (size_t i = 0; i < meshPositions.size(); ++i)
    if (used[i]) q.emplace_back(meshPositions[i].x, meshPositions[i].y, meshPositions[i].z);
  for (const Triangle& t : mesh) q.push_back(CGAL::centroid(t));
  const Acc b = distances(atlasTree, q);
  st.meshSamples = q.size();

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

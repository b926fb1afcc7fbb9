// Atlas fidelity: the two-sided distance between the input mesh and the atlas surface, as the
// issue's quality figure (a sampled Hausdorff distance, in units of the input's bounding-box
// diagonal). Uses CGAL's AABB tree for the closest-point queries.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <glm/vec3.hpp>

namespace gimlod {

struct FidelityStats {
  double diagonal = 0.0;            // of the input mesh's bounding box
  double maxAtlasToMesh = 0.0;      // over every atlas vertex: distance to the input surface
  double meanAtlasToMesh = 0.0;
  double maxMeshToAtlas = 0.0;      // over every input vertex and triangle centroid: to the atlas
  double meanMeshToAtlas = 0.0;
  double hausdorff = 0.0;           // max of the two maxima
  double hausdorffPercent = 0.0;    // hausdorff / diagonal * 100
  double meanPercent = 0.0;         // mean of the two means / diagonal * 100
  uint64_t atlasSamples = 0, meshSamples = 0;
  double seconds = 0.0;
};

// Both surfaces as positions + triangles. The atlas side is sampled at its vertices (the chart
// samples), the mesh side at its vertices and triangle centroids. Throws std::invalid_argument
// when either surface has no triangles.
FidelityStats measureFidelity(const std::vector<glm::vec3>& meshPositions,
                              const std::vector<std::array<uint32_t, 3>>& meshTriangles,
                              const std::vector<glm::vec3>& atlasPositions,
                              const std::vector<std::array<uint32_t, 3>>& atlasTriangles);

}  // namespace gimlod

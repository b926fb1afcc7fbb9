// The cut as drawn, as one mesh: every node's grid with the stitched world positions captured from
// the vertex shader (transform feedback), triangulated as the renderer draws it, with vertices of
// bit-identical positions welded. A watertight draw leaves boundary edges only along open chart
// borders (the input's own holes and rims); any other boundary edge is a crack, or the edge of
// what the view culled.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "hierarchy/hierarchy.h"
#include "runtime/cut.h"

namespace gimlod {

struct CutMesh {
  std::vector<glm::vec3> positions;
  // Per vertex: the first node (in cut order) that drew it, and that node's resolution (log2
  // intervals); a welded vertex belongs to every node around it.
  std::vector<uint32_t> chart;
  std::vector<uint8_t> level, resLog2;
  std::vector<uint32_t> nodeX, nodeY;
  std::vector<std::array<uint32_t, 3>> triangles;
  uint64_t boundaryEdges = 0;       // edges used by one triangle only
  uint64_t openBorderEdges = 0;     // of those, along chart borders without a neighbour (or, for a
                                    // height field, along the edge of the DEM's valid samples)
  uint64_t otherBoundaryEdges = 0;  // the rest: cracks, or the edge of the culled part of the view
};

// Builds the mesh of `cut` from captured[i], the (2^res + 1)^2 stitched positions of cut node i
// (row j * (2^res + 1) + i, as AtlasRenderer::captureVertices returns them). Each grid quad is split
// along its (0,0)-(1,1) diagonal, counter-clockwise in (u, v). Throws std::invalid_argument when a
// node's vertex count does not match its resolution. validRect (height fields): the world (x, y)
// rectangle of the DEM's valid samples; a vertex on or past its edge is on the input's own border
// too (charts reach past the DEM, and nodes wholly outside it are not drawn).
CutMesh buildCutMesh(const Hierarchy& h, const Cut& cut, const std::vector<std::vector<glm::vec3>>& captured,
                     const std::array<glm::dvec2, 2>* validRect = nullptr);

// Writes a binary little-endian PLY: float x y z, uint chart, uchar level, uint node_x, node_y,
// uchar res per vertex; uchar-list uint vertex_indices per face. Atomic; throws InputError.
void writeCutMeshPly(const std::filesystem::path& path, const CutMesh& mesh);

}  // namespace gimlod

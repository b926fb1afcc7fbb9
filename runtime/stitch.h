// Border stitching tables for the GPU (paper section 7.4) and the crack check that verifies the
// stitched positions captured from the real vertex shader. Pure C++.
#pragma once

#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

#include "runtime/cut.h"
#include "runtime/draw_list.h"

namespace gimlod {

// Fills, for every cut node and side, the log2 vertex spacing of the neighbour drawn there.
// Nodes are in cut order. See StitchTables for the layout.
// Where any node of the cut has a geomorph factor above 0, also fills StitchTables::morphs with the
// neighbours' morph bytes.
StitchTables buildStitchTables(const Hierarchy& h, const Cut& cut);

struct CrackReport {
  uint64_t borderVertices = 0;  // border vertices checked (sides with a drawn neighbour)
  uint64_t mismatches = 0;      // of those, ones that match no vertex of the neighbours there
  uint64_t sharedSides = 0;     // node sides with at least one drawn neighbour
};

// vertices[i] holds cut node i's stitched positions, index j * (2^res + 1) + i, as captured by
// transform feedback. Every border vertex must coincide bit for bit with a vertex on the facing
// side of a neighbour across that side.
CrackReport countCracks(const Hierarchy& h, const Cut& cut, const std::vector<std::vector<glm::vec3>>& vertices);

}  // namespace gimlod

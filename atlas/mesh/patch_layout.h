// The chart layout of a mesh atlas: the surface cut into disk-shaped patches with 3 to 8 sides
// (up to kMaxPatchSides once made even for the sides quad layout, atlas/mesh/resample.h),
// each side shared with exactly one other patch (or open), as produced by clustering
// (atlas/mesh/charting.h) and consumed by parameterization and resampling
// (atlas/mesh/patch_param.h).
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5; Purnomo, Cohen, Kumar, "Seamless Texture
// Atlases", SGP 2004 (patches, conforming quad layout, shared boundary sampling).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

namespace gimlod {

// The most sides a patch may have: clustering keeps 3..8 and the chart repair's cuts 3..9; making
// the side counts even (evenSides, atlas/mesh/layout_refine.h) may add corners up to this.
inline constexpr uint32_t kMaxPatchSides = 12;

// One side of a patch: the boundary run between two consecutive corners, as mesh vertex ids,
// in the patch's counter-clockwise boundary order (outward normals, seen from outside).
struct PatchSide {
  std::vector<uint32_t> vertices;  // first and last are corners; at least 2 entries
  int32_t neighbourPatch = -1;     // the patch across this side; -1: open boundary (a hole)
  uint32_t neighbourSide = 0;      // index of the same side in the neighbour's `sides`
  // The neighbour lists the same vertices in reverse order (always true for two consistently
  // oriented patches; false would mean a non-orientable join).
  bool reversed = true;
};

// A topological disk of the input surface.
struct Patch {
  std::vector<uint32_t> triangles;  // indices into PatchLayout::triangles
  std::vector<PatchSide> sides;     // 3..kMaxPatchSides, counter-clockwise; side i ends where side i+1 starts
};

// The surface (welded, manifold, after repair) and its patches. Every triangle belongs to
// exactly one patch; every side with a neighbour appears in both patches, reversed.
struct PatchLayout {
  std::vector<glm::vec3> positions;
  std::vector<glm::u8vec4> colours;                // empty, or one per position
  std::vector<std::array<uint32_t, 3>> triangles;  // counter-clockwise (outward normals)
  std::vector<Patch> patches;
};

// The length of a side's vertex run (the sum of its edges' lengths).
double sideLength(const PatchLayout& layout, const PatchSide& side);
// The mean of patch `patch`'s side lengths.
double meanSideLength(const PatchLayout& layout, uint32_t patch);

// Checks a layout independently of how it was built; returns one line per violation (capped at
// 100 lines), empty when valid: indices in range; every triangle in exactly one patch; each
// patch a topological disk (V - E + F = 1 and one simple boundary loop); minSides..maxSides
// sides; the sides chained, corner to corner, exactly along the patch's counter-clockwise
// boundary loop; neighbour sides reciprocal with reversed vertex lists; open sides only on edges
// with a single triangle in the whole mesh.
std::vector<std::string> validatePatchLayout(const PatchLayout& layout, uint32_t minSides = 3, uint32_t maxSides = 8);

}  // namespace gimlod

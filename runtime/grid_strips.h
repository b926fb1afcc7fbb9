// Index buffers for the reusable (u,v) grids (paper section 7.3): triangle strips of adjacent
// columns in vertical bands, joined with primitive restart. Pure CPU; no GL.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace gimlod {

inline constexpr uint32_t kPrimitiveRestartIndex = 0xFFFFFFFFu;  // GL_PRIMITIVE_RESTART_FIXED_INDEX
inline constexpr uint32_t kStripBandQuads = 16;                  // about half a post-transform vertex cache

using Triangle = std::array<uint32_t, 3>;

// Vertex index of grid vertex (i, j) in a grid with n = 2^res intervals per side (row-major).
inline uint32_t gridVertexIndex(uint32_t res, uint32_t i, uint32_t j) { return j * ((1u << res) + 1u) + i; }

// Strip indices for the (2^res+1)^2 grid: bands of bandQuads columns, one strip per row of
// quads in each band, strips separated by kPrimitiveRestartIndex. Every quad (i,j)-(i+1,j+1) is
// split along the diagonal (i,j)-(i+1,j+1); the strips wind counter-clockwise seen from +z.
std::vector<uint32_t> buildGridStripIndices(uint32_t res, uint32_t bandQuads = kStripBandQuads);

// Expands restart-separated triangle strips into triangles with GL's strip winding rule (odd
// triangles swap their first two vertices); drops degenerate triangles.
std::vector<Triangle> expandStrips(std::span<const uint32_t> indices, uint32_t restart = kPrimitiveRestartIndex);

// The triangles the hierarchy's error metric assumes, counter-clockwise: per quad
// {(i,j),(i+1,j),(i+1,j+1)} and {(i,j),(i+1,j+1),(i,j+1)}.
std::vector<Triangle> expectedGridTriangles(uint32_t res);

}  // namespace gimlod

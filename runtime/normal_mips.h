// The mip chains of a page's attribute maps (normals, colours), computed on the CPU before upload,
// so each node's attributes can be read at its attribute resolution (paper 7.1, 7.3). Pure C++;
// no GL.
#pragma once

#include <cstdint>
#include <vector>

#include "core/atlas_format.h"

namespace gimlod {

// Mip `level` (>= 1) of a page's normal map of samplesPerSide^2 texels in a pageSide^2 pool layer:
// each texel is the renormalised mean of the level-0 texels it covers. Writes side^2 normals
// (row-major) to out and returns side, the texels of that level that cover the page's data.
uint32_t normalMipLevel(const PackedNormal* normals, uint32_t samplesPerSide, uint32_t pageSide, uint32_t level,
                        std::vector<PackedNormal>& out);

// The same for a page's RGBA8 colours: each texel the rounded mean of the level-0 texels it covers.
uint32_t colourMipLevel(const PackedColour* colours, uint32_t samplesPerSide, uint32_t pageSide, uint32_t level,
                        std::vector<PackedColour>& out);

}  // namespace gimlod

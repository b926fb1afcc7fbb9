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

// A page's attribute mip chains from level 1 on, as a pool of pageSide^2 layers takes them:
// level l's texels (row-major) at [l - 1], with their side. Made before the upload where the
// render thread should not (the page loader's threads).
struct PageMips {
  std::vector<std::vector<PackedNormal>> normals;
  std::vector<std::vector<PackedColour>> colours;
  std::vector<uint32_t> normalSides, colourSides;
  size_t bytes() const {
    size_t b = 0;
    for (const auto& l : normals) b += l.size() * sizeof(PackedNormal);
    for (const auto& l : colours) b += l.size() * sizeof(PackedColour);
    return b;
  }
};

// One of a page's attribute maps as pageMips takes it: samplesPerSide^2 texels (row-major; none
// when null) for pool layers of layerSide^2 with `levels` mip levels.
template <typename Texel>
struct PageMap {
  const Texel* texels = nullptr;
  uint32_t samplesPerSide = 0;
  uint32_t layerSide = 0;
  uint32_t levels = 0;
};

// The mips of a page's normals and of its colours: normalMipLevel and colourMipLevel of each level
// of their maps.
PageMips pageMips(const PageMap<PackedNormal>& normals, const PageMap<PackedColour>& colours);

}  // namespace gimlod

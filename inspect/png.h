// Images of the inspection report and the command-line tool: PNG writing (the heat ramp the
// report's maps share is runtime/overlay.h heatColour).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "runtime/overlay.h"

namespace gimlod {

// Writes an 8-bit PNG of `channels` (3: RGB, 4: RGBA) per pixel, rows top first, atomically (a
// temporary file, then rename). Throws InputError naming the file.
void writePng(const std::filesystem::path& path, uint32_t width, uint32_t height, uint32_t channels,
              const std::vector<uint8_t>& pixels);

// writePng of RGB pixels.
inline void writePngRgb(const std::filesystem::path& path, uint32_t width, uint32_t height,
                        const std::vector<uint8_t>& rgb) {
  writePng(path, width, height, 3, rgb);
}

}  // namespace gimlod

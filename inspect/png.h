// Images of the inspection report: PNG writing and the colour ramp its heat maps share.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

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

// The heat ramp for t in [0, 1]: blue, green, red.
std::array<uint8_t, 3> heatColour(double t);

}  // namespace gimlod

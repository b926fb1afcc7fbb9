// Images of the inspection report: PNG writing and the colour ramp its heat maps share.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

namespace gimlod {

// Writes an 8-bit RGB PNG (rows top first). Throws InputError naming the file.
void writePngRgb(const std::filesystem::path& path, uint32_t width, uint32_t height, const std::vector<uint8_t>& rgb);

// The heat ramp for t in [0, 1]: blue, green, red.
std::array<uint8_t, 3> heatColour(double t);

}  // namespace gimlod

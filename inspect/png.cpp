#include "inspect/png.h"

#include <algorithm>
#include <cmath>

#include <OpenImageIO/imageio.h>

#include "core/atlas_format.h"

namespace gimlod {

void writePngRgb(const std::filesystem::path& path, uint32_t width, uint32_t height, const std::vector<uint8_t>& rgb) {
  auto out = OIIO::ImageOutput::create(path.string());
  const OIIO::ImageSpec spec(int(width), int(height), 3, OIIO::TypeDesc::UINT8);
  if (!out || !out->open(path.string(), spec) || !out->write_image(OIIO::TypeDesc::UINT8, rgb.data()) || !out->close())
    throw InputError(path.string() + ": cannot write the image");
}

std::array<uint8_t, 3> heatColour(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const auto u = [](double x) { return uint8_t(std::lround(std::clamp(x, 0.0, 1.0) * 255.0)); };
  return {u(t < 0.5 ? 0.0 : 2.0 * t - 1.0), u(t < 0.5 ? 2.0 * t : 2.0 - 2.0 * t), u(t < 0.5 ? 1.0 - 2.0 * t : 0.0)};
}

}  // namespace gimlod

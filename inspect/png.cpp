#include "inspect/png.h"

#include <algorithm>
#include <cmath>

#include <OpenImageIO/imageio.h>

#include "core/atlas_format.h"

namespace gimlod {

void writePng(const std::filesystem::path& path, uint32_t width, uint32_t height, uint32_t channels,
              const std::vector<uint8_t>& pixels) {
  if (pixels.size() != size_t(width) * height * channels)
    throw InputError(path.string() + ": image data does not match its size");
  const std::filesystem::path tmp = path.string() + ".tmp.png";
  auto out = OIIO::ImageOutput::create(tmp.string());
  const OIIO::ImageSpec spec(int(width), int(height), int(channels), OIIO::TypeDesc::UINT8);
  if (!out || !out->open(tmp.string(), spec) || !out->write_image(OIIO::TypeDesc::UINT8, pixels.data()) ||
      !out->close()) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    throw InputError(path.string() + ": cannot write the image" + (out ? ": " + out->geterror() : std::string()));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw InputError(path.string() + ": " + ec.message());
}

std::array<uint8_t, 3> heatColour(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const auto u = [](double x) { return uint8_t(std::lround(std::clamp(x, 0.0, 1.0) * 255.0)); };
  return {u(t < 0.5 ? 0.0 : 2.0 * t - 1.0), u(t < 0.5 ? 2.0 * t : 2.0 - 2.0 * t), u(t < 0.5 ? 1.0 - 2.0 * t : 0.0)};
}

}  // namespace gimlod

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

}  // namespace gimlod

// libFuzzer harness for the camera path reader (scenes/*.json): bad input must end in InputError,
// and an accepted path has only finite cameras.
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "core/atlas_format.h"
#include "runtime/camera.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = gimlod::fuzz::writeInput("path.json", data, size);
  try {
    for (const gimlod::Camera& c : gimlod::readCameraPath(path)) {
      const glm::dvec3 sum = c.eye + c.target + c.up;
      if (!std::isfinite(sum.x + sum.y + sum.z + c.fovYDeg + c.nearPlane + c.farPlane)) __builtin_trap();
    }
  } catch (const gimlod::InputError&) {}
  return 0;
}

#include "core/level_surface.h"

#include <stdexcept>

#include "core/atlas_format.h"

namespace gimlod {

std::vector<float> geometryLevelErrors(const std::vector<glm::vec3>& positions, uint32_t side, uint32_t levels) {
  if (!isChartSizeValid(side) || positions.size() != size_t(side) * side || (side - 1) >> levels == 0)
    throw std::invalid_argument("geometryLevelErrors: positions do not match the side, or too many levels");
  std::vector<float> out(levels + 1, 0.0f), running(positions.size(), 0.0f);
  for (uint32_t k = 1; k <= levels; ++k) {
    accumulateLevelError(positions, side, k, running, PointDistance{});
    out[k] = *std::max_element(running.begin(), running.end());
  }
  return out;
}

std::vector<glm::vec3> geometryLevelSurface(const std::vector<glm::vec3>& positions, uint32_t side, uint32_t k) {
  if (!isChartSizeValid(side) || positions.size() != size_t(side) * side || (side - 1) >> k == 0)
    throw std::invalid_argument("geometryLevelSurface: positions do not match the side, or a level past the pyramid");
  std::vector<glm::vec3> out(positions.size());
  forEachLevelSample(positions, side, k, [&](size_t i, const glm::vec3& p) { out[i] = p; });
  return out;
}

}  // namespace gimlod

#include "runtime/normal_mips.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace gimlod {

uint32_t normalMipLevel(const PackedNormal* normals, uint32_t samplesPerSide, uint32_t pageSide, uint32_t level,
                        std::vector<PackedNormal>& out) {
  const uint32_t mipSide = std::max(1u, pageSide >> level);
  // Texels of the level covering the page's data: level-0 texel t lies at (t + 0.5) / pageSide.
  const uint32_t side = std::min(mipSide, (samplesPerSide * mipSide + pageSide - 1) / pageSide);
  out.assign(size_t(side) * side, PackedNormal{});
  auto range = [&](uint32_t m, uint32_t* a, uint32_t* b) {
    *a = std::min(m * pageSide / mipSide, samplesPerSide - 1);
    *b = std::clamp((m + 1) * pageSide / mipSide, *a + 1, samplesPerSide);
  };
  for (uint32_t j = 0; j < side; ++j) {
    uint32_t y0, y1;
    range(j, &y0, &y1);
    for (uint32_t i = 0; i < side; ++i) {
      uint32_t x0, x1;
      range(i, &x0, &x1);
      float sum[3] = {0.f, 0.f, 0.f};
      for (uint32_t y = y0; y < y1; ++y)
        for (uint32_t x = x0; x < x1; ++x) {
          const std::array<float, 3> n = unpackNormal(normals[size_t(y) * samplesPerSide + x]);
          for (int c = 0; c < 3; ++c) sum[c] += n[c];
        }
      const float len = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
      out[size_t(j) * side + i] =
          len > 1e-12f ? packNormal(sum[0] / len, sum[1] / len, sum[2] / len) : packNormal(0.f, 0.f, 1.f);
    }
  }
  return side;
}

}  // namespace gimlod

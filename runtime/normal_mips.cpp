#include "runtime/normal_mips.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace gimlod {

namespace {

// Mip `level` of a samplesPerSide^2 map in a pageSide^2 layer; texel (i, j) is mean(first, last)
// over the level-0 texels [x0, x1) x [y0, y1) it covers, `mean` given their range.
template <typename T, typename Mean>
uint32_t mipLevel(uint32_t samplesPerSide, uint32_t pageSide, uint32_t level, std::vector<T>& out, Mean mean) {
  const uint32_t mipSide = std::max(1u, pageSide >> level);
  // Texels of the level covering the page's data: level-0 texel t lies at (t + 0.5) / pageSide.
  const uint32_t side = std::min(mipSide, (samplesPerSide * mipSide + pageSide - 1) / pageSide);
  out.assign(size_t(side) * side, T{});
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
      out[size_t(j) * side + i] = mean(x0, x1, y0, y1);
    }
  }
  return side;
}

}  // namespace

uint32_t normalMipLevel(const PackedNormal* normals, uint32_t samplesPerSide, uint32_t pageSide, uint32_t level,
                        std::vector<PackedNormal>& out) {
  return mipLevel(samplesPerSide, pageSide, level, out, [&](uint32_t x0, uint32_t x1, uint32_t y0, uint32_t y1) {
    float sum[3] = {0.f, 0.f, 0.f};
    for (uint32_t y = y0; y < y1; ++y)
      for (uint32_t x = x0; x < x1; ++x) {
        const std::array<float, 3> n = unpackNormal(normals[size_t(y) * samplesPerSide + x]);
        for (int c = 0; c < 3; ++c) sum[c] += n[c];
      }
    const float len = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
    return len > 1e-12f ? packNormal(sum[0] / len, sum[1] / len, sum[2] / len) : packNormal(0.f, 0.f, 1.f);
  });
}

uint32_t colourMipLevel(const PackedColour* colours, uint32_t samplesPerSide, uint32_t pageSide, uint32_t level,
                        std::vector<PackedColour>& out) {
  return mipLevel(samplesPerSide, pageSide, level, out, [&](uint32_t x0, uint32_t x1, uint32_t y0, uint32_t y1) {
    uint32_t sum[4] = {0, 0, 0, 0};
    for (uint32_t y = y0; y < y1; ++y)
      for (uint32_t x = x0; x < x1; ++x)
        for (int c = 0; c < 4; ++c) sum[c] += colours[size_t(y) * samplesPerSide + x][size_t(c)];
    const uint32_t n = (x1 - x0) * (y1 - y0);
    PackedColour m{};
    for (int c = 0; c < 4; ++c) m[size_t(c)] = uint8_t((sum[c] + n / 2) / n);
    return m;
  });
}

PageMips pageMips(const PageMap<PackedNormal>& normals, const PageMap<PackedColour>& colours) {
  PageMips m;
  for (uint32_t level = 1; normals.texels && level < normals.levels; ++level) {
    m.normals.emplace_back();
    m.normalSides.push_back(
        normalMipLevel(normals.texels, normals.samplesPerSide, normals.layerSide, level, m.normals.back()));
  }
  for (uint32_t level = 1; colours.texels && level < colours.levels; ++level) {
    m.colours.emplace_back();
    m.colourSides.push_back(
        colourMipLevel(colours.texels, colours.samplesPerSide, colours.layerSide, level, m.colours.back()));
  }
  return m;
}

}  // namespace gimlod

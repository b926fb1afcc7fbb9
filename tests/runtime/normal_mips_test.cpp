// Normal-map mips computed on the CPU before upload. No GL.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "runtime/normal_mips.h"

namespace gimlod {
namespace {

TEST(NormalMips, MeanOfCoveredTexelsRenormalised) {
  // A 5x5 page in a 9-wide pool layer; left half tilted +x, right half tilted -x.
  const uint32_t s = 5, pageSide = 9;
  std::vector<PackedNormal> n(s * s);
  for (uint32_t v = 0; v < s; ++v)
    for (uint32_t u = 0; u < s; ++u) n[v * s + u] = u < 2 ? packNormal(0.6f, 0.f, 0.8f) : packNormal(-0.6f, 0.f, 0.8f);
  std::vector<PackedNormal> mip;
  // Level 1 of a 9-wide layer has 4 texels a side; the page's 5 samples cover 3 of them.
  EXPECT_EQ(normalMipLevel(n.data(), s, pageSide, 1, mip), 3u);
  ASSERT_EQ(mip.size(), 9u);
  // Texel 0 covers level-0 texels [0, 2): all +x.
  EXPECT_NEAR(unpackNormal(mip[0])[0], 0.6f, 0.01f);
  // The last level is one texel: the renormalised mean of everything, about straight up.
  const uint32_t last = normalMipLevel(n.data(), s, pageSide, 3, mip);
  EXPECT_EQ(last, 1u);
  const auto up = unpackNormal(mip[0]);
  EXPECT_LT(std::abs(up[0]), 0.3f);
  EXPECT_NEAR(std::sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]), 1.f, 0.02f);
}

}  // namespace
}  // namespace gimlod

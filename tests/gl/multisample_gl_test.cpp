// Multisampling (SceneOptions::samples): the shipped DEM seen from straight above across its corner,
// whose edges are where the fragments past its last samples are discarded. With one sample a
// pixel there is either background or ground; with four, shaded per sample, the edge pixels blend
// the two, while the ground away from the edge stays as it was.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"
#include "tests/gl/gl_context_test.h"
#include "tests/small_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

class MultisampleTest : public test::GlContextTest<> {
 protected:
  static void SetUpTestSuite() {
    test::GlContextTest<>::SetUpTestSuite();
    dir_ = std::make_unique<test::TempDir>("gimlod-msaa");
    test::buildRainierAtlas(dir_->path() / "atlas", 129, 4, 32, 2);
  }
  static void TearDownTestSuite() {
    dir_.reset();
    test::GlContextTest<>::TearDownTestSuite();
  }
  static AtlasView atlas() { return openAtlas(dir_->path() / "atlas"); }
  static inline std::unique_ptr<test::TempDir> dir_;
};

std::vector<uint8_t> renderCorner(const AtlasView& atlas, uint32_t samples) {
  gl::SceneOptions so;
  so.width = 160;
  so.height = 120;
  so.samples = samples;
  gl::AtlasScene scene(atlas, so);
  const glm::dvec3 ext = atlas.hi - atlas.lo;
  // Straight down on the far corner (x and y at their largest), turned so the edges run diagonally.
  Camera c;
  c.target = glm::dvec3(atlas.hi.x, atlas.hi.y, atlas.lo.z);
  c.eye = c.target + glm::dvec3(0.0, 0.0, ext.z + 0.4 * ext.x);
  c.up = glm::normalize(glm::dvec3(1.0, 0.4, 0.0));
  c.nearPlane = c.farPlane = 0.0;
  fitClipPlanes(c, atlas.lo, atlas.hi);
  AdaptOptions o;
  o.tolerancePx = 1.0;
  o.maxNodes = 400;
  scene.renderFrame(c, o);
  return scene.renderer().readPixels();
}

TEST_F(MultisampleTest, TheDemsEdgeBlendsWithTheBackground) {
  const AtlasView atlas = this->atlas();
  const std::vector<uint8_t> one = renderCorner(atlas, 1), four = renderCorner(atlas, 4);
  ASSERT_EQ(one.size(), four.size());
  const gl::SceneOptions defaults;
  uint8_t bg[3];
  for (int c = 0; c < 3; ++c) bg[c] = uint8_t(std::lround(defaults.background[c] * 255.f));
  auto differs = [](const uint8_t* a, const uint8_t* b, int by) {
    for (int c = 0; c < 3; ++c)
      if (std::abs(int(a[c]) - int(b[c])) > by) return true;
    return false;
  };
  uint64_t ground = 0, background = 0, blended = 0, sameGround = 0;
  for (size_t p = 0; p < one.size(); p += 4) {
    const bool isBackground = !differs(&one[p], bg, 1);
    background += isBackground;
    ground += !isBackground;
    if (isBackground) continue;
    // Ground in the one-sample picture: with four samples, the same, or part background.
    const bool same = !differs(&four[p], &one[p], 12);
    sameGround += same;
    blended += !same && differs(&four[p], bg, 1);
  }
  ASSERT_GT(ground, 1000u) << "the DEM's corner should fill part of the picture";
  ASSERT_GT(background, 1000u) << "the background should fill part of the picture";
  // Each edge crosses the 160 x 120 picture: tens of pixels at least blend.
  EXPECT_GT(blended, 40u);
  // Away from the edges the ground is as it was.
  EXPECT_GT(sameGround, ground * 9 / 10);
}

TEST_F(MultisampleTest, MoreSamplesThanTheGlOffersIsAClearError) {
  const AtlasView atlas = this->atlas();
  gl::SceneOptions so;
  so.width = 32;
  so.height = 32;
  so.samples = 1024;
  try {
    gl::AtlasScene scene(atlas, so);
    FAIL() << "1024 samples per pixel accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("1024 samples"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace gimlod

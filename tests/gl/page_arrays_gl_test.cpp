// The GPU page pool past one texture array (GL_MAX_ARRAY_TEXTURE_LAYERS, 2048 on Mesa and
// NVIDIA): an atlas of more charts than that, whose root pages all stay resident, is drawn without
// cracks; and a pool cut into many small arrays draws the same frames as one array, bit for bit.
#include <gtest/gtest.h>

#include <epoxy/gl.h>

#include <algorithm>
#include <cstring>
#include <iostream>

#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"
#include "tests/gl/crack_check.h"
#include "tests/gl/gl_context_test.h"
#include "tests/small_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

class PageArraysTest : public test::GlContextTest<> {
 protected:
  // The shipped Rainier tile (1201^2 samples) in charts of chartSize^2, opened.
  // maxRoots: as openAtlas (0: no groups above the charts).
  AtlasView buildRainier(uint32_t chartSize, uint32_t depth, uint32_t nodeRes, uint32_t maxRoots = kDefaultMaxRoots) {
    const std::filesystem::path out = dir_.path() / ("rainier_" + std::to_string(chartSize));
    if (!std::filesystem::exists(out)) test::buildRainierAtlas(out, chartSize, depth, nodeRes, 1);
    return openAtlas(out, maxRoots);
  }

  static Camera overview(const AtlasView& atlas) {
    Camera cam = orbitPath(atlas.lo, atlas.hi, 1, 0.7, 35.0)[0];
    fitClipPlanes(cam, atlas.lo, atlas.hi);
    return cam;
  }

  test::TempDir dir_{"gimlod-page-arrays"};
};

// Charts of 17^2 make 75 x 75 = 5,625 charts, every one's root page resident: more pages than a
// texture array holds. Every chart root a root of the forest (no groups): a pool made for cuts of
// as many nodes as charts holds them all.
TEST_F(PageArraysTest, AnAtlasOfMoreChartsThanATextureArrayHoldsIsDrawn) {
  const AtlasView atlas = buildRainier(17, 2, 8, 0);
  GLint maxLayers = 0;
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &maxLayers);
  const uint32_t charts = atlas.hierarchy.chartCount();
  ASSERT_GT(charts, uint32_t(maxLayers));
  gl::SceneOptions so;
  so.width = 192;
  so.height = 144;
  so.minNodeRoom = charts;
  gl::AtlasScene scene(atlas, so);
  EXPECT_GT(scene.renderer().pageCapacity(), charts);
  EXPECT_GE(scene.renderer().pageArrays(), (charts + uint32_t(maxLayers) - 1) / uint32_t(maxLayers));
  EXPECT_GE(scene.nodeRoom(), charts);
  AdaptOptions o;
  o.tolerancePx = 0.5;
  const gl::FrameResult f = scene.renderFrame(overview(atlas), o);
  const test::CutMix mix = test::cutMix(atlas.hierarchy, f.cut);
  std::cout << "  " << charts << " charts, " << scene.renderer().pageArrays() << " arrays; cut of "
            << f.cut.nodes.size() << " nodes, " << mix.crossChartResDiff << " chart sides between resolutions, "
            << f.draw.drawCalls << " multi-draws\n";
  EXPECT_GT(mix.crossChartResDiff, 0u) << "the cut should stitch across charts";
  EXPECT_EQ(f.pagesMissing, 0u);
  EXPECT_GT(f.cut.nodes.size(), size_t(maxLayers)) << "the overview should draw roots from every array";
  EXPECT_GE(f.draw.drawCalls, 2u);
  // The tile fills the middle of the picture.
  const std::vector<uint8_t> px = scene.renderer().readPixels();
  uint32_t background = 0, middle = 0;
  for (uint32_t y = so.height / 3; y < 2 * so.height / 3; ++y)
    for (uint32_t x = so.width / 3; x < 2 * so.width / 3; ++x, ++middle) {
      const uint8_t* p = px.data() + (size_t(y) * so.width + x) * 4;
      background += std::abs(p[2] - int(so.background[2] * 255.f + 0.5f)) <= 2 &&
                    std::abs(p[0] - int(so.background[0] * 255.f + 0.5f)) <= 2;
    }
  EXPECT_LT(background, middle / 10);
  // Its stitched borders, from the real vertex shader reading every array: no crack.
  const CrackReport r = test::captureCracks(scene, f.cut);
  EXPECT_GT(r.borderVertices, 10000u);
  EXPECT_EQ(r.mismatches, 0u);
}

// The same 5,625 charts with their roots in groups: a budget of 100 nodes holds, closed groups draw
// their roots from every array with no missing page, and the stitched borders have no crack.
TEST_F(PageArraysTest, GroupsOfManyChartsHoldABudgetOfAHundredNodes) {
  const AtlasView atlas = buildRainier(17, 2, 8);
  ASSERT_FALSE(atlas.hierarchy.groups.empty());
  gl::SceneOptions so;
  so.width = 192;
  so.height = 144;
  gl::AtlasScene scene(atlas, so);
  for (const double distance : {0.7, 0.2}) {
    SCOPED_TRACE(distance);
    Camera cam = orbitPath(atlas.lo, atlas.hi, 1, distance, 35.0)[0];
    fitClipPlanes(cam, atlas.lo, atlas.hi);
    AdaptOptions o;
    o.tolerancePx = 0.5;
    o.maxNodes = 100;
    const gl::FrameResult f = scene.renderFrame(cam, o);
    EXPECT_LE(f.cut.nodeCount(), 100u);
    EXPECT_GT(f.adapt.closedGroups, 0u);
    EXPECT_FALSE(f.adapt.budgetBelowRoots);
    EXPECT_EQ(f.pagesMissing, 0u);
    const CrackReport r = test::captureCracks(scene, f.cut);
    std::cout << "  distance " << distance << ": " << f.cut.nodeCount() << " nodes (" << f.adapt.closedGroups
              << " closed groups of " << f.adapt.groupedRoots << " roots), " << f.cut.nodes.size()
              << " drawn, max error " << f.maxErrorPx << " px; " << r.borderVertices << " border vertices\n";
    EXPECT_GT(r.borderVertices, 1000u);
    EXPECT_EQ(r.mismatches, 0u);
  }
}

// The same atlas and frames with the pool in arrays of 50 layers (eight or more arrays) and in one:
// the same cuts, pages and pictures, bit for bit, and the transform-feedback capture alike.
TEST_F(PageArraysTest, ManySmallArraysDrawTheFramesOfOne) {
  const AtlasView atlas = buildRainier(65, 4, 16);
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  gl::AtlasScene one(atlas, so);
  so.layersPerArray = 50;
  gl::AtlasScene many(atlas, so);
  EXPECT_EQ(one.renderer().pageArrays(), 1u);
  EXPECT_GE(many.renderer().pageArrays(), 8u);
  EXPECT_EQ(one.renderer().pageCapacity(), many.renderer().pageCapacity());
  AdaptOptions o;
  o.tolerancePx = 1.0;
  uint32_t multiDraws = 0;
  for (Camera cam : orbitPath(atlas.lo, atlas.hi, 4, 0.5, 30.0)) {
    fitClipPlanes(cam, atlas.lo, atlas.hi);
    const gl::FrameResult a = one.renderFrame(cam, o);
    const std::vector<uint8_t> pa = one.renderer().readPixels();
    const gl::FrameResult b = many.renderFrame(cam, o);
    const std::vector<uint8_t> pb = many.renderer().readPixels();
    ASSERT_EQ(a.cut.nodes.size(), b.cut.nodes.size());
    EXPECT_EQ(a.draw.triangles, b.draw.triangles);
    EXPECT_EQ(a.draw.drawCalls, 1u);
    multiDraws += b.draw.drawCalls > 1;
    ASSERT_EQ(pa.size(), pb.size());
    EXPECT_EQ(0, std::memcmp(pa.data(), pb.data(), pa.size())) << "the pictures differ";
    const auto va = one.capture(a.cut), vb = many.capture(b.cut);
    ASSERT_EQ(va.size(), vb.size());
    for (size_t k = 0; k < va.size(); ++k)
      ASSERT_EQ(0, std::memcmp(va[k].data(), vb[k].data(), va[k].size() * sizeof(glm::vec3))) << "node " << k;
  }
  EXPECT_GT(multiDraws, 0u) << "no frame drew pages from more than one array";
}

// A node budget the frames are to hold (SceneOptions::minNodeRoom, what render --max-nodes sets)
// sizes the pool: the budget fits beside the locked roots, with no more than twice its pages.
TEST_F(PageArraysTest, ThePoolHoldsTheNodeBudget) {
  const AtlasView atlas = buildRainier(65, 4, 16);
  const uint32_t charts = atlas.hierarchy.chartCount();
  for (uint32_t budget : {500u, 3000u, 9000u}) {
    gl::SceneOptions so;
    so.width = 32;
    so.height = 24;
    so.minNodeRoom = budget;
    gl::AtlasScene scene(atlas, so);
    EXPECT_GE(scene.nodeRoom(), budget);
    EXPECT_EQ(scene.nodeBudget(budget), budget);
    EXPECT_LE(scene.renderer().pageCapacity(), std::max(so.pageCapacity, charts + 2 * budget)) << budget;
  }
}

}  // namespace
}  // namespace gimlod

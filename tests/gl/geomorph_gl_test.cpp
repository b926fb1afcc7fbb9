// Geomorphs on the real vertex shader (transform feedback): at every morph factor, and with
// factors that differ from node to node, the cut stays crack-free; at factor 0 every vertex is
// where it was, at 1 every inner vertex the coarser grid lacks lies on that grid's surface (the
// middle of the coarse edge or diagonal it halves), in between on the way. Corners never move; on a
// side with nothing drawn across, the odd vertices move as inner ones do; on a shared side, the
// border's vertices move with the neighbour's (their positions stay bit-identical: no cracks).
// On the shipped DEM and on the bunny's atlas.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>

#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/atlas_view.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/stitch.h"
#include "tests/gl/crack_check.h"
#include "tests/gl/gl_context_test.h"
#include "tests/small_atlases.h"
#include "tests/scan_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

class GeomorphTest : public test::GlContextTest<> {
 public:  // the shared scans' suite (ScanGeomorphTest) checks its cuts too
  // The cut captured with every node's morph factor from `factor` (node index -> factor).
  template <class F>
  static std::vector<std::vector<glm::vec3>> captureWith(gl::AtlasScene& scene, Cut cut, F factor) {
    for (size_t i = 0; i < cut.nodes.size(); ++i) cut.nodes[i].morph = factor(i);
    const auto verts = scene.capture(cut);
    const CrackReport r = countCracks(scene.atlas().hierarchy, cut, verts);
    EXPECT_EQ(r.mismatches, 0u) << r.mismatches << " of " << r.borderVertices << " border vertices";
    EXPECT_GT(r.borderVertices, 0u);
    return verts;
  }

  // Checks a cut at morph factors 0, 0.25, 0.5, 0.75 and 1, and at random factors per node.
  static void checkCut(gl::AtlasScene& scene, const Cut& cut, bool openBorders) {
    const Hierarchy& h = scene.atlas().hierarchy;
    // No factor set: as before geomorphs, crack-free, and cracked without the stitching tables.
    EXPECT_EQ(test::captureCracks(scene, cut).mismatches, 0u);
    const auto base = scene.capture(cut);
    const double extent = glm::length(scene.atlas().hi - scene.atlas().lo);
    uint64_t moved = 0, openMoved = 0, sharedMoved = 0;
    // Per node, the sides with nothing drawn across.
    std::vector<std::array<bool, 4>> open(cut.nodes.size());
    std::vector<SideNeighbour> across;
    for (size_t k = 0; k < cut.nodes.size(); ++k)
      for (uint32_t side = 0; side < 4; ++side) {
        across.clear();
        sideNeighbours(h, cut, cut.nodes[k].id, side, across);
        open[k][side] = across.empty();
      }
    for (const float f : {0.f, 0.25f, 0.5f, 0.75f, 1.f}) {
      SCOPED_TRACE("morph " + std::to_string(f));
      const auto verts = captureWith(scene, cut, [f](size_t) { return f; });
      ASSERT_EQ(verts.size(), base.size());
      for (size_t k = 0; k < cut.nodes.size(); ++k) {
        const uint32_t res = cut.nodes[k].resLog2, n = 1u << res;
        const bool morphs = res > h.params.minNodeResLog2;
        // The factor in the node record is quantized to 1/255.
        const float q = morphs ? float(std::lround(f * 255.f)) / 255.f : 0.f;
        for (uint32_t j = 0; j <= n; ++j)
          for (uint32_t i = 0; i <= n; ++i) {
            const size_t v = size_t(j) * (n + 1) + i;
            const bool inner = i > 0 && i < n && j > 0 && j < n;
            const bool corner = (i == 0 || i == n) && (j == 0 || j == n);
            const uint32_t di = i & 1, dj = j & 1;
            if (!inner && !corner && f > 0.f) {
              const uint32_t side = j == 0 ? kEdgeBottom : j == n ? kEdgeTop : i == 0 ? kEdgeLeft : kEdgeRight;
              const bool alongX = side == kEdgeBottom || side == kEdgeTop;
              const uint32_t along = alongX ? i : j;
              if (!open[k][side]) {
                sharedMoved += verts[k][v] != base[k][v];
                continue;  // the crack check holds it to its neighbour's
              }
              if ((along & 1) == 0) {
                ASSERT_EQ(verts[k][v], base[k][v])
                    << "node " << k << " open border vertex " << i << "," << j << " moved";
                continue;
              }
              const size_t step = alongX ? 1 : n + 1;
              const glm::vec3 want = glm::mix(base[k][v], 0.5f * (base[k][v - step] + base[k][v + step]), q);
              ASSERT_LE(glm::length(verts[k][v] - want), 1e-5 * extent)
                  << "node " << k << " open border vertex " << i << "," << j << " morph " << q;
              openMoved += verts[k][v] != base[k][v];
              continue;
            }
            if (!inner || (di | dj) == 0 || q == 0.f) {
              ASSERT_EQ(verts[k][v], base[k][v]) << "node " << k << " vertex " << i << "," << j << " moved";
              continue;
            }
            const glm::vec3 a = base[k][size_t(j - dj) * (n + 1) + (i - di)];
            const glm::vec3 b = base[k][size_t(j + dj) * (n + 1) + (i + di)];
            const glm::vec3 want = glm::mix(base[k][v], 0.5f * (a + b), q);
            ASSERT_LE(glm::length(verts[k][v] - want), 1e-5 * extent)
                << "node " << k << " vertex " << i << "," << j << " morph " << q;
            moved += verts[k][v] != base[k][v];
          }
      }
    }
    EXPECT_GT(moved, 0u) << "no inner vertex moved";
    EXPECT_GT(sharedMoved, 0u) << "no vertex of a shared border moved";
    if (openBorders) {
      EXPECT_GT(openMoved, 0u) << "no vertex of an open border moved";
    }
    // Neighbours at other factors, each node its own.
    std::mt19937 random(7);
    std::uniform_real_distribution<float> factor(0.f, 1.f);
    for (int round = 0; round < 3; ++round) {
      SCOPED_TRACE("random factors, round " + std::to_string(round));
      std::vector<float> f(cut.nodes.size());
      for (float& x : f) x = factor(random);
      captureWith(scene, cut, [&](size_t i) { return f[i]; });
    }
  }
};

TEST_F(GeomorphTest, ShippedDemCutsStayCrackFreeAtEveryMorphFactor) {
  test::TempDir dir("gimlod-geomorph");
  test::buildRainierAtlas(dir.path() / "atlas", 129, 4, 32, 2);
  const AtlasView atlas = openAtlas(dir.path() / "atlas");
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  gl::AtlasScene scene(atlas, so);
  const glm::dvec3 ext = atlas.hi - atlas.lo;
  Camera c;
  c.eye = atlas.lo + glm::dvec3(0.3 * ext.x, 0.2 * ext.y, ext.z + 0.08 * ext.x);
  c.target = atlas.lo + glm::dvec3(0.6 * ext.x, 0.7 * ext.y, 0.0);
  c.nearPlane = c.farPlane = 0.0;
  fitClipPlanes(c, atlas.lo, atlas.hi);
  AdaptOptions ao;
  ao.tolerancePx = 0.5;
  ao.maxNodes = scene.nodeBudget(600);
  const Cut cut = adaptErrorThreshold(atlas.hierarchy, makeViewParams(c, so.width, so.height), ao);
  const test::CutMix mix = test::cutMix(atlas.hierarchy, cut);
  ASSERT_GT(mix.mixed, 0u) << "the cut should join nodes of different levels or resolutions";
  checkCut(scene, cut, true);
}

// Every shared scan (the atlases the crack tests build), across its chart seams.
class ScanGeomorphTest : public test::GlContextTest<::testing::TestWithParam<std::string>> {};

TEST_P(ScanGeomorphTest, CutsStayCrackFreeAtEveryMorphFactor) {
  const std::string name = GetParam();
  GIMLOD_NEED_SHARED_DATA(test::haveSharedScan(name));
  const test::BuiltScanAtlas* built = nullptr;
  ASSERT_NO_THROW(built = &test::scanAtlas(name, true));
  const AtlasView atlas = openAtlas(built->dir);
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  gl::AtlasScene scene(atlas, so);
  Camera c = orbitPath(atlas.lo, atlas.hi, 8, 0.6, 25.0)[3];
  fitClipPlanes(c, atlas.lo, atlas.hi);
  AdaptOptions ao;
  ao.tolerancePx = 0.5;
  ao.maxNodes = scene.nodeBudget(400);
  const Cut cut = adaptErrorThreshold(atlas.hierarchy, makeViewParams(c, so.width, so.height), ao);
  ASSERT_GT(test::cutMix(atlas.hierarchy, cut).crossChart, 0u);
  GeomorphTest::checkCut(scene, cut, false);
}

INSTANTIATE_TEST_SUITE_P(SharedScans, ScanGeomorphTest, ::testing::ValuesIn(test::sharedScanNames()),
                         [](const ::testing::TestParamInfo<std::string>& i) { return i.param; });

// The scene's factors: 0 without geomorphs; with them, geomorphFactor of each drawn node: 0 while
// the coarser resolution's error is 1.5 times the tolerance or more, 1 at the tolerance, and some
// nodes part way, along a path.
TEST_F(GeomorphTest, SceneFactorsFollowTheCoarserError) {
  test::TempDir dir("gimlod-geomorph-scene");
  test::buildRainierAtlas(dir.path() / "atlas", 129, 4, 32, 2);
  const AtlasView atlas = openAtlas(dir.path() / "atlas");
  const Hierarchy& h = atlas.hierarchy;
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  AdaptOptions ao;
  ao.tolerancePx = 1.0;
  ao.maxNodes = 800;
  const std::vector<Camera> path = orbitPath(atlas.lo, atlas.hi, 6, 0.5, 30.0);
  {
    gl::AtlasScene plain(atlas, so);
    for (const Camera& c : path)
      for (const CutNode& n : plain.renderFrame(c, ao).cut.nodes) ASSERT_EQ(n.morph, 0.f);
  }
  so.geomorph = 0.5;
  gl::AtlasScene scene(atlas, so);
  uint32_t partWay = 0;
  for (const Camera& c : path) {
    const gl::FrameResult f = scene.renderFrame(c, ao);
    const ViewParams v = makeViewParams(c, so.width, so.height);
    for (const CutNode& n : f.cut.nodes) {
      ASSERT_GE(n.morph, 0.f);
      ASSERT_LE(n.morph, 1.f);
      EXPECT_FLOAT_EQ(n.morph, float(geomorphFactor(h, n, v, ao.tolerancePx, so.geomorph)));
      if (n.resLog2 > h.params.minNodeResLog2) {
        const double coarser = screenError(h, n.id, n.resLog2 - 1, v);
        if (coarser >= 1.5 * ao.tolerancePx) {
          EXPECT_EQ(n.morph, 0.f);
        }
        if (coarser <= ao.tolerancePx) {
          EXPECT_EQ(n.morph, 1.f);
        }
      } else {
        EXPECT_EQ(n.morph, 0.f);
      }
      partWay += n.morph > 0.f && n.morph < 1.f;
    }
  }
  EXPECT_GT(partWay, 0u) << "no node was part way to its coarser resolution";
}

}  // namespace
}  // namespace gimlod

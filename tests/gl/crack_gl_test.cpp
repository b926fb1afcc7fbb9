// Cracks measured on the real vertex shader: stitched positions captured with transform
// feedback, every border vertex checked against the neighbours across that side.
#include <gtest/gtest.h>

#include <random>

#include "pipeline/build.h"
#include "atlas/mesh/charting.h"
#include "atlas/mesh/layout_refine.h"
#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/mesh_io.h"
#include "atlas/mesh/resample.h"
#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/atlas_view.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"
#include "tests/gl/gl_context_test.h"
#include "runtime/stitch.h"
#include "tests/chart_layout_fixture.h"
#include "tests/gl/crack_check.h"
#include "tests/test_util.h"
#include "tests/upsampled_tile.h"

namespace gimlod {
namespace {

class CrackTest : public test::GlContextTest<> {
 protected:
  // Builds an atlas of `dem` into the temp dir and opens it.
  AtlasView build(const std::filesystem::path& dem, uint32_t chartSize, uint32_t depth, uint32_t nodeRes,
                  uint32_t minNodeRes) {
    TerrainBuildOptions o;
    o.input = dem;
    o.output = dir_.path() / ("atlas_" + dem.stem().string() + "_" + std::to_string(chartSize));
    o.chartSize = chartSize;
    o.depth = depth;
    o.nodeRes = nodeRes;
    o.minNodeRes = minNodeRes;
    buildAtlas(o);
    return openAtlas(o.output);
  }

  // Crack count of a cut through the real shader; also checks the negative control.
  CrackReport check(gl::AtlasScene& scene, const Cut& cut, bool expectControlToFail = true) {
    return test::captureCracks(scene, cut, expectControlToFail);
  }

  // The scene of the mesh atlas checks: small frames, every root's pages resident.
  static gl::SceneOptions meshSceneOptions() {
    gl::SceneOptions so;
    so.width = 96;
    so.height = 72;
    so.pageCapacity = 512;
    return so;
  }

  // Writes `set` as a geometry atlas in the temp dir, opens it, and checks the cuts of cameras all
  // around it at several distances through the real vertex shader: no stitch violation, 0 cracks,
  // some cuts refined below the roots.
  // The atlas and its scene stay in meshAtlas_ and meshScene_ (the scene refers to the atlas).
  void checkMeshAtlasCracks(const GeometryImageSet& set, const std::filesystem::path& dir, uint64_t minChecked) {
    AtlasManifest m;
    m.depth = 3;
    m.maxNodeResLog2 = 4;
    m.minNodeResLog2 = 1;
    writeGeometryCharts(set, dir, 16, m);
    std::vector<std::array<RootNeighbour, 4>> roots;
    for (const ChartInfo& c : m.charts) roots.push_back(c.neighbours);
    writeHierarchy(dir / m.hierarchyFile, buildGeometryHierarchy(hierarchyParams(m), roots,
                                                                 [&](uint32_t c) { return set.charts[c].positions; }));
    writeManifest(dir, m);
    meshScene_.reset();
    meshAtlas_ = std::make_unique<AtlasView>(openAtlas(dir));
    const AtlasView& atlas = *meshAtlas_;
    const gl::SceneOptions so = meshSceneOptions();
    meshScene_ = std::make_unique<gl::AtlasScene>(atlas, so);
    gl::AtlasScene& scene = *meshScene_;
    const Hierarchy& h = atlas.hierarchy;
    uint64_t checked = 0, mixed = 0;
    int frame = 0;
    for (double distance : {0.55, 0.9, 2.0})
      for (const Camera& c0 : orbitPath(atlas.lo, atlas.hi, 4, distance, 35.0)) {
        Camera cam = c0;
        fitClipPlanes(cam, atlas.lo, atlas.hi);
        AdaptOptions o;
        o.tolerancePx = 0.3;
        o.maxNodes = 300;
        DualQueueAdapter dq(h);
        const Cut cut = dq.update(makeViewParams(cam, so.width, so.height), o);
        EXPECT_EQ(countStitchViolations(h, cut), 0u);
        for (const CutNode& n : cut.nodes) mixed += n.id.level > 0;
        const CrackReport r = check(scene, cut, frame == 0);
        EXPECT_EQ(r.mismatches, 0u) << "distance " << distance << " frame " << frame << ": " << r.mismatches << " of "
                                    << r.borderVertices;
        checked += r.borderVertices;
        ++frame;
      }
    EXPECT_GT(checked, minChecked);
    EXPECT_GT(mixed, 0u) << "no cut was refined below the roots";
  }

  std::unique_ptr<AtlasView> meshAtlas_;
  std::unique_ptr<gl::AtlasScene> meshScene_;

  test::TempDir dir_{"gimlod-crack"};
};

// Hand-made cuts: neighbours 1..3 levels and several resolutions apart, across chart borders.
TEST_F(CrackTest, HandMadeCutsAcrossChartBorders) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  const AtlasView atlas = build(test::sharedData() / "terrain/SainteHelens.dem", 129, 4, 32, 2);
  ASSERT_GE(atlas.hierarchy.chartCount(), 4u);
  gl::SceneOptions so;
  so.width = 64;
  so.height = 48;
  gl::AtlasScene scene(atlas, so);
  const Hierarchy& h = atlas.hierarchy;
  const uint32_t cx = atlas.manifest.chartsX;

  // Chart 0 refined to leaves in its top-right corner (3 levels below the neighbour roots);
  // charts 1 (right) and cx (top) stay roots at resolutions 3..5; chart cx+1 at level 1.
  for (uint32_t rootRes : {3u, 4u, 5u}) {
    Cut cut;
    cut.nodes.push_back({{1, 0, 0, 0}, rootRes, 0});
    cut.nodes.push_back({{cx, 0, 0, 0}, rootRes, 0});
    for (uint32_t i = 0; i < 4; ++i) cut.nodes.push_back({NodeId{cx + 1, 0, 0, 0}.child(i), 2 + i % 3, 0});
    // Chart 0: level-1 children except top-right, which is split down to level 3 at its corner.
    for (uint32_t i = 0; i < 3; ++i) cut.nodes.push_back({NodeId{0, 0, 0, 0}.child(i), 2 + i, 0});
    const NodeId tr = NodeId{0, 0, 0, 0}.child(3);
    for (uint32_t i = 0; i < 3; ++i) cut.nodes.push_back({tr.child(i), 2 + (i % 2) * 3, 0});
    const NodeId trtr = tr.child(3);
    for (uint32_t i = 0; i < 4; ++i) cut.nodes.push_back({trtr.child(i), 2 + i % 3, 0});
    cut.rebuildIndex();
    // Cover the remaining charts with roots so every shared side has a neighbour.
    for (uint32_t c = 0; c < h.chartCount(); ++c)
      if (c != 0 && c != 1 && c != cx && c != cx + 1 && !(h.flags({c, 0, 0, 0}) & kNodeEmpty))
        cut.nodes.push_back({{c, 0, 0, 0}, 4, 0});
    cut.rebuildIndex();
    ASSERT_EQ(countStitchViolations(h, cut), 0u) << "root res " << rootRes;
    const CrackReport r = check(scene, cut);
    EXPECT_GT(r.borderVertices, 100u);
    EXPECT_EQ(r.mismatches, 0u) << "root res " << rootRes;
  }
}

// Cuts adapted from several cameras over the real SRTM tiles.
TEST_F(CrackTest, AdaptedCutsOverRealSrtmTiles) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  for (const char* tile : {"terrain/mt_rainier_90m.tif", "terrain/mt_fuji_90m.tif"}) {
    const AtlasView atlas = build(test::sharedData() / tile, 257, 5, 32, 2);
    gl::SceneOptions so;
    so.width = 160;
    so.height = 120;
    gl::AtlasScene scene(atlas, so);
    std::mt19937 rng(42);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const glm::dvec3 ext = atlas.hi - atlas.lo;
    uint64_t crossChart = 0;
    for (int i = 0; i < 6; ++i) {
      Camera cam;
      cam.eye = atlas.lo + glm::dvec3(u(rng) * ext.x, u(rng) * ext.y, atlas.hi.z + (0.02 + 0.3 * u(rng)) * ext.x);
      cam.target = atlas.lo + glm::dvec3(u(rng) * ext.x, u(rng) * ext.y, atlas.lo.z);
      cam.nearPlane = cam.farPlane = 0.0;
      fitClipPlanes(cam, atlas.lo, atlas.hi);
      AdaptOptions o;
      o.tolerancePx = 0.5 + 2.0 * u(rng);
      o.maxNodes = 1500;
      o.frustumCull = (i % 2) == 0;
      const Cut cut = adaptErrorThreshold(atlas.hierarchy, makeViewParams(cam, so.width, so.height), o);
      ASSERT_EQ(countStitchViolations(atlas.hierarchy, cut), 0u);
      // Count resolution and level differences across sides, to show the cut is mixed.
      const test::CutMix mix = test::cutMix(atlas.hierarchy, cut);
      const uint64_t mixed = mix.mixed;
      crossChart += mix.crossChart;
      const CrackReport r = check(scene, cut, mixed > 0);
      EXPECT_EQ(r.mismatches, 0u) << tile << " camera " << i << ": " << r.mismatches << " of " << r.borderVertices
                                  << " border vertices";
      EXPECT_GT(r.borderVertices, 0u);
    }
    EXPECT_GT(crossChart, 0u) << "no cut crossed a chart border";
  }
}

// Deep trees, as the build plans them for large DEMs: the shipped tile upsampled twice, in 3 x 3
// charts of 1025 samples at depth 8 (leaves 8 intervals wide), adapted from low cameras so that
// neighbours meet many levels apart, within and across charts: 0 cracks.
TEST_F(CrackTest, AdaptedCutsOnDeepTrees) {
  const std::filesystem::path vrt = test::upsampledTile(dir_.path(), "200%");
  const AtlasView atlas = build(vrt, 1025, 8, 64, 4);
  ASSERT_EQ(atlas.hierarchy.chartCount(), 9u);
  gl::SceneOptions so;
  so.width = 160;
  so.height = 120;
  so.pageCapacity = 4096;
  gl::AtlasScene scene(atlas, so);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const glm::dvec3 ext = atlas.hi - atlas.lo;
  uint32_t deepest = 0, levelGap = 0;
  uint64_t crossChart = 0;
  for (int i = 0; i < 6; ++i) {
    Camera cam;
    cam.eye = atlas.lo + glm::dvec3(u(rng) * ext.x, u(rng) * ext.y, atlas.hi.z + (0.005 + 0.05 * u(rng)) * ext.x);
    cam.target = atlas.lo + glm::dvec3(u(rng) * ext.x, u(rng) * ext.y, atlas.lo.z);
    cam.nearPlane = cam.farPlane = 0.0;
    fitClipPlanes(cam, atlas.lo, atlas.hi);
    AdaptOptions o;
    o.tolerancePx = 0.5;
    o.maxNodes = 3000;
    const Cut cut = adaptErrorThreshold(atlas.hierarchy, makeViewParams(cam, so.width, so.height), o);
    ASSERT_EQ(countStitchViolations(atlas.hierarchy, cut), 0u);
    uint32_t lo = 99, hi = 0;
    for (const CutNode& n : cut.nodes) lo = std::min(lo, n.id.level), hi = std::max(hi, n.id.level);
    deepest = std::max(deepest, hi);
    levelGap = std::max(levelGap, hi - lo);
    const test::CutMix mix = test::cutMix(atlas.hierarchy, cut);
    crossChart += mix.crossChart;
    const CrackReport r = check(scene, cut, mix.mixed > 0);
    EXPECT_EQ(r.mismatches, 0u) << "camera " << i << ": " << r.mismatches << " of " << r.borderVertices;
    EXPECT_GT(r.borderVertices, 0u);
  }
  EXPECT_GE(deepest, 6u) << "no cut reached the deep levels";
  EXPECT_GE(levelGap, 4u);
  EXPECT_GT(crossChart, 0u);
}

// The cuts of the coherent adapters (dual queue in error mode, quad queue under a triangle
// budget) along a moving path over real SRTM, frame after frame: no stitching violation, no crack.
TEST_F(CrackTest, CoherentAdapterCutsAlongAPathOverRealSrtm) {
  GIMLOD_NEED_SHARED_DATA(test::haveSharedData());
  const AtlasView atlas = build(test::sharedData() / "terrain/mt_fuji_90m.tif", 257, 5, 32, 2);
  gl::SceneOptions so;
  so.width = 160;
  so.height = 120;
  gl::AtlasScene scene(atlas, so);
  const Hierarchy& h = atlas.hierarchy;
  const auto path = orbitPath(atlas.lo, atlas.hi, 6, 0.4, 25.0);
  DualQueueAdapter dq(h);
  QuadQueueAdapter qq(h);
  AdaptOptions ao;
  ao.tolerancePx = 0.8;
  ao.maxNodes = 600;
  BudgetOptions bo;
  bo.maxTriangles = 40000;
  bo.maxNodes = 150;
  uint64_t checked = 0;
  for (size_t f = 0; f < path.size(); ++f) {
    Camera cam = path[f];
    fitClipPlanes(cam, atlas.lo, atlas.hi);
    const ViewParams v = makeViewParams(cam, so.width, so.height);
    for (int which = 0; which < 2; ++which) {
      const Cut cut = which == 0 ? dq.update(v, ao) : qq.update(v, bo);
      ASSERT_EQ(countStitchViolations(h, cut), 0u) << "frame " << f << (which ? " quad" : " dual");
      const CrackReport r = check(scene, cut, f == 0);
      EXPECT_EQ(r.mismatches, 0u) << "frame " << f << (which ? " quad" : " dual") << ": " << r.mismatches << " of "
                                  << r.borderVertices;
      checked += r.borderVertices;
    }
  }
  EXPECT_GT(checked, 1000u);
}

// Mesh atlases: the quad charts of a sphere (six curved patches, 24 charts meeting at 3 and 4
// per corner, at every edge orientation the quad layout makes), adapted from cameras all around
// and at several distances, then captured from the real vertex shader: 0 cracks across chart
// borders, with neighbours at different levels and resolutions; and a drawn frame shows the
// surface.
TEST_F(CrackTest, MeshAtlasCutsAcrossChartsOfEveryOrientation) {
  const PatchLayout layout = test::cubeLayout(8, true);
  ResampleOptions ro;
  ro.chartSize = 33;
  const GeometryImageSet set = resampleLayout(layout, ro);
  uint32_t rotated = 0;
  for (const GeometryImage& g : set.charts)
    for (uint32_t e = 0; e < 4; ++e) rotated += g.neighbours[e].chart >= 0 && g.neighbours[e].edge != (e + 2) % 4;
  EXPECT_GT(rotated, 0u) << "the layout should join charts at other than opposite edges";
  checkMeshAtlasCracks(set, dir_.path() / "sphere.atlas", 2000);
  const AtlasView& atlas = *meshAtlas_;
  gl::AtlasScene& scene = *meshScene_;
  const gl::SceneOptions so = meshSceneOptions();
  // A frame of the sphere: the centre is surface, the corner is background.
  Camera cam = orbitPath(atlas.lo, atlas.hi, 1, 1.2, 20.0)[0];
  fitClipPlanes(cam, atlas.lo, atlas.hi);
  AdaptOptions o;
  scene.renderFrame(cam, o);
  const std::vector<uint8_t> px = scene.renderer().readPixels();
  auto at = [&](int x, int y) { return px.data() + (size_t(y) * so.width + x) * 4; };
  auto isBackground = [&](const uint8_t* p) {
    return std::abs(p[0] - int(so.background[0] * 255.f + 0.5f)) <= 2 &&
           std::abs(p[2] - int(so.background[2] * 255.f + 0.5f)) <= 2;
  };
  EXPECT_FALSE(isBackground(at(48, 36)));
  EXPECT_TRUE(isBackground(at(0, 0)));
}

// The sides quad layout on a real scan: the shipped bunny in 48 patches, its odd patches paired
// by evenSides, so 4-sided patches are single charts beside patches of up to 10 sides split round
// their centres (spokes meeting 3 to 5 at a centre): 0 cracks from cameras all around.
TEST_F(CrackTest, SidesQuadLayoutOfTheBunnyHasNoCracks) {
  const IndexedMesh mesh = readMesh(test::realData("meshes/bun_zipper.ply"));
  ChartingOptions copt;
  copt.targetPatches = 48;
  PatchLayout layout = buildPatchLayout(mesh, copt);
  ASSERT_EQ(evenSides(layout).oddLeft, 0u);
  ResampleOptions ro;
  ro.chartSize = 17;
  ro.quads = QuadLayout::kSides;
  const GeometryImageSet set = resampleLayout(layout, ro);
  uint32_t single = 0;
  for (const PatchResampleStats& p : set.patches) single += p.quads == 1;
  EXPECT_GT(single, 0u) << "the layout should have 4-sided patches drawn as one chart";
  checkMeshAtlasCracks(set, dir_.path() / "bunny_sides.atlas", 2000);
}

}  // namespace
}  // namespace gimlod

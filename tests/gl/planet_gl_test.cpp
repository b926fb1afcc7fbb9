// Planet atlases through the real vertex shader: the shipped global DEM on a sphere and on the
// WGS84 ellipsoid, crack-free across chart borders, the antimeridian and the poles; a closed
// surface; positions near the eye exact to millimetres at the planet's scale.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/atlas_format.h"
#include "pipeline/build.h"
#include "runtime/atlas_view.h"
#include "runtime/cut_mesh.h"
#include "runtime/gl/atlas_scene.h"
#include "tests/gl/crack_check.h"
#include "tests/gl/gl_context_test.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

class PlanetTest : public test::GlContextTest<> {
 protected:
  static void SetUpTestSuite() {
    test::GlContextTest<>::SetUpTestSuite();
    dir_ = std::make_unique<test::TempDir>("planet");
    TerrainBuildOptions o;
    o.input = test::repoData() / "terrain/etopo_30min.tif";
    o.output = dir_->path() / "earth.atlas";
    o.planet = true;
    o.chartSize = 129;
    o.depth = 4;
    o.nodeRes = 16;
    o.minNodeRes = 2;
    buildAtlas(o);
    atlas_ = std::make_unique<AtlasView>(openAtlas(o.output));
    o.output = dir_->path() / "wgs84.atlas";
    o.planetRadius = kEllipsoids[0].radius;
    o.planetFlattening = kEllipsoids[0].flattening;
    buildAtlas(o);
    ellipsoid_ = std::make_unique<AtlasView>(openAtlas(o.output));
  }
  static void TearDownTestSuite() {
    atlas_.reset();
    ellipsoid_.reset();
    dir_.reset();
    test::GlContextTest<>::TearDownTestSuite();
  }

  static gl::SceneOptions sceneOptions() {
    gl::SceneOptions so;
    so.width = 160;
    so.height = 120;
    return so;
  }

  // A camera `altitude` metres above (lon, lat) of `a`'s surface, looking `ahead` degrees north
  // along it.
  static Camera cameraAbove(const AtlasView& a, double lonDeg, double latDeg, double altitude, double aheadDeg) {
    const PlanetInfo& p = a.manifest.planet;
    Camera c;
    c.eye = surfacePosition(p, lonDeg * kDeg, latDeg * kDeg, altitude);
    c.target = surfacePosition(p, lonDeg * kDeg, std::clamp(latDeg + aheadDeg, -89.9, 89.9) * kDeg, 0.0);
    c.up = glm::normalize(c.eye);
    c.fovYDeg = 60.0;
    return c;
  }
  static std::array<const AtlasView*, 2> both() { return {atlas_.get(), ellipsoid_.get()}; }

  static inline std::unique_ptr<test::TempDir> dir_;
  static inline std::unique_ptr<AtlasView> atlas_, ellipsoid_;
};

TEST_F(PlanetTest, TheGlobalDemWrapsAndClosesAtThePoles) {
  const AtlasManifest& m = atlas_->manifest;
  ASSERT_TRUE(m.planet.present);
  // 720 columns a turn, made 6 charts of 128 intervals, plus the wrap column.
  EXPECT_EQ(m.planet.wrapColumns, 768u);
  EXPECT_EQ(m.samplesX, 769u);
  EXPECT_EQ(m.chartsX, 6u);
  // Cell-centred rows: a pole row added each side.
  EXPECT_EQ(m.samplesY, 362u);
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  EXPECT_EQ(frame.pole(0), -1);
  EXPECT_EQ(frame.pole(1), 0);
  EXPECT_EQ(frame.pole(361), 1);
  EXPECT_EQ(frame.pole(400), 1);  // padding past the pole folds onto it
  // The last chart column's right edge meets the first's left.
  for (uint32_t y = 0; y < m.chartsY; ++y) {
    const ChartInfo& last = m.charts[y * m.chartsX + m.chartsX - 1];
    EXPECT_EQ(last.neighbours[kEdgeRight].chart, int32_t(y * m.chartsX));
  }
}

TEST_F(PlanetTest, CutsAreCrackFreeAcrossChartsTheAntimeridianAndThePoles) {
  for (const AtlasView* a : both()) {
    SCOPED_TRACE(a->dir.filename().string());
    gl::AtlasScene scene(*a, sceneOptions());
    const Hierarchy& h = a->hierarchy;
    const AtlasManifest& m = a->manifest;
    AdaptOptions ao;
    ao.tolerancePx = 0.5;
    ao.maxNodes = scene.nodeBudget(0);
    test::CutMix mix;
    uint64_t seamSides = 0, poleNodes = 0, checked = 0;
    std::vector<uint32_t> levels(h.params.depth, 0);
    const double views[][4] = {{180.0, 0.0, 2.0e6, 20.0},   {-179.0, 10.0, 4.0e5, 15.0}, {0.0, 88.0, 1.5e6, -10.0},
                               {179.5, -87.0, 8.0e5, 5.0},  {60.0, 30.0, 2.0e7, 0.0},    {-90.0, 89.9, 3.0e5, -30.0}};
    for (const auto& v : views) {
      const gl::FrameResult f = scene.renderFrame(cameraAbove(*a, v[0], v[1], v[2], v[3]), ao);
      ASSERT_FALSE(f.cut.nodes.empty());
      const CrackReport r = test::captureCracks(scene, f.cut);
      EXPECT_EQ(r.mismatches, 0u) << "view at " << v[0] << ", " << v[1];
      EXPECT_GT(r.borderVertices, 0u);
      checked += r.borderVertices;
      mix += test::cutMix(h, f.cut);
      std::vector<SideNeighbour> ns;
      for (const CutNode& n : f.cut.nodes) {
        ++levels[n.id.level];
        const uint32_t size = (m.chartSize - 1) >> n.id.level;
        const int64_t y0 = int64_t(m.charts[n.id.chart].gridY) * (m.chartSize - 1) + int64_t(n.id.y) * size;
        poleNodes += y0 == 0 || (y0 <= 361 && y0 + size >= 361);
        ns.clear();
        sideNeighbours(h, f.cut, n.id, kEdgeRight, ns);
        for (const SideNeighbour& sn : ns)
          seamSides += m.charts[n.id.chart].gridX == int32_t(m.chartsX - 1) &&
                       m.charts[f.cut.nodes[sn.cutIndex].id.chart].gridX == 0;
      }
    }
    EXPECT_GT(checked, 1000u);
    EXPECT_GT(seamSides, 0u) << "no cut crossed the antimeridian";
    EXPECT_GT(poleNodes, 0u) << "no cut reached a pole";
    EXPECT_GT(mix.crossChartLevelDiff, 0u) << "no chart border between levels";
    EXPECT_GT(mix.crossChartResDiff, 0u);
    uint32_t used = 0;
    for (uint32_t c : levels) used += c > 0;
    EXPECT_GE(used, 3u);
  }
}

TEST_F(PlanetTest, TheWholePlanetIsAClosedSurface) {
  for (const AtlasView* a : both()) {
    SCOPED_TRACE(a->dir.filename().string());
    gl::AtlasScene scene(*a, sceneOptions());
    AdaptOptions ao;
    ao.tolerancePx = 0.5;
    ao.maxNodes = scene.nodeBudget(0);
    ao.frustumCull = false;
    for (const double altitude : {3.0e6, 3.0e7}) {
      const gl::FrameResult f = scene.renderFrame(cameraAbove(*a, -179.5, 45.0, altitude, -20.0), ao);
      const CutMesh mesh = buildCutMesh(a->hierarchy, f.cut, scene.capture(f.cut), nullptr);
      EXPECT_EQ(mesh.boundaryEdges, 0u) << "altitude " << altitude;
      EXPECT_GT(mesh.triangles.size(), 500u);
      // Without the stitching, the near view's cut (of mixed resolutions) opens.
      if (altitude < 1e7) {
        const CutMesh open = buildCutMesh(a->hierarchy, f.cut, scene.capture(f.cut, false), nullptr);
        EXPECT_GT(open.boundaryEdges, 0u);
      }
    }
  }
}

// The height of the level-0 sample under (lon, lat), from its chart file.
float surfaceHeight(const AtlasView& a, double lonDeg, double latDeg) {
  const AtlasManifest& m = a.manifest;
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  const auto g = frame.sampleUnder(surfacePosition(m.planet, lonDeg * kDeg, latDeg * kDeg, 0.0));
  const uint32_t M = m.chartSize - 1;
  const ChartInfo& c = m.charts[(g[1] / M) * m.chartsX + g[0] / M];
  const std::vector<float> level0 = ChartFileReader(a.dir / c.file).readHeightsWindow(0, 0, 0, M);
  return level0[size_t(g[1] % M) * (M + 1) + size_t(g[0] % M)];
}

// Camera-relative precision: a camera a metre above the highest land, above the sea floor and by the
// antimeridian; every inner vertex the vertex shader places within 500 km lies within a millimetre
// plus 5e-7 of its distance of its double-precision position (the nearest, 36 to 60 km away on this
// lattice, within millimetres), where plain float32 planet-centred positions are off by decimetres.
TEST_F(PlanetTest, PositionsNearTheEyeKeepMillimetresAMetreAboveTheSurface) {
  for (const AtlasView* a : both()) {
    SCOPED_TRACE(a->dir.filename().string());
    gl::AtlasScene scene(*a, sceneOptions());
    const AtlasManifest& m = a->manifest;
    const Hierarchy& h = a->hierarchy;
    const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
    const uint32_t L = h.params.intervalsLog2, M = 1u << L;
    AdaptOptions ao;
    ao.tolerancePx = 1.0;
    ao.maxNodes = scene.nodeBudget(0);
    for (const auto& [lon, lat] : {std::array<double, 2>{86.9, 28.0}, {-150.0, -20.0}, {179.9, 70.0}}) {
      const Camera cam = cameraAbove(*a, lon, lat, surfaceHeight(*a, lon, lat) + 1.0, 0.5);
      const gl::FrameResult f = scene.renderFrame(cam, ao);
      const auto verts = scene.capture(f.cut);
      const glm::dvec3 origin = scene.captureOrigin();
      EXPECT_LT(glm::length(origin - cam.eye), 1.0e5) << "the anchor lies under the eye";
      double worst = 0.0, control = 0.0, closest = 1e30, closestError = 0.0;
      uint64_t near = 0;
      for (size_t i = 0; i < f.cut.nodes.size(); ++i) {
        const CutNode& n = f.cut.nodes[i];
        const ChartInfo& c = m.charts[n.id.chart];
        const uint32_t k = L - n.id.level - n.res, side = (1u << n.res) + 1;
        const uint32_t u0 = (n.id.x * (M >> n.id.level)) >> k, v0 = (n.id.y * (M >> n.id.level)) >> k;
        const uint32_t levelSide = (M >> k) + 1;
        const std::vector<float> level = ChartFileReader(a->dir / c.file).readHeightsWindow(k, 0, 0, M >> k);
        for (uint32_t j = 1; j + 1 < side; ++j)
          for (uint32_t ii = 1; ii + 1 < side; ++ii) {
            const int64_t gx = int64_t(c.gridX) * M + (int64_t(u0 + ii) << k), gy = int64_t(c.gridY) * M + (int64_t(v0 + j) << k);
            const double hgt = level[size_t(v0 + j) * levelSide + (u0 + ii)];
            const glm::dvec3 exact = frame.position(gx, gy, hgt);
            const double dist = glm::length(exact - cam.eye);
            if (dist > 5.0e5) continue;
            ++near;
            const glm::dvec3 got = glm::dvec3(verts[i][size_t(j) * side + ii]) + origin;
            worst = std::max(worst, glm::length(got - exact) / (1e-3 + 5e-7 * dist));
            closest = std::min(closest, dist);
            if (dist == closest) closestError = glm::length(got - exact);
            const glm::dvec3 plain = glm::dvec3(glm::vec3(exact));
            control = std::max(control, glm::length(plain - exact));
          }
      }
      EXPECT_GT(near, 20u) << lon << ", " << lat;
      EXPECT_LT(worst, 1.0) << lon << ", " << lat;
      EXPECT_LT(10.0 * closestError, control) << lon << ", " << lat << ": the nearest sample, " << closest << " m away";
      EXPECT_GT(control, 0.05) << lon << ", " << lat;
    }
  }
}

}  // namespace
}  // namespace gimlod

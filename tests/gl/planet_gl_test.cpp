// Planet atlases through the real vertex shader: the shipped global DEM on a sphere and on the
// WGS84 ellipsoid, crack-free across chart borders, the antimeridian and the poles; a closed
// surface; positions near the eye exact to millimetres at the planet's scale.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
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
    const double views[][4] = {{180.0, 0.0, 2.0e6, 20.0},  {-179.0, 10.0, 4.0e5, 15.0}, {0.0, 88.0, 1.5e6, -10.0},
                               {179.5, -87.0, 8.0e5, 5.0}, {60.0, 30.0, 2.0e7, 0.0},    {-90.0, 89.9, 3.0e5, -30.0}};
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

// How far from their double-precision positions the vertex shader places a cut's inner vertices
// within 500 km of the eye, in metres and in pixels (at 640 x 480, the scene's aspect); and where
// plain float32 planet-centred positions would put them (the control).
struct Precision {
  uint64_t near = 0, inView = 0;
  double worst = 0.0;  // the largest error over (1 mm + 5e-7 of the distance)
  double control = 0.0, closest = 1e30, closestError = 0.0;
  double pixelWorst = 0.0, pixelControl = 0.0;
};

Precision measurePrecision(gl::AtlasScene& scene, const AtlasView& a, const Camera& cam) {
  const AtlasManifest& m = a.manifest;
  const Hierarchy& h = a.hierarchy;
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  const uint32_t L = h.params.intervalsLog2, M = 1u << L;
  AdaptOptions ao;
  ao.tolerancePx = 1.0;
  ao.maxNodes = scene.nodeBudget(0);
  const gl::FrameResult f = scene.renderFrame(cam, ao);
  const auto verts = scene.capture(f.cut);
  const glm::dvec3 origin = scene.captureOrigin();
  EXPECT_LT(glm::length(origin - cam.eye), 1.0e5) << "the anchor lies under the eye";
  const glm::dmat4 vp = scene.viewProjection(cam);
  auto pixel = [&](const glm::dvec3& p, glm::dvec2* out) {
    const glm::dvec4 c = vp * glm::dvec4(p - origin, 1.0);
    if (!(c.w > 0.0)) return false;
    *out = (glm::dvec2(c) / c.w * 0.5 + 0.5) * glm::dvec2(640.0, 480.0);
    return out->x >= 0.0 && out->x <= 640.0 && out->y >= 0.0 && out->y <= 480.0;
  };
  Precision r;
  for (size_t i = 0; i < f.cut.nodes.size(); ++i) {
    const CutNode& n = f.cut.nodes[i];
    const ChartInfo& c = m.charts[n.id.chart];
    const uint32_t k = L - n.id.level - n.resLog2, side = (1u << n.resLog2) + 1;
    const uint32_t u0 = (n.id.x * (M >> n.id.level)) >> k, v0 = (n.id.y * (M >> n.id.level)) >> k;
    const uint32_t levelSide = (M >> k) + 1;
    const std::vector<float> level = ChartFileReader(a.dir / c.file).readHeightsWindow(k, 0, 0, M >> k);
    for (uint32_t j = 1; j + 1 < side; ++j)
      for (uint32_t ii = 1; ii + 1 < side; ++ii) {
        const int64_t gx = int64_t(c.gridX) * M + (int64_t(u0 + ii) << k),
                      gy = int64_t(c.gridY) * M + (int64_t(v0 + j) << k);
        const double hgt = level[size_t(v0 + j) * levelSide + (u0 + ii)];
        const glm::dvec3 exact = frame.position(gx, gy, hgt);
        const double dist = glm::length(exact - cam.eye);
        if (dist > 5.0e5) continue;
        ++r.near;
        const glm::dvec3 got = glm::dvec3(verts[i][size_t(j) * side + ii]) + origin;
        r.worst = std::max(r.worst, glm::length(got - exact) / (1e-3 + 5e-7 * dist));
        r.closest = std::min(r.closest, dist);
        if (dist == r.closest) r.closestError = glm::length(got - exact);
        const glm::dvec3 plain = glm::dvec3(glm::vec3(exact));
        r.control = std::max(r.control, glm::length(plain - exact));
        glm::dvec2 pe, pg, pp;
        if (pixel(exact, &pe) && pixel(got, &pg) && pixel(plain, &pp)) {
          ++r.inView;
          r.pixelWorst = std::max(r.pixelWorst, glm::length(pg - pe));
          r.pixelControl = std::max(r.pixelControl, glm::length(pp - pe));
        }
      }
  }
  std::printf(
      "%s: %llu vertices near, %llu in view, %.5f px from their exact projection (float32: %.3f px), "
      "the nearest %.0f m away within %.2g m\n",
      a.dir.filename().c_str(), (unsigned long long)r.near, (unsigned long long)r.inView, r.pixelWorst, r.pixelControl,
      r.closest, r.closestError);
  return r;
}

// Camera-relative precision: a camera a metre above the highest land, above the sea floor and by the
// antimeridian; every inner vertex the vertex shader places within 500 km lies within a millimetre
// plus 5e-7 of its distance of its double-precision position (the nearest, 36 to 60 km away on this
// lattice, within millimetres), where plain float32 planet-centred positions are off by decimetres.
TEST_F(PlanetTest, PositionsNearTheEyeKeepMillimetresAMetreAboveTheSurface) {
  for (const AtlasView* a : both()) {
    SCOPED_TRACE(a->dir.filename().string());
    gl::AtlasScene scene(*a, sceneOptions());
    for (const auto& [lon, lat] : {std::array<double, 2>{86.9, 28.0}, {-150.0, -20.0}, {179.9, 70.0}}) {
      const Precision p =
          measurePrecision(scene, *a, cameraAbove(*a, lon, lat, surfaceHeight(*a, lon, lat) + 1.0, 0.5));
      EXPECT_GT(p.near, 20u) << lon << ", " << lat;
      EXPECT_LT(p.worst, 1.0) << lon << ", " << lat;
      EXPECT_LT(10.0 * p.closestError, p.control)
          << lon << ", " << lat << ": the nearest sample, " << p.closest << " m away";
      EXPECT_GT(p.control, 0.05) << lon << ", " << lat;
    }
  }
}

// No jitter in the image: the shipped 3-arc-second tile (90 m) as a regional planet, on the sphere
// and on WGS84, seen from a metre above its summit and above its lowest sample. Every inner vertex
// in view lies within half a pixel (at 640 x 480) of where its double-precision position projects,
// and within a hundredth of how far float32 planet-centred positions move it: those move the
// sample a metre below the eye by tens of pixels, and the ground 90 m on by about one.
TEST_F(PlanetTest, AMetreAboveTheGroundTheImageDoesNotJitter) {
  for (const bool wgs84 : {false, true}) {
    TerrainBuildOptions o;
    o.input = test::repoData() / "terrain/mt_rainier_90m.tif";
    o.output = dir_->path() / (wgs84 ? "rainier-wgs84.atlas" : "rainier-sphere.atlas");
    o.planet = true;
    o.chartSize = 257;
    if (wgs84) {
      o.planetRadius = kEllipsoids[0].radius;
      o.planetFlattening = kEllipsoids[0].flattening;
    }
    buildAtlas(o);
    const AtlasView a = openAtlas(o.output);
    ASSERT_TRUE(a.manifest.planet.present);
    ASSERT_EQ(a.manifest.planet.wrapColumns, 0u) << "a regional planet";
    gl::AtlasScene scene(a, sceneOptions());
    // The highest and the lowest level-0 samples, from the charts.
    const uint32_t M = a.manifest.chartSize - 1;
    std::array<double, 3> high{0, 0, -1e30}, low{0, 0, 1e30};
    const PlanetFrame frame(a.manifest.planet, a.manifest.samplesX, a.manifest.samplesY);
    for (const ChartInfo& c : a.manifest.charts) {
      const std::vector<float> h = ChartFileReader(a.dir / c.file).readHeightsWindow(0, 0, 0, M);
      for (uint32_t v = 8; v + 8 <= M; ++v)
        for (uint32_t u = 8; u + 8 <= M; ++u) {
          const int64_t gx = int64_t(c.gridX) * M + u, gy = int64_t(c.gridY) * M + v;
          if (gx >= int64_t(a.manifest.samplesX) - 8 || gy >= int64_t(a.manifest.samplesY) - 8) continue;
          const double z = h[size_t(v) * (M + 1) + u];
          const std::array<double, 3> s{frame.longitude(gx) / kDeg, frame.latitude(gy) / kDeg, z};
          if (z > high[2]) high = s;
          if (z < low[2]) low = s;
        }
    }
    for (const auto& s : {high, low}) {
      SCOPED_TRACE(std::string(wgs84 ? "WGS84" : "sphere") + " at height " + std::to_string(s[2]));
      // Looking at the ground about 200 m north, a little down (vertices from 90 m on), and nearly
      // straight down (the sample a metre below the eye).
      for (const double ahead : {0.002, 0.00005}) {
        Camera cam;
        cam.eye = surfacePosition(a.manifest.planet, s[0] * kDeg, s[1] * kDeg, s[2] + 1.0);
        cam.target = surfacePosition(a.manifest.planet, s[0] * kDeg, (s[1] + ahead) * kDeg, s[2] - 20.0);
        cam.up = glm::normalize(cam.eye);
        cam.fovYDeg = 60.0;
        const Precision p = measurePrecision(scene, a, cam);
        EXPECT_GT(p.inView, ahead > 0.001 ? 50u : 0u) << ahead;
        EXPECT_LT(p.closest, 10.0) << "no vertex near the eye";
        EXPECT_LT(p.pixelWorst, 0.5) << ahead;
        EXPECT_GT(p.pixelControl, std::max(0.5, 100.0 * p.pixelWorst)) << ahead
                                                                       << ": float32 planet-centred positions "
                                                                          "do not jitter here";
        if (ahead < 0.001) {
          EXPECT_GT(p.pixelControl, 10.0) << "a metre from the eye, float32 jitters by pixels";
        }
      }
    }
  }
}

}  // namespace
}  // namespace gimlod

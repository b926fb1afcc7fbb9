// Terrain imagery end to end: the shipped Rainier DEM is built with a hand-made UTM image whose
// coloured squares sit on known geographic points; the imagery charts hold bit-identical colours
// on every shared border at every level, node pages carry the finer imagery, and `render` draws
// each square's colour where its point is (and the height colouring with the colours off).
#include <gtest/gtest.h>

#include <fstream>

#include <OpenImageIO/imageio.h>

#include "core/atlas_format.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"
#include "runtime/page_reader.h"
#include "tests/colour_seams.h"
#include "tests/imagery_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

class ImageryDrapedDem : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("gimlod-imagery-gl");
    const double* e = test::kRainierUtm;
    // 40 m pixels: finer than the DEM, so the atlas keeps 2 imagery samples per DEM interval.
    test::writeUtmImagery(dir_->path() / "utm.tif", test::rainierPoints(), e[0], e[1], e[2], e[3], 40.0, 3000.0);
    std::string out;
    const int rc = test::runCommand(
        test::appPath().string() + " build '" + (test::repoData() / "terrain" / "mt_rainier_90m.tif").string() +
            "' -o '" + atlas().string() + "' --chart-size 257 --imagery '" + (dir_->path() / "utm.tif").string() + "'",
        &out);
    if (rc != 0) ADD_FAILURE() << out;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path atlas() { return dir_->path() / "rainier.atlas"; }
  // World position of a geographic point on the atlas's terrain (z = 0).
  static glm::dvec3 world(const AtlasManifest& m, double lon, double lat) {
    const auto& gt = m.georef.geotransform;
    const double gx = (lon - (gt[0] + 0.5 * gt[1])) / gt[1];
    const double gy = (m.samplesY - 1) - (lat - (gt[3] + 0.5 * gt[5])) / gt[5];
    return {gx * m.spacing[0], gy * m.spacing[1], 0.0};
  }
  static test::TempDir* dir_;
};
test::TempDir* ImageryDrapedDem::dir_ = nullptr;

TEST_F(ImageryDrapedDem, ManifestAndPagesCarryTheFinerImagery) {
  const AtlasManifest m = readManifest(atlas());
  ASSERT_TRUE(m.imagery.present);
  EXPECT_EQ(m.imagery.scaleLog2, 1u);
  EXPECT_GT(m.imagery.coverage, 0.85);
  AtlasView view = openAtlas(atlas());
  const PageReader pages(atlas(), view.manifest, view.hierarchy.params);
  ASSERT_TRUE(pages.colours());
  EXPECT_EQ(pages.colourScaleLog2(), 1u);
  std::vector<float> samples;
  std::vector<PackedNormal> normals;
  std::vector<PackedColour> colours;
  const NodeId root{0, 0, 0, 0};
  pages.read(root, samples, normals, &colours);
  const size_t s = pages.pageSamples(root), cs = pages.colourPageSamples(root);
  EXPECT_EQ(cs, 2 * (s - 1) + 1);
  EXPECT_EQ(colours.size(), cs * cs);
  EXPECT_EQ(samples.size(), s * s);
}

TEST_F(ImageryDrapedDem, SharedEdgesHoldBitIdenticalImagery) {
  const AtlasManifest m = readManifest(atlas());
  ASSERT_GT(m.charts.size(), 4u);
  std::vector<std::unique_ptr<ChartFileReader>> charts;
  for (const ChartInfo& c : m.charts) charts.push_back(std::make_unique<ChartFileReader>(atlas() / c.imageryFile));
  const uint64_t compared =
      test::expectColourSeamsBitIdentical(m, charts, m.imagery.chartSize(m.chartSize), m.pyramidLevels());
  EXPECT_GT(compared, 5000u);
}

// Looking straight down on each point: the pixel there is its square's colour, lit.
TEST_F(ImageryDrapedDem, RenderDrawsTheImageryAtItsGeographicPoints) {
  const AtlasManifest m = readManifest(atlas());
  const auto points = test::rainierPoints();
  std::string frames = "{\"frames\": [";
  for (size_t i = 0; i < points.size(); ++i) {
    const glm::dvec3 p = world(m, points[i].lon, points[i].lat);
    const std::string x = std::to_string(p.x), y = std::to_string(p.y);
    frames += std::string(i ? ", " : "") + "{\"eye\": [" + x + ", " + y + ", 60000], \"target\": [" + x + ", " + y +
              ", 0], \"up\": [0, 1, 0], \"fov_deg\": 45}";
  }
  const fs::path path = dir_->path() / "points.json";
  std::ofstream(path) << frames << "]}";
  const fs::path out = dir_->path() / "frames";
  std::string log;
  ASSERT_EQ(test::runCommand(test::appPath().string() + " render '" + atlas().string() + "' --path '" + path.string() +
                                 "' --size 160x160 -o '" + out.string() + "'",
                             &log),
            0)
      << log;
  for (size_t i = 0; i < points.size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04zu.png", i);
    auto in = OIIO::ImageInput::open((out / name).string());
    ASSERT_TRUE(in);
    const int w = in->spec().width, h = in->spec().height, ch = in->spec().nchannels;
    std::vector<uint8_t> px(size_t(w) * h * ch);
    in->read_image(0, 0, 0, ch, OIIO::TypeDesc::UINT8, px.data());
    const uint8_t* p = &px[(size_t(h / 2) * w + w / 2) * ch];
    const auto& want = points[i].rgb;
    const size_t dominant = size_t(std::max_element(want.begin(), want.end()) - want.begin());
    for (size_t c = 0; c < 3; ++c) {
      if (c == dominant) continue;
      EXPECT_GT(int(p[dominant]), int(p[c]) + 60)
          << "point " << i << ": pixel " << int(p[0]) << "," << int(p[1]) << "," << int(p[2]);
    }
  }
}

// With the colours off the scene draws the height colouring at the summit: not the red square.
TEST_F(ImageryDrapedDem, SceneDrawsTheImageryOnlyWhenAsked) {
  auto context = gl::EglContext::create();
  const AtlasView view = openAtlas(atlas());
  gl::SceneOptions so;
  so.width = 64;
  so.height = 64;
  gl::AtlasScene scene(view, so);
  ASSERT_TRUE(scene.hasColours());
  const test::GeoPoint summit = test::rainierPoints()[0];
  const glm::dvec3 p = world(view.manifest, summit.lon, summit.lat);
  Camera cam;
  cam.eye = p + glm::dvec3(0.0, 0.0, 60000.0);
  cam.target = p;
  cam.up = {0.0, 1.0, 0.0};
  fitClipPlanes(cam, view.lo, view.hi);
  AdaptOptions ao;
  scene.renderFrame(cam, ao);
  const std::vector<uint8_t> coloured = scene.renderer().readPixels();
  scene.renderer().setColours(false);
  scene.renderFrame(cam, ao);
  const std::vector<uint8_t> plain = scene.renderer().readPixels();
  const size_t at = (size_t(32) * 64 + 32) * 4;
  EXPECT_GT(int(coloured[at]), int(coloured[at + 1]) + 60);
  EXPECT_LT(int(plain[at]), int(plain[at + 1]) + 30);
}

}  // namespace
}  // namespace gimlod

// Vertex colours of a mesh, end to end: a hand-made plane whose four quadrants have four colours
// is built into an atlas (colours resampled into every chart), its shared chart edges hold
// bit-identical colours at every pyramid level, and `render` draws each quadrant in its own
// colour seen from above (and the neutral material with the colours off, in the scene).
#include <gtest/gtest.h>

#include <fstream>

#include <OpenImageIO/imageio.h>

#include "core/atlas_format.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"
#include "tests/colour_seams.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

constexpr std::array<std::array<int, 3>, 4> kQuadrant{{{230, 40, 40}, {40, 200, 60}, {50, 70, 230}, {230, 210, 40}}};

// Quadrant of (x, y) in [0, 1]^2: 0 lower left, 1 lower right, 2 upper left, 3 upper right.
int quadrant(double x, double y) { return (x < 0.5 ? 0 : 1) + (y < 0.5 ? 0 : 2); }

// A plane of n x n quads over [0, 1]^2 at z = 0, faces up, coloured by quadrant.
void writeColouredPlane(const fs::path& file, int n) {
  std::ofstream f(file);
  f << "ply\nformat ascii 1.0\nelement vertex " << (n + 1) * (n + 1)
    << "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
       "property uchar blue\nelement face "
    << 2 * n * n << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = double(i) / n, y = double(j) / n;
      // Vertices on a dividing line take the colour of the quadrant above / to the right, so the
      // quadrants' centres are far from any blend.
      const auto& c = kQuadrant[size_t(quadrant(x, y))];
      f << x << " " << y << " 0 " << c[0] << " " << c[1] << " " << c[2] << "\n";
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      f << "3 " << a << " " << b << " " << d << "\n3 " << a << " " << d << " " << c << "\n";
    }
}

class ColouredMesh : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("gimlod-colour");
    writeColouredPlane(dir_->path() / "plane.ply", 48);
    std::string out;
    const int rc =
        test::runCommand(test::appPath().string() + " build '" + (dir_->path() / "plane.ply").string() + "' -o '" +
                             (dir_->path() / "plane.atlas").string() + "' --charts 8 --chart-size 33 --no-fidelity",
                         &out);
    if (rc != 0) ADD_FAILURE() << out;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path atlas() { return dir_->path() / "plane.atlas"; }
  static test::TempDir* dir_;
};
test::TempDir* ColouredMesh::dir_ = nullptr;

TEST_F(ColouredMesh, SharedEdgesHoldBitIdenticalColours) {
  const AtlasManifest m = readManifest(atlas());
  ASSERT_GT(m.charts.size(), 1u);
  std::vector<std::unique_ptr<ChartFileReader>> charts;
  for (const ChartInfo& c : m.charts) {
    charts.push_back(std::make_unique<ChartFileReader>(atlas() / c.file));
    ASSERT_TRUE(charts.back()->hasChannel(kChannelColours)) << c.file;
  }
  const uint64_t compared = test::expectColourSeamsBitIdentical(m, charts, m.chartSize, m.pyramidLevels());
  EXPECT_GT(compared, 100u);
}

// The plane seen from straight above: each quadrant's centre pixel is its colour, lit (the plane
// faces the light the same way everywhere, so each channel is the colour's times one factor).
TEST_F(ColouredMesh, RenderDrawsEachQuadrantInItsColour) {
  const fs::path path = dir_->path() / "top.json";
  std::ofstream(path)
      << R"({"frames": [{"eye": [0.5, 0.5, 2.0], "target": [0.5, 0.5, 0.0], "up": [0, 1, 0], "fov_deg": 45}]})";
  const fs::path frames = dir_->path() / "frames";
  std::string out;
  ASSERT_EQ(test::runCommand(test::appPath().string() + " render '" + atlas().string() + "' --path '" + path.string() +
                                 "' --size 200x200 -o '" + frames.string() + "'",
                             &out),
            0)
      << out;
  auto in = OIIO::ImageInput::open((frames / "frame_0000.png").string());
  ASSERT_TRUE(in);
  const int w = in->spec().width, h = in->spec().height, ch = in->spec().nchannels;
  std::vector<uint8_t> px(size_t(w) * h * ch);
  in->read_image(0, 0, 0, ch, OIIO::TypeDesc::UINT8, px.data());
  // World (x, y) -> pixel: the view's half height at the plane is 2 tan(22.5 deg).
  const double half = 2.0 * std::tan(glm::radians(22.5));
  double factor = -1.0;
  for (double y : {0.25, 0.75})
    for (double x : {0.25, 0.75}) {
      const int u = int((0.5 + (x - 0.5) / (2.0 * half)) * w), v = int((0.5 - (y - 0.5) / (2.0 * half)) * h);
      const uint8_t* p = &px[(size_t(v) * w + u) * ch];
      const auto& want = kQuadrant[size_t(quadrant(x, y))];
      // One lighting factor for all three channels (within rounding), the same in every quadrant.
      const double f = double(p[0] + p[1] + p[2]) / double(want[0] + want[1] + want[2]);
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(double(p[c]), f * want[size_t(c)], 6.0) << "quadrant at " << x << "," << y << " channel " << c;
      if (factor < 0.0) factor = f;
      EXPECT_NEAR(f, factor, 0.03) << "quadrant at " << x << "," << y;
      EXPECT_GT(f, 0.3);
    }
}

// In the scene: the colours can be switched off (the neutral material), and on again.
TEST_F(ColouredMesh, SceneDrawsColoursOnlyWhenAsked) {
  auto context = gl::EglContext::create();
  const AtlasView view = openAtlas(atlas());
  gl::SceneOptions so;
  so.width = 96;
  so.height = 96;
  gl::AtlasScene scene(view, so);
  EXPECT_TRUE(scene.hasColours());
  Camera cam;
  cam.eye = {0.5, 0.5, 2.0};
  cam.target = {0.5, 0.5, 0.0};
  cam.up = {0.0, 1.0, 0.0};
  fitClipPlanes(cam, view.lo, view.hi);
  AdaptOptions ao;
  scene.renderFrame(cam, ao);
  const std::vector<uint8_t> coloured = scene.renderer().readPixels();
  scene.renderer().setColours(false);
  scene.renderFrame(cam, ao);
  const std::vector<uint8_t> plain = scene.renderer().readPixels();
  // Lower-left quadrant's centre (red there): red dominates with colours, not without.
  const size_t at = (size_t(96 * 3 / 4 - 8) * 96 + 96 / 4 + 8) * 4;
  EXPECT_GT(int(coloured[at]), int(coloured[at + 1]) + 60);
  EXPECT_LT(std::abs(int(plain[at]) - int(plain[at + 1])), 30);
}

}  // namespace
}  // namespace gimlod

// Tests for the viewer's cameras: framing puts the whole box in view from the up axis's side,
// orbiting keeps the distance, zooming scales it, the fly camera moves at its speed along the
// view and looks about the eye, clip planes follow the eye into close-ups, a camera taken and given
// back is the same, and recorded paths read back as they were written.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "core/atlas_format.h"
#include "runtime/camera_control.h"
#include "tests/adapt_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

const glm::dvec3 kLo{-1.0, 0.0, -0.5}, kHi{1.0, 2.0, 0.5};

// The box's corners in normalized device coordinates of the camera (aspect 4:3).
std::vector<glm::dvec3> cornersInView(const Camera& c) {
  const glm::dmat4 vp = projectionMatrix(c, 4.0 / 3.0) * viewMatrix(c);
  std::vector<glm::dvec3> out;
  for (int i = 0; i < 8; ++i) {
    const glm::dvec4 p{(i & 1) ? kHi.x : kLo.x, (i & 2) ? kHi.y : kLo.y, (i & 4) ? kHi.z : kLo.z, 1.0};
    const glm::dvec4 q = vp * p;
    out.push_back(glm::dvec3(q) / q.w);
  }
  return out;
}

TEST(CameraControl, ParsesUpAxes) {
  EXPECT_EQ(parseUpAxis("y")->axis, 1);
  EXPECT_EQ(parseUpAxis("+z")->vector(), glm::dvec3(0, 0, 1));
  EXPECT_EQ(parseUpAxis("-x")->vector(), glm::dvec3(-1, 0, 0));
  EXPECT_FALSE(parseUpAxis("w"));
  EXPECT_FALSE(parseUpAxis("yy"));
  EXPECT_FALSE(parseUpAxis(""));
}

TEST(CameraControl, FramesTheWholeBoxFromTheUpAxisSide) {
  for (const char* axis : {"y", "z", "-y"}) {
    SCOPED_TRACE(axis);
    const UpAxis up = *parseUpAxis(axis);
    CameraControl control(kLo, kHi, up);
    const Camera c = control.camera();
    EXPECT_EQ(c.up, up.vector());
    for (const glm::dvec3& p : cornersInView(c)) {
      EXPECT_LE(std::abs(p.x), 1.0);
      EXPECT_LE(std::abs(p.y), 1.0);
      EXPECT_GT(p.z, -1.0);
      EXPECT_LT(p.z, 1.0);
    }
    // Looking down at the centre from above the horizon.
    const glm::dvec3 centre = (kLo + kHi) * 0.5;
    EXPECT_NEAR(glm::length(c.target - centre), 0.0, 1e-12);
    EXPECT_GT(glm::dot(c.eye - centre, up.vector()), 0.0);
  }
  // y up looks at a scan's front (+z); z up from the south (-y).
  EXPECT_GT(CameraControl(kLo, kHi, *parseUpAxis("y")).camera().eye.z, 0.5);
  EXPECT_LT(CameraControl(kLo, kHi, *parseUpAxis("z")).camera().eye.y, 0.0);
}

TEST(CameraControl, OrbitKeepsTheDistanceAndZoomScalesIt) {
  CameraControl control(kLo, kHi, *parseUpAxis("y"));
  const glm::dvec3 centre = (kLo + kHi) * 0.5;
  const double d0 = glm::length(control.camera().eye - centre);
  const glm::dvec3 e0 = control.camera().eye;
  control.rotate(120.0, -40.0, 600.0);
  const Camera turned = control.camera();
  EXPECT_NEAR(glm::length(turned.eye - centre), d0, 1e-9);
  EXPECT_GT(glm::length(turned.eye - e0), 0.1 * d0);
  EXPECT_NEAR(glm::length(turned.target - centre), 0.0, 1e-9);
  // A drag across the whole height turns by half a turn (pitch clamped short of the pole).
  control.zoom(2.0);
  EXPECT_NEAR(glm::length(control.camera().eye - centre), d0 * 0.85 * 0.85, 1e-9);
  control.zoom(-2.0);
  EXPECT_NEAR(glm::length(control.camera().eye - centre), d0, 1e-9);
  // Pitch stops short of the pole: no degenerate view.
  control.rotate(0.0, 5000.0, 600.0);
  const Camera top = control.camera();
  EXPECT_LT(std::abs(glm::dot(glm::normalize(top.eye - top.target), glm::dvec3(0, 1, 0))), 1.0);
  // Panning moves centre and eye together.
  const Camera before = control.camera();
  control.pan(50.0, 0.0, 600.0);
  const Camera panned = control.camera();
  EXPECT_NEAR(glm::length((panned.eye - before.eye) - (panned.target - before.target)), 0.0, 1e-9);
  EXPECT_GT(glm::length(panned.eye - before.eye), 0.0);
}

TEST(CameraControl, FlyMovesAtItsSpeedAndClipPlanesFollow) {
  CameraControl control(kLo, kHi, *parseUpAxis("y"));
  control.setMode(CameraControl::Mode::kFly);
  const Camera start = control.camera();
  const glm::dvec3 forward = glm::normalize(start.target - start.eye);
  const double speed = control.flySpeed();
  EXPECT_GT(speed, 0.0);
  control.move({0.0, 0.0, 1.0}, 0.5);
  const Camera ahead = control.camera();
  EXPECT_NEAR(glm::length(ahead.eye - start.eye), 0.5 * speed, 1e-9);
  EXPECT_NEAR(glm::dot(glm::normalize(ahead.eye - start.eye), forward), 1.0, 1e-9);
  // Flying on towards the box's centre the eye enters it; there the speed drops to 1% of the
  // diagonal, and near comes in close.
  const auto inside = [&](const glm::dvec3& e) {
    return glm::all(glm::greaterThanEqual(e, kLo)) && glm::all(glm::lessThanEqual(e, kHi));
  };
  for (int i = 0; i < 1000 && !inside(control.camera().eye); ++i) control.move({0.0, 0.0, 1.0}, 0.02);
  ASSERT_TRUE(inside(control.camera().eye));
  EXPECT_NEAR(control.flySpeed(), 0.01 * glm::length(kHi - kLo), 1e-12);
  EXPECT_LT(control.camera().nearPlane, start.nearPlane);
  // Looking about turns the view, not the eye.
  const Camera beforeLook = control.camera();
  control.rotate(100.0, 0.0, 600.0);
  const Camera looked = control.camera();
  EXPECT_EQ(looked.eye, beforeLook.eye);
  EXPECT_LT(glm::dot(glm::normalize(looked.target - looked.eye), glm::normalize(beforeLook.target - beforeLook.eye)),
            0.99);
  // Scroll in fly mode changes the speed.
  control.zoom(-3.0);
  EXPECT_LT(control.flySpeed(), 0.01 * glm::length(kHi - kLo) + 1e-12);
}

// Low over the surface (inside the box): the speed follows the height above the surface, and
// the near plane comes in to half of it, so the close-up does not clip.
TEST(CameraControl, SpeedAndNearPlaneFollowTheHeightAboveTheSurface) {
  CameraControl control(kLo, kHi, *parseUpAxis("z"));
  control.setMode(CameraControl::Mode::kFly);
  const double diag = glm::length(kHi - kLo);
  const double boxNear = control.camera().nearPlane;
  control.setSurfaceDistance(0.2 * diag);
  EXPECT_NEAR(control.flySpeed(), 0.2 * diag, 1e-12);
  control.setSurfaceDistance(0.02 * diag);
  EXPECT_NEAR(control.flySpeed(), 0.02 * diag, 1e-12);  // ten times lower, ten times slower
  control.setSurfaceDistance(1e-9 * diag);
  EXPECT_NEAR(control.flySpeed(), 0.001 * diag, 1e-12);  // the floor
  control.setSurfaceDistance(1e-3 * diag);
  EXPECT_NEAR(control.camera().nearPlane, std::min(0.5e-3 * diag, boxNear), 1e-12);
  control.setSurfaceDistance(-1.0);  // unknown: the box again
  EXPECT_NEAR(control.camera().nearPlane, boxNear, 1e-12);
}

// distanceToSurface is the nearest leaf box's distance (brute force over every leaf agrees), 0 on
// the surface, and above a terrain it tracks the height above the ground below.
TEST(CameraControl, DistanceToSurfaceIsTheNearestLeafBox) {
  const test::World w = test::makeWorld(33, 3, 2, 4);
  const uint32_t leaf = w.h.params.depth - 1;
  const auto bruteForce = [&](const glm::dvec3& p) {
    double best = std::numeric_limits<double>::infinity();
    for (uint32_t c = 0; c < w.h.chartCount(); ++c)
      for (uint32_t y = 0; y < (1u << leaf); ++y)
        for (uint32_t x = 0; x < (1u << leaf); ++x) {
          const auto& b = w.h.bounds(NodeId{c, leaf, x, y});
          const glm::dvec3 lo(b[0], b[1], b[2]), hi(b[3], b[4], b[5]);
          best = std::min(best, glm::length(glm::clamp(p, lo, hi) - p));
        }
    return best;
  };
  for (const glm::dvec3& p : {glm::dvec3(10.5, 20.25, 200.0), glm::dvec3(-40.0, 70.0, 5.0),
                              glm::dvec3(50.0, 30.0, 21.0), glm::dvec3(90.0, 60.0, -80.0)})
    EXPECT_DOUBLE_EQ(distanceToSurface(w.h, p), bruteForce(p)) << p.x << "," << p.y << "," << p.z;
  const double ground = test::syntheticHeight(40, 20);
  EXPECT_DOUBLE_EQ(distanceToSurface(w.h, {40.0, 20.0, ground}), 0.0);
  const double high = distanceToSurface(w.h, {40.0, 20.0, ground + 500.0});
  EXPECT_LE(high, 500.0);
  EXPECT_GT(high, 500.0 - 45.0);  // no leaf box reaches above the relief (heights within +-21.5)
}

TEST(CameraControl, ACameraGivenBackIsTheSame) {
  CameraControl control(kLo, kHi, *parseUpAxis("z"));
  Camera c;
  c.eye = {3.0, -2.0, 1.5};
  c.target = {0.2, 0.9, -0.1};
  c.up = {0.0, 0.0, 1.0};
  c.fovYDeg = 50.0;
  control.setCamera(c);
  const Camera back = control.camera();
  EXPECT_NEAR(glm::length(back.eye - c.eye), 0.0, 1e-12);
  EXPECT_NEAR(glm::length(back.target - c.target), 0.0, 1e-12);
  EXPECT_EQ(back.fovYDeg, 50.0);
  // Switching to fly and back keeps the view.
  control.setMode(CameraControl::Mode::kFly);
  control.setMode(CameraControl::Mode::kOrbit);
  EXPECT_NEAR(glm::length(control.camera().eye - c.eye), 0.0, 1e-12);
  control.frame();
  EXPECT_GT(glm::length(control.camera().eye - c.eye), 0.1);
}

TEST(CameraControl, RecordedPathsReadBackAsWritten) {
  test::TempDir dir("gimlod-camera-path");
  CameraControl control(kLo, kHi, *parseUpAxis("y"));
  std::vector<Camera> cams;
  for (int i = 0; i < 5; ++i) {
    cams.push_back(control.camera());
    control.rotate(30.0, 5.0, 400.0);
  }
  const auto file = dir.path() / "path.json";
  writeCameraPath(file, cams);
  const std::vector<Camera> back = readCameraPath(file);
  ASSERT_EQ(back.size(), cams.size());
  for (size_t i = 0; i < cams.size(); ++i) {
    EXPECT_EQ(back[i].eye, cams[i].eye);
    EXPECT_EQ(back[i].target, cams[i].target);
    EXPECT_EQ(back[i].up, cams[i].up);
    EXPECT_EQ(back[i].fovYDeg, cams[i].fovYDeg);
    EXPECT_EQ(back[i].nearPlane, cams[i].nearPlane);
    EXPECT_EQ(back[i].farPlane, cams[i].farPlane);
  }
  EXPECT_THROW(writeCameraPath(dir.path() / "missing" / "path.json", cams), InputError);
}

// The fly-down path: from a diagonal above the box's top to 1/500 of it, always lower, over the
// box, towards its centre, looking ahead and down.
TEST(CameraPaths, DescentFliesDownFromTheWholeBoxToNearItsTop) {
  const glm::dvec3 lo(0, 0, -100), hi(40000, 20000, 4000);
  const double diagonal = glm::length(hi - lo);
  const std::vector<Camera> path = descentPath(lo, hi, 50);
  ASSERT_EQ(path.size(), 50u);
  EXPECT_NEAR(path.front().eye.z - hi.z, diagonal, 1e-6 * diagonal);
  EXPECT_NEAR(path.back().eye.z - hi.z, 0.002 * diagonal, 1e-6 * diagonal);
  EXPECT_NEAR(path.back().eye.x, 20000, 1e-6);
  EXPECT_NEAR(path.back().eye.y, 10000, 1e-6);
  for (size_t i = 0; i < path.size(); ++i) {
    const Camera& c = path[i];
    if (i > 0) {
      EXPECT_LT(c.eye.z, path[i - 1].eye.z) << i;
    }
    EXPECT_GE(c.eye.x, lo.x);
    EXPECT_LE(c.eye.x, hi.x);
    EXPECT_LT(c.target.z, c.eye.z);
    EXPECT_GT(c.farPlane, c.nearPlane);
    EXPECT_GT(c.nearPlane, 0.0);
  }
  EXPECT_TRUE(descentPath(lo, hi, 0).empty());
}

}  // namespace
}  // namespace gimlod

namespace gimlod {
namespace {

// Flying round a planet: up stays away from its centre, and a heading held while the eye moves a
// quarter of the way round keeps the view level (its pitch against the local horizon).
TEST(CameraControl, FlyingOverAPlanetKeepsUpRadialAndTheHorizonLevel) {
  const double R = 6.371e6;
  CameraControl c(glm::dvec3(-R), glm::dvec3(R), UpAxis{2, 1.0});
  c.setRadialUp(true);
  Camera start;
  start.eye = {R + 1000.0, 0.0, 0.0};
  start.target = {R + 900.0, 5000.0, 0.0};  // east, a little down
  start.fovYDeg = 45.0;
  c.setCamera(start);
  c.setMode(CameraControl::Mode::kFly);
  auto pitch = [&]() {
    const Camera k = c.camera();
    const glm::dvec3 f = glm::normalize(k.target - k.eye), up = glm::normalize(k.eye);
    return std::asin(glm::dot(f, up));
  };
  const double before = pitch();
  EXPECT_NEAR(glm::dot(glm::normalize(c.camera().up), glm::normalize(c.camera().eye)), 1.0, 1e-12);
  // The view kept across the switch.
  EXPECT_NEAR(glm::dot(glm::normalize(c.camera().target - c.camera().eye), glm::normalize(start.target - start.eye)),
              1.0, 1e-9);
  c.setSurfaceDistance(1000.0);
  auto longitude = [&]() { return std::atan2(c.eye().y, c.eye().x); };
  for (int i = 0; i < 2000 && longitude() < 1.0; ++i) c.move({0.0, 0.0, 1.0}, 1.0);  // forward, east
  EXPECT_GE(longitude(), 1.0);                                                       // flown a sixth of the way round
  EXPECT_LT(std::fabs(c.eye().z), 1.0);                                              // along the equator
  EXPECT_NEAR(glm::dot(glm::normalize(c.camera().up), glm::normalize(c.camera().eye)), 1.0, 1e-12);
  EXPECT_NEAR(pitch(), before, 1e-6);
  // Orbiting keeps the axis up.
  c.setMode(CameraControl::Mode::kOrbit);
  EXPECT_EQ(c.camera().up, glm::dvec3(0.0, 0.0, 1.0));
}

}  // namespace
}  // namespace gimlod

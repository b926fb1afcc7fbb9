#include "runtime/camera_control.h"

#include <limits>
#include <utility>
#include <vector>

#include <algorithm>
#include <cmath>
#include <numbers>

#include <nlohmann/json.hpp>

#include "core/atlas_format.h"

namespace gimlod {
namespace {

constexpr double kMaxPitch = 89.0 * std::numbers::pi / 180.0;

glm::dvec3 unit(int axis) {
  glm::dvec3 v(0.0);
  v[axis] = 1.0;
  return v;
}

// The two horizontal axes (a, b) of an up axis, with a x b = up.
void horizontal(const UpAxis& up, glm::dvec3* a, glm::dvec3* b) {
  *a = unit((up.axis + 1) % 3);
  *b = unit((up.axis + 2) % 3);
  if (up.sign < 0) std::swap(*a, *b);
}

}  // namespace

glm::dvec3 UpAxis::vector() const { return unit(axis) * sign; }

std::optional<UpAxis> parseUpAxis(const std::string& text) {
  std::string t = text;
  double sign = 1.0;
  if (!t.empty() && (t[0] == '+' || t[0] == '-')) {
    sign = t[0] == '-' ? -1.0 : 1.0;
    t = t.substr(1);
  }
  if (t.size() != 1 || t[0] < 'x' || t[0] > 'z') return std::nullopt;
  return UpAxis{t[0] - 'x', sign};
}

CameraControl::CameraControl(const glm::dvec3& lo, const glm::dvec3& hi, UpAxis up, double fovYDeg)
    : lo_(lo), hi_(hi), up_(up), fov_(fovYDeg) {
  frame();
}

void CameraControl::frame() {
  mode_ = Mode::kOrbit;
  centre_ = (lo_ + hi_) * 0.5;
  const double radius = std::max(0.5 * glm::length(hi_ - lo_), 1e-12);
  distance_ = radius / std::sin(0.5 * glm::radians(fov_));
  // y up (scans): from +z, a scan's front; z up (terrain): from the south (-y).
  yaw_ = up_.axis == 2 ? -0.5 * std::numbers::pi : 0.0;
  pitch_ = glm::radians(35.0);
  speedFactor_ = 1.0;
  updateEye();
}

void CameraControl::basis(glm::dvec3* a, glm::dvec3* b, glm::dvec3* up) const {
  const double r = glm::length(eye_);
  if (radialUp_ && mode_ == Mode::kFly && r > 0.0) {
    // The local east, north and up of a planet: up away from its centre.
    *up = eye_ / r;
    const glm::dvec3 e = glm::cross(glm::dvec3(0.0, 0.0, 1.0), *up);
    *a = glm::length(e) > 1e-9 ? glm::normalize(e) : glm::dvec3(1.0, 0.0, 0.0);
    *b = glm::cross(*up, *a);
    return;
  }
  horizontal(up_, a, b);
  *up = up_.vector();
}

glm::dvec3 CameraControl::upVector() const {
  glm::dvec3 a, b, up;
  basis(&a, &b, &up);
  return up;
}

glm::dvec3 CameraControl::forward() const {
  glm::dvec3 a, b, up;
  basis(&a, &b, &up);
  const glm::dvec3 d = std::cos(pitch_) * (std::cos(yaw_) * a + std::sin(yaw_) * b) + std::sin(pitch_) * up;
  return -d;
}

void CameraControl::lookAlong(const glm::dvec3& f) {
  glm::dvec3 a, b, up;
  basis(&a, &b, &up);
  const glm::dvec3 d = -glm::normalize(f);
  pitch_ = std::clamp(std::asin(std::clamp(glm::dot(d, up), -1.0, 1.0)), -kMaxPitch, kMaxPitch);
  yaw_ = std::atan2(glm::dot(d, b), glm::dot(d, a));
}

void CameraControl::updateEye() { eye_ = centre_ - distance_ * forward(); }

void CameraControl::setMode(Mode m) {
  if (m == mode_) return;
  const glm::dvec3 f = forward();
  mode_ = m;
  lookAlong(f);  // the same view in the new mode's frame (a planet's local one when flying)
  centre_ = eye_ + distance_ * forward();
}

void CameraControl::rotate(double dxPx, double dyPx, double heightPx) {
  const double k = std::numbers::pi / std::max(heightPx, 1.0);
  yaw_ -= dxPx * k;
  pitch_ = std::clamp(pitch_ + dyPx * k, -kMaxPitch, kMaxPitch);
  if (mode_ == Mode::kOrbit) {
    updateEye();
  } else {
    centre_ = eye_ + distance_ * forward();
  }
}

void CameraControl::pan(double dxPx, double dyPx, double heightPx) {
  const glm::dvec3 f = forward();
  const glm::dvec3 right = glm::normalize(glm::cross(f, upVector()));
  const glm::dvec3 up = glm::cross(right, f);
  const double scale = mode_ == Mode::kOrbit
                           ? 2.0 * distance_ * std::tan(0.5 * glm::radians(fov_)) / std::max(heightPx, 1.0)
                           : flySpeed() / std::max(heightPx, 1.0);
  const glm::dvec3 shift = (-dxPx * right + dyPx * up) * scale;
  centre_ += shift;
  eye_ += shift;
}

void CameraControl::zoom(double steps) {
  const double factor = std::pow(0.85, steps);
  if (mode_ == Mode::kOrbit) {
    const double diag = glm::length(hi_ - lo_);
    distance_ = std::clamp(distance_ * factor, 1e-5 * diag, 100.0 * diag);
    updateEye();
  } else {
    speedFactor_ = std::clamp(speedFactor_ / factor, 1e-3, 1e3);
  }
}

void CameraControl::move(const glm::dvec3& rightUpForward, double seconds) {
  const glm::dvec3 f = forward();
  const glm::dvec3 right = glm::normalize(glm::cross(f, upVector()));
  const double step = flySpeed() * seconds;
  if (mode_ == Mode::kFly) {
    const glm::dvec3 shift = (rightUpForward.x * right + rightUpForward.y * upVector() + rightUpForward.z * f) * step;
    eye_ += shift;
    // On a planet the local frame turns with the eye: the heading and pitch stay, the horizon level.
    centre_ = eye_ + distance_ * forward();
    return;
  }
  const double diag = glm::length(hi_ - lo_);
  distance_ = std::clamp(distance_ * std::exp(-rightUpForward.z * seconds), 1e-5 * diag, 100.0 * diag);
  const glm::dvec3 shift = (rightUpForward.x * right + rightUpForward.y * up_.vector()) * step;
  centre_ += shift;
  updateEye();
}

double CameraControl::flySpeed() const {
  const double diag = glm::length(hi_ - lo_);
  if (surfaceDistance_ >= 0.0) return std::max(surfaceDistance_, 0.001 * diag) * speedFactor_;
  const double gap = glm::length(glm::clamp(eye_, lo_, hi_) - eye_);
  return std::max(gap, 0.01 * diag) * speedFactor_;
}

Camera CameraControl::camera() const {
  Camera c;
  c.eye = eye_;
  c.target = eye_ + distance_ * forward();
  c.up = upVector();
  c.fovYDeg = fov_;
  c.nearPlane = 0.0;
  c.farPlane = 0.0;
  fitClipPlanes(c, lo_, hi_);
  if (surfaceDistance_ >= 0.0)
    c.nearPlane = std::clamp(0.5 * surfaceDistance_, 1e-6 * glm::length(hi_ - lo_), c.nearPlane);
  return c;
}

void CameraControl::setCamera(const Camera& c) {
  mode_ = Mode::kOrbit;
  eye_ = c.eye;
  centre_ = c.target;
  fov_ = c.fovYDeg;
  distance_ = std::max(glm::length(eye_ - centre_), 1e-12);
  const glm::dvec3 d = (eye_ - centre_) / distance_;
  glm::dvec3 a, b;
  horizontal(up_, &a, &b);
  pitch_ = std::clamp(std::asin(std::clamp(glm::dot(d, up_.vector()), -1.0, 1.0)), -kMaxPitch, kMaxPitch);
  yaw_ = std::atan2(glm::dot(d, b), glm::dot(d, a));
  updateEye();
}

double distanceToSurface(const Hierarchy& h, const glm::dvec3& p) {
  const auto boxDistance = [&](const NodeId& n) {
    const std::array<float, 6>& b = h.bounds(n);
    const glm::dvec3 lo(b[0], b[1], b[2]), hi(b[3], b[4], b[5]);
    return glm::length(glm::clamp(p, lo, hi) - p);
  };
  double best = std::numeric_limits<double>::infinity();
  std::vector<std::pair<double, NodeId>> stack;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    stack.emplace_back(boxDistance(root), root);
  }
  const uint32_t leaf = h.params.depth - 1;
  while (!stack.empty()) {
    const auto [d, n] = stack.back();
    stack.pop_back();
    if (d >= best) continue;
    if (n.level == leaf) {
      best = d;
      continue;
    }
    for (uint32_t i = 0; i < 4; ++i) {
      const NodeId k = n.child(i);
      const double dk = boxDistance(k);
      if (dk < best) stack.emplace_back(dk, k);
    }
  }
  return best;
}

void writeCameraPath(const std::filesystem::path& path, const std::vector<Camera>& cameras) {
  nlohmann::json frames = nlohmann::json::array();
  for (const Camera& c : cameras) {
    frames.push_back({{"eye", {c.eye.x, c.eye.y, c.eye.z}},
                      {"target", {c.target.x, c.target.y, c.target.z}},
                      {"up", {c.up.x, c.up.y, c.up.z}},
                      {"fov_deg", c.fovYDeg},
                      {"near", c.nearPlane},
                      {"far", c.farPlane}});
  }
  const std::string text = nlohmann::json{{"frames", frames}}.dump(1) + "\n";
  try {
    atomicWriteFile(path, text.data(), text.size());
  } catch (const std::exception& e) {
    throw InputError(path.string() + ": cannot write the camera path: " + e.what());
  }
}

}  // namespace gimlod

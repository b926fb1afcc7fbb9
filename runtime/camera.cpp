#include "runtime/camera.h"

#include <array>
#include <cmath>
#include <fstream>
#include <numbers>

#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include "core/atlas_format.h"

namespace gimlod {

void Frustum::setHorizon(const glm::dvec3& eye, double radius) {
  horizonEye = eye;
  occluderRadius = radius;
}

int Frustum::horizonClass(const glm::dvec3& lo, const glm::dvec3& hi) const {
  const double e = glm::length(horizonEye), r = occluderRadius;
  if (!(r > 0.0) || !(e > r)) return 2;
  const glm::dvec3 n = horizonEye / e;
  const double plane = r * r / e, cosCone = std::sqrt(e * e - r * r) / e;
  bool allHidden = true, allFront = true;
  for (int i = 0; i < 8; ++i) {
    const glm::dvec3 x{(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z};
    const double along = glm::dot(n, x);
    if (along <= plane) allFront = false;
    const glm::dvec3 d = x - horizonEye;
    if (!(along <= plane && -glm::dot(d, n) >= glm::length(d) * cosCone)) allHidden = false;
  }
  return allHidden ? 0 : allFront ? 2 : 1;
}

bool Frustum::intersects(const glm::dvec3& lo, const glm::dvec3& hi) const {
  if (occluderRadius > 0.0 && horizonClass(lo, hi) == 0) return false;
  for (const glm::dvec4& p : planes) {
    const glm::dvec3 v{p.x >= 0 ? hi.x : lo.x, p.y >= 0 ? hi.y : lo.y, p.z >= 0 ? hi.z : lo.z};
    if (p.x * v.x + p.y * v.y + p.z * v.z + p.w < 0) return false;
  }
  return true;
}

int Frustum::classify(const glm::dvec3& lo, const glm::dvec3& hi) const {
  int result = occluderRadius > 0.0 ? horizonClass(lo, hi) : 2;
  if (result == 0) return 0;
  for (const glm::dvec4& p : planes) {
    const glm::dvec3 v{p.x >= 0 ? hi.x : lo.x, p.y >= 0 ? hi.y : lo.y, p.z >= 0 ? hi.z : lo.z};
    if (p.x * v.x + p.y * v.y + p.z * v.z + p.w < 0) return 0;
    const glm::dvec3 u{p.x >= 0 ? lo.x : hi.x, p.y >= 0 ? lo.y : hi.y, p.z >= 0 ? lo.z : hi.z};
    if (p.x * u.x + p.y * u.y + p.z * u.z + p.w < 0) result = 1;
  }
  return result;
}

glm::dmat4 viewMatrix(const Camera& c) { return glm::lookAt(c.eye, c.target, c.up); }

glm::dmat4 projectionMatrix(const Camera& c, double aspect) {
  return glm::perspective(glm::radians(c.fovYDeg), aspect, c.nearPlane, c.farPlane);
}

glm::dmat4 reversedProjectionMatrix(const Camera& c, double aspect) {
  const double f = 1.0 / std::tan(glm::radians(c.fovYDeg) / 2.0);
  glm::dmat4 m(0.0);
  m[0][0] = f / aspect;
  m[1][1] = f;
  m[2][3] = -1.0;
  m[3][2] = c.nearPlane;
  return m;
}

Frustum frustumFromMatrix(const glm::dmat4& m) {
  // Gribb-Hartmann: rows of the matrix combined.
  auto row = [&](int i) { return glm::dvec4(m[0][i], m[1][i], m[2][i], m[3][i]); };
  Frustum f;
  f.planes = {row(3) + row(0), row(3) - row(0), row(3) + row(1), row(3) - row(1), row(3) + row(2), row(3) - row(2)};
  for (auto& p : f.planes) p /= glm::length(glm::dvec3(p));
  return f;
}

double pixelsPerRadian(const Camera& c, uint32_t viewportHeight) {
  return double(viewportHeight) / (2.0 * std::tan(glm::radians(c.fovYDeg) * 0.5));
}

void fitClipPlanes(Camera& c, const glm::dvec3& lo, const glm::dvec3& hi) {
  const double diag = glm::length(hi - lo);
  double farthest = 0.0;
  for (int i = 0; i < 8; ++i) {
    const glm::dvec3 corner{(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z};
    farthest = std::max(farthest, glm::length(corner - c.eye));
  }
  const glm::dvec3 closest = glm::clamp(c.eye, lo, hi);
  const double dist = glm::length(closest - c.eye);
  if (c.farPlane <= 0) c.farPlane = farthest * 1.01 + 1.0;
  if (c.nearPlane <= 0) c.nearPlane = std::max({dist * 0.5, diag * 1e-4, 1e-3});
}

namespace {

// A camera at eye looking at target, z up, its clip planes fitted to the box.
Camera zUpCamera(const glm::dvec3& eye, const glm::dvec3& target, double fovYDeg, const glm::dvec3& lo,
                 const glm::dvec3& hi) {
  Camera c;
  c.eye = eye;
  c.target = target;
  c.up = {0.0, 0.0, 1.0};
  c.fovYDeg = fovYDeg;
  c.nearPlane = 0.0;
  c.farPlane = 0.0;
  fitClipPlanes(c, lo, hi);
  return c;
}

}  // namespace

std::vector<Camera> orbitPath(const glm::dvec3& lo, const glm::dvec3& hi, uint32_t frames, double distanceFraction,
                              double elevationDeg, double fovYDeg) {
  const glm::dvec3 centre = (lo + hi) * 0.5;
  const double radius = glm::length(hi - lo) * distanceFraction;
  const double el = glm::radians(elevationDeg);
  std::vector<Camera> path;
  for (uint32_t i = 0; i < frames; ++i) {
    const double a = 2.0 * std::numbers::pi * double(i) / double(std::max(frames, 1u));
    path.push_back(
        zUpCamera(centre + radius * glm::dvec3(std::cos(el) * std::cos(a), std::cos(el) * std::sin(a), std::sin(el)),
                  centre, fovYDeg, lo, hi));
  }
  return path;
}

std::vector<Camera> descentPath(const glm::dvec3& lo, const glm::dvec3& hi, uint32_t frames, double fovYDeg) {
  const glm::dvec3 centre = (lo + hi) * 0.5, ext = hi - lo;
  const double diagonal = std::max(glm::length(ext), 1e-12);
  const glm::dvec2 start(lo.x + 0.1 * ext.x, lo.y + 0.1 * ext.y);
  const glm::dvec2 end(centre.x, centre.y);
  std::vector<Camera> path;
  for (uint32_t i = 0; i < frames; ++i) {
    const double s = frames > 1 ? double(i) / double(frames - 1) : 0.0;
    const double height = diagonal * std::pow(0.002, s);
    const glm::dvec2 at = start + s * (end - start);
    glm::dvec2 ahead = end - start;
    ahead = glm::length(ahead) > 0 ? ahead / glm::length(ahead) : glm::dvec2(1.0, 0.0);
    const glm::dvec2 look = at + ahead * (1.5 * height);
    path.push_back(zUpCamera({at.x, at.y, hi.z + height}, {look.x, look.y, centre.z}, fovYDeg, lo, hi));
  }
  return path;
}

std::vector<Camera> axisViews(const glm::dvec3& lo, const glm::dvec3& hi, double fovYDeg,
                              std::vector<std::string>* names) {
  const glm::dvec3 centre = (lo + hi) * 0.5;
  const double radius = std::max(0.5 * glm::length(hi - lo), 1e-12);
  const double distance = radius / std::sin(0.5 * glm::radians(fovYDeg));
  static const std::array<std::pair<glm::dvec3, const char*>, 6> kAxes = {{{{1, 0, 0}, "+x"},
                                                                           {{-1, 0, 0}, "-x"},
                                                                           {{0, 1, 0}, "+y"},
                                                                           {{0, -1, 0}, "-y"},
                                                                           {{0, 0, 1}, "+z"},
                                                                           {{0, 0, -1}, "-z"}}};
  std::vector<Camera> views;
  if (names) names->clear();
  for (const auto& [axis, name] : kAxes) {
    Camera c;
    c.eye = centre + distance * axis;
    c.target = centre;
    c.up = axis.z != 0.0 ? glm::dvec3(0.0, 1.0, 0.0) : glm::dvec3(0.0, 0.0, 1.0);
    c.fovYDeg = fovYDeg;
    c.nearPlane = 0.0;
    c.farPlane = 0.0;
    fitClipPlanes(c, lo, hi);
    views.push_back(c);
    if (names) names->push_back(name);
  }
  return views;
}

std::vector<Camera> readCameraPath(const std::filesystem::path& path) {
  std::ifstream f(path);
  if (!f) throw InputError(path.string() + ": cannot open camera path");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(f);
  } catch (const std::exception& e) {
    throw InputError(path.string() + ": invalid JSON: " + e.what());
  }
  const nlohmann::json& frames = j.is_object() && j.contains("frames") ? j["frames"] : j;
  if (!frames.is_array() || frames.empty()) throw InputError(path.string() + ": expected a non-empty list of frames");
  auto vec3 = [&](const nlohmann::json& fr, const char* key, size_t i, bool required, glm::dvec3 fallback) {
    if (!fr.contains(key)) {
      if (required) throw InputError(path.string() + ": frame " + std::to_string(i) + " has no \"" + key + "\"");
      return fallback;
    }
    const auto& a = fr[key];
    if (!a.is_array() || a.size() != 3 || !a[0].is_number() || !a[1].is_number() || !a[2].is_number())
      throw InputError(path.string() + ": frame " + std::to_string(i) + ": \"" + key + "\" must be [x, y, z]");
    glm::dvec3 v{a[0].get<double>(), a[1].get<double>(), a[2].get<double>()};
    if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
      throw InputError(path.string() + ": frame " + std::to_string(i) + ": non-finite \"" + key + "\"");
    return v;
  };
  // An optional finite number.
  auto number = [&](const nlohmann::json& fr, const char* key, size_t i, double fallback) {
    if (!fr.contains(key)) return fallback;
    const auto& v = fr[key];
    if (!v.is_number() || !std::isfinite(v.get<double>()))
      throw InputError(path.string() + ": frame " + std::to_string(i) + ": \"" + key + "\" must be a finite number");
    return v.get<double>();
  };
  std::vector<Camera> cams;
  for (size_t i = 0; i < frames.size(); ++i) {
    const auto& fr = frames[i];
    if (!fr.is_object()) throw InputError(path.string() + ": frame " + std::to_string(i) + " is not an object");
    Camera c;
    c.eye = vec3(fr, "eye", i, true, {});
    c.target = vec3(fr, "target", i, true, {});
    c.up = vec3(fr, "up", i, false, {0.0, 0.0, 1.0});
    c.fovYDeg = number(fr, "fov_deg", i, 45.0);
    c.nearPlane = number(fr, "near", i, 0.0);
    c.farPlane = number(fr, "far", i, 0.0);
    if (c.nearPlane < 0.0 || c.farPlane < 0.0 || (c.farPlane > 0.0 && c.farPlane <= c.nearPlane))
      throw InputError(path.string() + ": frame " + std::to_string(i) + ": near and far must be 0 or 0 < near < far");
    if (!(c.fovYDeg > 1.0 && c.fovYDeg < 179.0))
      throw InputError(path.string() + ": frame " + std::to_string(i) + ": fov_deg must be in (1, 179)");
    if (glm::length(c.target - c.eye) <= 0.0)
      throw InputError(path.string() + ": frame " + std::to_string(i) + ": eye equals target");
    cams.push_back(c);
  }
  return cams;
}

}  // namespace gimlod

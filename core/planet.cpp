#include "core/planet.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace gimlod {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// sin x to float precision relative to x for small x (the shader's planetSin): built-in sines
// have an absolute error of about 1e-6 on GPUs, a metre on the planet where an offset is a metre.
float smallSin(float x) {
  if (std::fabs(x) > 0.25f) return std::sin(x);
  const float x2 = x * x;
  return x * (1.0f - x2 / 6.0f * (1.0f - x2 / 20.0f * (1.0f - x2 / 42.0f * (1.0f - x2 / 72.0f))));
}

// sin(a + d) - sin a and cos(a + d) - cos a from sin a, cos a and d, without cancellation.
void angleDifferences(float sa, float ca, float d, float* dsin, float* dcos) {
  const float h = smallSin(0.5f * d), s = smallSin(d);
  const float v = 2.0f * h * h;  // 1 - cos d
  *dsin = ca * s - sa * v;
  *dcos = -(sa * s) - ca * v;
}

}  // namespace

PlanetFrame::PlanetFrame(const PlanetInfo& info, uint32_t samplesX, uint32_t samplesY)
    : info_(info), lastX_(int64_t(samplesX) - 1), lastY_(int64_t(samplesY) - 1) {
  const double tol = 1e-6 * info.dlatDeg;
  // Rows y with lat0 + y dlat <= -90 + tol, and >= 90 - tol (clamped to the lattice before any
  // conversion: a manifest may hold any step).
  const double rows = double(lastY_) + 1.0;
  southRow_ = int64_t(std::clamp(std::floor((-90.0 + tol - info.lat0Deg) / info.dlatDeg), -1.0, double(lastY_)));
  const double n = std::clamp(std::ceil((90.0 - tol - info.lat0Deg) / info.dlatDeg), 0.0, rows);
  northRow_ = n <= double(lastY_) ? int64_t(n) : INT32_MAX;
}

int PlanetFrame::pole(int64_t gy) const {
  const int64_t r = row(gy);
  return r <= southRow_ ? -1 : r >= northRow_ ? 1 : 0;
}

int64_t PlanetFrame::column(int64_t gx) const {
  const int64_t x = std::clamp<int64_t>(gx, 0, lastX_);
  return info_.wrapColumns ? x % int64_t(info_.wrapColumns) : x;
}

int64_t PlanetFrame::row(int64_t gy) const { return std::clamp<int64_t>(gy, 0, lastY_); }

double PlanetFrame::longitude(int64_t gx) const { return (info_.lon0Deg + double(column(gx)) * info_.dlonDeg) * kDeg; }

double PlanetFrame::latitude(int64_t gy) const {
  const int p = pole(gy);
  if (p != 0) return p * std::numbers::pi / 2;
  return (info_.lat0Deg + double(row(gy)) * info_.dlatDeg) * kDeg;
}

glm::dvec3 PlanetFrame::direction(int64_t gx, int64_t gy) const {
  const double lat = latitude(gy);
  if (std::fabs(lat) == std::numbers::pi / 2) return {0.0, 0.0, lat > 0 ? 1.0 : -1.0};
  const double lon = longitude(gx);
  return {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
}

glm::dvec3 PlanetFrame::position(int64_t gx, int64_t gy, double h) const {
  return (info_.radius + h) * direction(gx, gy);
}

std::array<int64_t, 2> PlanetFrame::sampleUnder(const glm::dvec3& p) const {
  const double r = glm::length(p);
  if (!(r > 0.0)) return {0, 0};
  const double lat = std::asin(std::clamp(p.z / r, -1.0, 1.0)) / kDeg;
  double lon = std::atan2(p.y, p.x) / kDeg;
  double x = (lon - info_.lon0Deg) / info_.dlonDeg;
  if (info_.wrapColumns) {
    const double w = double(info_.wrapColumns);
    x = std::fmod(std::fmod(x, w) + w, w);
  }
  const double y = (lat - info_.lat0Deg) / info_.dlatDeg;
  return {column(std::llround(std::clamp(x, 0.0, double(lastX_)))), row(std::llround(std::clamp(y, 0.0, double(lastY_))))};
}

PlanetAnchor planetAnchor(const PlanetFrame& frame, int64_t gx, int64_t gy) {
  PlanetAnchor a;
  a.gx = frame.column(gx);
  a.gy = frame.row(gy);
  const double lat = frame.latitude(a.gy), lon = frame.longitude(a.gx);
  a.position = frame.position(a.gx, a.gy, 0.0);
  a.sinLat = std::sin(lat);
  a.cosLat = std::fabs(lat) == std::numbers::pi / 2 ? 0.0 : std::cos(lat);
  a.sinLon = std::sin(lon);
  a.cosLon = std::cos(lon);
  a.latBelow = lat + std::numbers::pi / 2;
  a.latAbove = std::numbers::pi / 2 - lat;
  return a;
}

glm::vec3 planetOffset(const PlanetFrame& frame, const PlanetAnchor& a, int64_t gx, int64_t gy, float h) {
  const PlanetInfo& info = frame.info();
  const int64_t c = frame.column(gx), r = frame.row(gy);
  const int64_t w = info.wrapColumns;
  int64_t dx = c - a.gx;
  if (w > 0 && 2 * dx > w) dx -= w;
  if (w > 0 && 2 * dx < -w) dx += w;
  const float sLat = float(a.sinLat), cLat = float(a.cosLat), sLon = float(a.sinLon), cLon = float(a.cosLon);
  const bool south = frame.pole(r) < 0, north = frame.pole(r) > 0;
  float dp = float(r - a.gy) * float(info.dlatDeg * kDeg);
  if (south) dp = -float(a.latBelow);
  if (north) dp = float(a.latAbove);
  float dsinLat, dcosLat;
  angleDifferences(sLat, cLat, dp, &dsinLat, &dcosLat);
  glm::vec3 d;
  if (south || north) {
    d = {-(cLat * cLon), -(cLat * sLon), dsinLat};
  } else {
    float dsinLon, dcosLon;
    angleDifferences(sLon, cLon, float(dx) * float(info.dlonDeg * kDeg), &dsinLon, &dcosLon);
    const float cosLat = cLat + dcosLat;
    d = {cosLat * dcosLon + cLon * dcosLat, cosLat * dsinLon + sLon * dcosLat, dsinLat};
  }
  const float rho = float(info.radius) + h;
  return rho * d + h * glm::vec3(cLat * cLon, cLat * sLon, sLat);
}

}  // namespace gimlod

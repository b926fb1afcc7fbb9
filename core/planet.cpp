#include "core/planet.h"

#include <algorithm>
#include <cctype>
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

const Ellipsoid* findEllipsoid(const std::string& name) {
  for (const Ellipsoid& e : kEllipsoids) {
    const std::string n = e.name;
    if (n.size() == name.size() && std::equal(n.begin(), n.end(), name.begin(), [](unsigned char a, unsigned char b) {
          return std::toupper(a) == std::toupper(b);
        }))
      return &e;
  }
  return nullptr;
}

glm::dvec3 surfacePosition(const PlanetInfo& info, double lon, double lat, double h) {
  const double cl = std::cos(lat), sl = std::sin(lat), N = info.normalRadius(sl);
  return {(N + h) * cl * std::cos(lon), (N + h) * cl * std::sin(lon), (N * (1.0 - info.eccentricity2()) + h) * sl};
}

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
  const double e2 = info_.eccentricity2();
  if (e2 == 0.0) return (info_.radius + h) * direction(gx, gy);
  // (N + h) n - e^2 N sin(lat) z: N the radius of curvature in the prime vertical.
  const glm::dvec3 n = direction(gx, gy);
  const double N = info_.normalRadius(n.z);
  return (N + h) * n - glm::dvec3(0.0, 0.0, e2 * N * n.z);
}

std::array<int64_t, 2> PlanetFrame::sampleUnder(const glm::dvec3& p) const {
  const double r = glm::length(p);
  if (!(r > 0.0)) return {0, 0};
  const double e2 = info_.eccentricity2();
  // On an ellipsoid, the geodetic latitude of the surface point on the ray from the centre.
  const double lat =
      (e2 == 0.0 ? std::asin(std::clamp(p.z / r, -1.0, 1.0)) : std::atan2(p.z, (1.0 - e2) * std::hypot(p.x, p.y))) /
      kDeg;
  double lon = std::atan2(p.y, p.x) / kDeg;
  double x = (lon - info_.lon0Deg) / info_.dlonDeg;
  if (info_.wrapColumns) {
    const double w = double(info_.wrapColumns);
    x = std::fmod(std::fmod(x, w) + w, w);
  }
  const double y = (lat - info_.lat0Deg) / info_.dlatDeg;
  return {column(std::llround(std::clamp(x, 0.0, double(lastX_)))),
          row(std::llround(std::clamp(y, 0.0, double(lastY_))))};
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
  a.w = std::sqrt(1.0 - frame.info().eccentricity2() * a.sinLat * a.sinLat);
  a.normalRadius = frame.info().normalRadius(a.sinLat);
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
  const bool south = frame.pole(r)<0, north = frame.pole(r)> 0;
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
  if (info.flattening == 0.0) {
    const float rho = float(info.radius) + h;
    return rho * d + h * glm::vec3(cLat * cLon, cLat * sLon, sLat);
  }
  // An ellipsoid: P = (N + h) n - e^2 N sin(lat) z, so P - P_A = (N + h)(n - n_A) + (N - N_A + h) n_A
  // - e^2 (N sin(lat) - N_A sin(lat_A)) z, each difference from the sine's difference alone:
  // N - N_A = a e^2 (s - s_A)(s + s_A) / (w w_A (w + w_A)).
  const float e2 = float(info.eccentricity2()), wA = float(a.w), nA = float(a.normalRadius);
  const float s = sLat + dsinLat;
  const float ws = std::sqrt(1.0f - e2 * s * s);
  const float dN = float(info.radius) * e2 * dsinLat * (s + sLat) / (ws * wA * (ws + wA));
  const float rho = nA + dN + h;
  const glm::vec3 up(cLat * cLon, cLat * sLon, sLat);
  return rho * d + (dN + h) * up - glm::vec3(0.0f, 0.0f, e2 * (dN * s + nA * dsinLat));
}

}  // namespace gimlod

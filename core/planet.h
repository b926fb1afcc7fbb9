// Planet atlases: a longitude/latitude height field drawn on a sphere. The heights stay a scalar
// field on the DEM's lattice (the paper's spherical Earth: a radius field spherified when drawn), so
// a page holds as many bytes as on flat terrain. Sample (gx, gy) lies at longitude lon0 + gx dlon
// and latitude lat0 + gy dlat, the latitude clamped to the poles; a whole circle of longitude wraps
// (column W is column 0), so the antimeridian and the poles close without a seam of their own.
// Positions are computed relative to an anchor on the lattice near the eye (camera-relative
// precision): the same integer sample offsets and the same arithmetic give the same position in
// every node that draws a sample.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <string>

#include <glm/glm.hpp>

namespace gimlod {

inline constexpr double kEarthRadius = 6371008.8;  // metres: the IUGG mean radius

// A reference ellipsoid: its equatorial radius (metres) and flattening.
struct Ellipsoid {
  const char* name;
  double radius, flattening;
};
inline constexpr Ellipsoid kEllipsoids[] = {{"WGS84", 6378137.0, 1.0 / 298.257223563},
                                            {"GRS80", 6378137.0, 1.0 / 298.257222101}};

// The ellipsoid of kEllipsoids called `name` (case-insensitive), or null.
const Ellipsoid* findEllipsoid(const std::string& name);

// The most flattening a planet may have: Saturn's is 0.098.
inline constexpr double kMaxPlanetFlattening = 0.1;

// What a planet atlas's manifest records ("planet").
struct PlanetInfo {
  bool present = false;
  // The surface heights are measured from: a sphere of `radius` metres (flattening 0), or an
  // ellipsoid of revolution of equatorial radius `radius` and this flattening, heights along its
  // normal (geodetic latitudes, as GPS and WGS84 DEMs give them).
  double radius = kEarthRadius;
  double flattening = 0.0;
  double eccentricity2() const { return flattening * (2.0 - flattening); }
  // The radius of curvature in the prime vertical at a latitude of sine s: N = radius / sqrt(1 -
  // e^2 s^2) (the radius itself on a sphere).
  double normalRadius(double s) const { return radius / std::sqrt(1.0 - eccentricity2() * s * s); }
  double polarRadius() const { return radius * (1.0 - flattening); }
  double lon0Deg = 0.0, lat0Deg = 0.0;  // sample (0, 0): longitude and latitude, degrees
  double dlonDeg = 1.0, dlatDeg = 1.0;  // degrees between samples (both > 0; rows go north)
  // W > 0: the samples circle the planet, W columns a turn, and column W is column 0 again
  // (the DEM holds W + 1 columns, the last a copy of the first). 0: a regional DEM.
  uint32_t wrapColumns = 0;
};

// The planet-centred position of longitude lon and latitude lat (radians; geodetic on an ellipsoid)
// at height h above the surface, along its normal.
glm::dvec3 surfacePosition(const PlanetInfo& info, double lon, double lat, double h);

// The lattice's place on the sphere: samples to directions and positions.
class PlanetFrame {
 public:
  PlanetFrame() = default;
  // samplesX, samplesY: the DEM's lattice (AtlasManifest::samplesX/Y). Samples past the last are
  // clamped to it, as the charts' padding is.
  PlanetFrame(const PlanetInfo& info, uint32_t samplesX, uint32_t samplesY);
  const PlanetInfo& info() const { return info_; }
  // The column that sample column gx is drawn as: clamped to the lattice, then wrapped.
  int64_t column(int64_t gx) const;
  int64_t row(int64_t gy) const;
  double longitude(int64_t gx) const;  // radians
  double latitude(int64_t gy) const;   // radians, within [-pi/2, pi/2]; exactly +-pi/2 at a pole
  // -1 (+1): row gy lies on the south (north) pole (its latitude within a millionth of a row of
  // it, or past it); 0: neither.
  int pole(int64_t gy) const;
  // The last row on the south pole (-1: none) and the first on the north pole (INT32_MAX: none).
  int64_t southPoleRow() const { return southRow_; }
  int64_t northPoleRow() const { return northRow_; }
  // The surface's normal (up) at sample (gx, gy): on an ellipsoid, geodetic.
  glm::dvec3 direction(int64_t gx, int64_t gy) const;
  // Planet-centred position (x towards longitude 0 on the equator, z north) of sample (gx, gy) at
  // height h.
  glm::dvec3 position(int64_t gx, int64_t gy, double h) const;
  // The lattice sample under a point (the nearest to its longitude and latitude; on an ellipsoid,
  // the geodetic latitude of the surface point under it).
  std::array<int64_t, 2> sampleUnder(const glm::dvec3& p) const;

 private:
  PlanetInfo info_;
  int64_t lastX_ = 0, lastY_ = 0;
  int64_t southRow_ = -1, northRow_ = INT32_MAX;
};

// The point positions are computed from in a frame: a lattice sample at height 0. The vertex
// shader gets its sines and cosines and the range of latitude offsets (to the poles), and computes
// a sample's position minus the anchor's from the integer offsets alone (planetOffset).
struct PlanetAnchor {
  int64_t gx = 0, gy = 0;
  glm::dvec3 position{0.0};  // planet-centred, metres
  double sinLat = 0, cosLat = 1, sinLon = 0, cosLon = 1;
  double latBelow = 0, latAbove = 0;  // radians from the anchor's latitude to the south and north poles
  // On an ellipsoid: its radius of curvature in the prime vertical N = a / w, w = sqrt(1 - e^2
  // sin^2 lat), and w (a sphere: N = radius, w = 1).
  double normalRadius = 0, w = 1;
};
PlanetAnchor planetAnchor(const PlanetFrame& frame, int64_t gx, int64_t gy);

// A sample's position minus the anchor's, as the vertex shader computes it in float (the same
// operations, for tests and for CPU-side meshes): exact to about float precision times the distance
// from the anchor, whatever the planet's size.
glm::vec3 planetOffset(const PlanetFrame& frame, const PlanetAnchor& anchor, int64_t gx, int64_t gy, float h);

}  // namespace gimlod

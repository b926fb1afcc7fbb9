// Cameras, frusta and camera paths (orbit or JSON). Pure C++ (glm for math), no GL.
#pragma once

#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace gimlod {

struct Camera {
  glm::dvec3 eye{0.0, 0.0, 1.0};
  glm::dvec3 target{0.0};
  glm::dvec3 up{0.0, 0.0, 1.0};
  double fovYDeg = 45.0;
  double nearPlane = 1.0;  // 0: choose from the scene (see fitClipPlanes)
  double farPlane = 0.0;   // 0: choose from the scene
};

// Six planes (a, b, c, d), inside where a x + b y + c z + d >= 0.
struct Frustum {
  std::array<glm::dvec4, 6> planes;
  // Planets (occluderRadius > 0): a box behind the horizon of the sphere of occluderRadius round
  // the origin, seen from horizonEye, is outside too: every corner beyond the horizon's plane and
  // inside the sphere's shadow cone, a convex part of what the sphere hides. No culling while the
  // eye is inside the sphere.
  double occluderRadius = 0.0;
  glm::dvec3 horizonEye{0.0};
  void setHorizon(const glm::dvec3& eye, double radius);
  // True when the box [lo, hi] may intersect the frustum (and lies not wholly behind the horizon).
  bool intersects(const glm::dvec3& lo, const glm::dvec3& hi) const;
  // 0: the box is outside (exactly when intersects is false), 2: entirely inside every plane (and
  // in front of the horizon's plane), 1: otherwise. A box inside a box classified 0 or 2 gets the
  // same class.
  int classify(const glm::dvec3& lo, const glm::dvec3& hi) const;
  // The horizon's part of classify: 0 hidden, 2 wholly in front of the horizon's plane, 1 otherwise.
  int horizonClass(const glm::dvec3& lo, const glm::dvec3& hi) const;
};

glm::dmat4 viewMatrix(const Camera& c);
glm::dmat4 projectionMatrix(const Camera& c, double aspect);
// The same with the depth reversed (1 at the near plane, 0 at infinity: no far plane) for a
// [0, 1] clip depth (glClipControl): a float depth buffer then resolves centimetres near the eye
// and the planet's far side alike.
glm::dmat4 reversedProjectionMatrix(const Camera& c, double aspect);
// The near plane of planet views: reversed depth keeps it small at every height.
inline constexpr double kPlanetNearPlane = 0.05;
Frustum frustumFromMatrix(const glm::dmat4& viewProj);

// Pixels covered by one world unit seen face-on at unit distance: height / (2 tan(fovy / 2)).
double pixelsPerRadian(const Camera& c, uint32_t viewportHeight);

// Sets near/far (where 0) so the box [lo, hi] fits: far beyond the farthest corner, near a small
// fraction of the distance to the box (bounded below by 1e-4 of the diagonal).
void fitClipPlanes(Camera& c, const glm::dvec3& lo, const glm::dvec3& hi);

// N frames circling the box centre at distance = fraction * diagonal, elevation in degrees.
std::vector<Camera> orbitPath(const glm::dvec3& lo, const glm::dvec3& hi, uint32_t frames, double distanceFraction,
                              double elevationDeg, double fovYDeg = 45.0);

// N frames flying down onto a terrain (z up): from the box's south-west, a diagonal above its top,
// towards its centre, the height above the top falling geometrically to 1/500 of the diagonal,
// looking ahead and down at the mid height: the view goes from the whole atlas to its finest
// nodes.
std::vector<Camera> descentPath(const glm::dvec3& lo, const glm::dvec3& hi, uint32_t frames, double fovYDeg = 45.0);

// The six axis views of the box: from +x, -x, +y, -y, +z and -z, looking at its centre from the
// distance at which its bounding sphere fills the vertical field of view (up: z, or y from +-z).
// names, if given, receives "+x", "-x", ... in the same order.
std::vector<Camera> axisViews(const glm::dvec3& lo, const glm::dvec3& hi, double fovYDeg = 45.0,
                              std::vector<std::string>* names = nullptr);

// Reads {"frames": [{"eye": [x,y,z], "target": [...], "up": [...], "fov_deg": 45}, ...]} or a bare
// list of such frames. Throws InputError naming the file on malformed input.
std::vector<Camera> readCameraPath(const std::filesystem::path& path);

}  // namespace gimlod

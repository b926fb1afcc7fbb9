// Interactive cameras for the viewer: an orbit camera (rotate about a centre, pan, dolly) and a
// fly camera (move along the view, look around), both framed on a bounding box with a chosen up
// axis, with clip planes that follow the distance to the data. Also the camera-path writer that
// readCameraPath reads back, for recorded paths. Pure C++ (glm), no GL and no window system, so
// it is tested on its own.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "hierarchy/hierarchy.h"
#include "runtime/camera.h"

namespace gimlod {

// An up axis: +x, -x, +y, -y, +z or -z.
struct UpAxis {
  int axis = 2;     // 0, 1, 2
  double sign = 1;  // +1 or -1
  glm::dvec3 vector() const;
};

// "x", "+y", "-z", ...; nullopt otherwise.
std::optional<UpAxis> parseUpAxis(const std::string& text);

class CameraControl {
 public:
  enum class Mode { kOrbit, kFly };

  // Framed on the box [lo, hi] (see frame).
  CameraControl(const glm::dvec3& lo, const glm::dvec3& hi, UpAxis up, double fovYDeg = 45.0);

  // Back to the starting view: orbit mode, looking at the box centre from 35 degrees above the
  // horizon (about the up axis; from +z when y is up, from -y when z is up), at the distance
  // where the box's bounding sphere fills the view.
  void frame();
  Mode mode() const { return mode_; }
  // Switches mode keeping the current view (the orbit centre is put in front of the eye at the
  // current distance).
  void setMode(Mode m);

  // Orbit: yaw and pitch by a drag of (dx, dy) pixels in a viewport `height` pixels tall (a drag
  // across the viewport height turns by 180 degrees). In fly mode the same turns the view about
  // the eye (mouse look).
  void rotate(double dxPx, double dyPx, double heightPx);
  // Orbit: moves the centre (and eye) across the view by (dx, dy) pixels, so the point under the
  // cursor at the centre's depth follows it. Fly: the same at the flying speed's scale.
  void pan(double dxPx, double dyPx, double heightPx);
  // Orbit: distance multiplied by 0.85^steps (scroll steps; negative steps move out). Fly:
  // speed changes by the same factor, inverted.
  void zoom(double steps);
  // Fly: moves by (right, up, forward) units of speed * seconds (the keys held). Orbit: forward
  // dollies, right and up pan.
  void move(const glm::dvec3& rightUpForward, double seconds);

  // The eye's distance to the surface (the viewer measures it with distanceToSurface whenever the
  // eye moves: the height above a terrain, the gap to a scan); negative: unknown, the distance to
  // the whole box is used instead.
  void setSurfaceDistance(double d) { surfaceDistance_ = d; }
  // The flying speed in world units per second: the eye's distance to the surface (or to the box),
  // at least 0.1% of the diagonal (1% without a surface distance), times the user's speed factor.
  double flySpeed() const;

  // The camera for this view: near and far follow the distance to the box (near a small fraction
  // of it, so close-ups do not clip; far beyond the farthest corner), and the near plane comes in
  // to half the surface distance when that is closer (flying low inside the box).
  Camera camera() const;
  // Takes a camera's view (eye, target, up, fov) in orbit mode; the orbit centre is its target.
  void setCamera(const Camera& c);

  const glm::dvec3& eye() const { return eye_; }
  double distance() const { return distance_; }

  // Planets: flying, up is away from the planet's centre (the origin), and the heading and pitch are
  // the local ones (from east, north and up under the eye), so the horizon stays level as the eye
  // moves round the planet; orbiting keeps the up axis.
  void setRadialUp(bool on) { radialUp_ = on; }
  // The camera's up: the up axis, or away from the planet's centre when flying over one.
  glm::dvec3 upVector() const;

 private:
  // The horizontal axes (a, b) and the up of the current frame, a x b = up.
  void basis(glm::dvec3* a, glm::dvec3* b, glm::dvec3* up) const;
  // Sets yaw and pitch to look along f in the current frame.
  void lookAlong(const glm::dvec3& f);
  glm::dvec3 forward() const;
  void updateEye();  // orbit: eye from centre, distance, yaw, pitch
  glm::dvec3 lo_, hi_;
  UpAxis up_;
  double fov_;
  Mode mode_ = Mode::kOrbit;
  glm::dvec3 centre_{0.0}, eye_{0.0};
  double distance_ = 1.0;
  double yaw_ = 0.0, pitch_ = 0.0;  // radians; pitch in (-pi/2, pi/2) above the horizon
  double speedFactor_ = 1.0;
  double surfaceDistance_ = -1.0;
  bool radialUp_ = false;
};

// The distance from p to the nearest leaf node's bounding box (0 inside one): the height above a
// terrain's surface, the gap to a scan's, to within the leaves' size. Branch and bound over the
// hierarchy's boxes.
double distanceToSurface(const Hierarchy& h, const glm::dvec3& p);

// Writes cameras as {"frames": [{"eye", "target", "up", "fov_deg"}, ...]}, the format of
// readCameraPath, atomically (temporary file, then rename). Throws InputError naming the file.
void writeCameraPath(const std::filesystem::path& path, const std::vector<Camera>& cameras);

}  // namespace gimlod

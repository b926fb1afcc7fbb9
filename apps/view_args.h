// View options shared by `gimlod render` and `gimlod bench`: an orbit or a JSON camera path, and
// the frame size.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/overlay.h"

namespace gimlod {

struct CameraArgs {
  std::string path;      // camera path JSON; empty: orbit
  uint32_t orbit = 0;    // orbit frames
  uint32_t descent = 0;  // fly-down frames (descentPath)
  double distance = 0.9, elevation = 35.0, fov = 45.0;
  // Top groups above the charts at most (openAtlas, hierarchy/root_groups.h); 0: none.
  uint32_t maxRoots = kDefaultMaxRoots;
};

// Registers --max-roots on cmd.
inline void addMaxRootsOption(CLI::App* cmd, uint32_t& maxRoots) {
  cmd->add_option("--max-roots", maxRoots,
                  "Gather the chart roots into groups, and those into groups, until at most this many top groups "
                  "remain: a closed group is one node of the budget; 0: no groups (every chart root a root)")
      ->capture_default_str();
}

// Registers --path, --orbit, --distance, --elevation and --fov on cmd.
inline void addCameraOptions(CLI::App* cmd, CameraArgs& a) {
  cmd->add_option("--path", a.path, "Camera path JSON: frames of eye, target, up, fov_deg");
  cmd->add_option("--orbit", a.orbit, "Frames of an orbit around the bounding-box centre");
  cmd->add_option("--descent", a.descent,
                  "Frames of a fly-down onto a terrain: from a diagonal above it to 1/500 of it, towards the centre");
  cmd->add_option("--distance", a.distance, "Orbit distance as a fraction of the bounding-box diagonal")
      ->capture_default_str();
  cmd->add_option("--elevation", a.elevation, "Orbit elevation in degrees")->capture_default_str();
  cmd->add_option("--fov", a.fov, "Vertical field of view for --orbit, degrees")->capture_default_str();
  addMaxRootsOption(cmd, a.maxRoots);
}

// Throws InputError for impossible camera options.
inline void validateCameraArgs(const CameraArgs& a) {
  if (!(a.distance > 0.0) || !std::isfinite(a.distance)) throw InputError("--distance must be > 0");
  if (!(a.fov > 1.0 && a.fov < 179.0)) throw InputError("--fov must be in (1, 179) degrees");
  if ((a.orbit > 0) + (a.descent > 0) + !a.path.empty() != 1)
    throw InputError("give one of --orbit N, --descent N and --path FILE.json");
  if (a.orbit > 100000) throw InputError("--orbit must be at most 100000 frames");
  if (a.descent > 100000) throw InputError("--descent must be at most 100000 frames");
}

// The cameras: the JSON path (clip planes fitted to the atlas) if given, else the orbit or the
// descent.
inline std::vector<Camera> loadCameras(const CameraArgs& a, const AtlasView& atlas) {
  if (a.descent > 0) return descentPath(atlas.lo, atlas.hi, a.descent, a.fov);
  if (a.path.empty()) return orbitPath(atlas.lo, atlas.hi, a.orbit, a.distance, a.elevation, a.fov);
  std::vector<Camera> cams = readCameraPath(a.path);
  for (Camera& c : cams) fitClipPlanes(c, atlas.lo, atlas.hi);
  return cams;
}

// The adaptation and drawing options `render` and `view` share; throws InputError naming the
// option that is out of range or that conflicts with another.
inline void validateViewOptions(double tolerance, double texelRatio, uint32_t uploadsPerFrame, bool budgetGiven,
                                bool topDown, double frameMs) {
  if (!(tolerance > 0.0) || !std::isfinite(tolerance)) throw InputError("--tolerance must be > 0 pixels");
  if (uploadsPerFrame == 0) throw InputError("--uploads-per-frame must be at least 1");
  if (!(texelRatio >= 0.0) || !std::isfinite(texelRatio) || texelRatio > 64.0)
    throw InputError("--texel-ratio must be in [0, 64] texels per pixel (0: page resolution)");
  if (budgetGiven && topDown) throw InputError("--top-down applies to error mode; --triangles selects the quad queue");
  if (frameMs < 0.0 || !std::isfinite(frameMs) || frameMs > 10000.0)
    throw InputError("--frame-ms must be in (0, 10000] milliseconds");
  if (frameMs > 0.0 && topDown) throw InputError("--frame-ms sets a triangle budget; --top-down is for error mode");
}

// Registers --geomorph on cmd (SceneOptions::geomorph).
inline void addGeomorphOption(CLI::App* cmd, double& range) {
  cmd->add_option("--geomorph", range,
                  "Geomorphs: a node's inner vertices move onto its next coarser resolution as that resolution's "
                  "error comes within (1 + RANGE) times the tolerance, so resolution switches do not pop; 0: off")
      ->capture_default_str();
}

inline void addMsaaOption(CLI::App* cmd, uint32_t& samples) {
  cmd->add_option("--msaa", samples,
                  "Samples per pixel (multisampling, shaded per sample, so the terrain's edge is smoothed too); "
                  "1: none")
      ->check(CLI::Range(1u, 32u))
      ->capture_default_str();
}

inline void validateGeomorph(double range) {
  if (!(range >= 0.0) || !std::isfinite(range) || range > 8.0) throw InputError("--geomorph must be in [0, 8]");
}

// Parses --overlay; throws InputError naming the option.
inline OverlayMode parseOverlayOption(const std::string& name) {
  const std::optional<OverlayMode> m = parseOverlayMode(name);
  if (!m) throw InputError("--overlay '" + name + "': expected none, chart, level, res or error");
  return *m;
}

// Parses --background R,G,B (in [0, 1], or [0, 255] when any is above 1); throws InputError.
inline std::array<float, 3> parseBackground(const std::string& s) {
  std::array<float, 3> c{};
  char extra;
  if (std::sscanf(s.c_str(), "%f,%f,%f%c", &c[0], &c[1], &c[2], &extra) != 3)
    throw InputError("--background '" + s + "' must be R,G,B");
  for (float& v : c) {
    if (!std::isfinite(v) || v < 0.f) throw InputError("--background '" + s + "' must be R,G,B in [0,1] or [0,255]");
  }
  if (c[0] > 1.f || c[1] > 1.f || c[2] > 1.f)
    for (float& v : c) v = std::min(v, 255.f) / 255.f;
  return c;
}

// Parses --size WxH (8 <= W, H <= 16384); throws InputError otherwise.
inline void parseFrameSize(const std::string& size, uint32_t* w, uint32_t* h) {
  char extra;
  if (std::sscanf(size.c_str(), "%ux%u%c", w, h, &extra) != 2 || *w < 8 || *h < 8 || *w > 16384 || *h > 16384)
    throw InputError("--size '" + size + "' must be WxH with 8 <= W, H <= 16384");
}

}  // namespace gimlod

// `gimlod view`: a window (GLFW, OpenGL 4.3 core) onto an atlas, drawn by the same scene as
// `render`, with an orbit and a fly camera, live adaptation controls and overlays in a Dear ImGui
// panel, a frozen cut to fly around, live graphs, camera paths recorded and played back,
// screenshots, and scripted runs for tests and documentation images.
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "apps/streaming_args.h"
#include "hierarchy/root_groups.h"

namespace gimlod {

struct ViewArgs {
  std::string atlas;
  std::string size = "1280x720";
  std::string background = "0.53,0.70,0.92";
  std::string up = "auto";  // auto: z for terrain, y for meshes
  std::string path;         // camera path to play (JSON, as render and bench read)
  bool loop = false;        // play the path again and again
  std::string record;       // where R writes the recorded path
  std::string screenshot;   // scripted: the last frame's PNG; interactive: where P writes
  std::string stats;        // CSV, one row per frame (as render's stats.csv)
  uint32_t frames = 0;      // scripted: frames to draw along the path (0: the path's length)
  uint32_t exitAfter = 0;   // exit after this many frames (0: when the window closes)
  bool hideUi = false;      // no panel (and none in screenshots)
  double tolerance = 1.0;   // px
  uint64_t triangles = 0;   // > 0: triangle-budget mode
  uint32_t maxNodes = 2048;
  uint32_t maxRoots = kDefaultMaxRoots;  // top groups above the charts at most (openAtlas); 0: none
  double texelRatio = 1.0;
  double geomorph = 0.0;    // SceneOptions::geomorph
  uint32_t msaa = 1;        // SceneOptions::samples
  StreamingArgs streaming;  // the loader and the caches' byte budgets
  bool topDown = false;
  std::string overlay = "none";  // none, chart, level, res, error
  bool wireframe = false;
  double fov = 45.0;
  double frameMs = 0.0;  // > 0: the frame-time controller holds this (budget mode)
};

// Registers the `view` subcommand on app, parsing into args (which must outlive app's parse).
CLI::App* addViewCommand(CLI::App& app, ViewArgs& args);

// Opens the window and runs until it closes (or --exit-after / the scripted frames). Throws
// InputError on invalid options or inputs. Returns the process exit code.
int runView(const ViewArgs& args);

}  // namespace gimlod

// Popping along a slow path, with geomorphs and without: for each frame, the largest per-pixel
// change that the new cut makes at the same camera. Frame k+1 is drawn with its own cut and again
// with frame k's cut frozen (nodes, resolutions and morph factors as they were); their difference
// is what the cut's change did to the picture, the camera's motion taken out. Prints, per setting,
// the largest and the mean of the per-frame largest change (0-255 per channel), the 99th
// percentile, and the pixels that changed by more than 16.
//
// Usage: bench_popping ATLAS_DIR [--frames 240] [--distance 0.6] [--size 320x240] [--tolerance 1]
//        [--max-nodes 2000] [--geomorph 0,0.5] [--attribute-blend 1] [--msaa 1] [--cull] [--descent] (a fly-down on a
//        terrain instead of an orbit spiralling in); --attribute-blend 0,1 compares the normals and
//        colours switching between mips with their blending between them (CutNode::texBlend);
//        --msaa 4 draws 4 samples per pixel, shaded per sample, so that a silhouette moving part of
//        a pixel changes it part way rather than all (without it, the largest change is a pixel
//        going from sky to ground whatever moved it)
// Reads a built atlas; renders headless (EGL).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "bench/guarded_main.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"

using namespace gimlod;

namespace {

struct Args {
  std::string atlas, size = "320x240";
  uint32_t frames = 240, maxNodes = 2000;
  double distance = 0.6, tolerance = 1.0;
  std::vector<double> geomorphs{0.0, 0.5};
  bool descent = false;
  std::vector<int> blends{1};  // attribute blending (CutNode::texBlend) on, off or both
  uint32_t samples = 1;        // multisampling: a silhouette that moves part of a pixel changes it part way
  // Frustum culling: off by default, so frame k's cut covers what frame k+1 sees (with it, the
  // ground newly in view at the picture's edges is sky in the frozen cut's picture: not a pop).
  bool cull = false;
};

// The largest per-channel difference of two RGBA8 pictures, and the pixels differing by more than 16.
std::pair<int, uint64_t> difference(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  int largest = 0;
  uint64_t over = 0;
  for (size_t p = 0; p + 3 < a.size() && p + 3 < b.size(); p += 4) {
    int d = 0;
    for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(int(a[p + c]) - int(b[p + c])));
    largest = std::max(largest, d);
    over += d > 16;
  }
  return {largest, over};
}

int run(int argc, char** argv) {
  Args a;
  CLI::App app{"Popping along a slow path, with geomorphs and without"};
  app.add_option("atlas", a.atlas, "built atlas directory")->required();
  app.add_option("--frames", a.frames, "frames of the path")->check(CLI::Range(2u, 100000u));
  app.add_option("--distance", a.distance, "orbit: the closest distance, a fraction of the diagonal");
  app.add_option("--size", a.size, "frame WxH");
  app.add_option("--tolerance", a.tolerance, "screen-space tolerance, px")->check(CLI::PositiveNumber);
  app.add_option("--max-nodes", a.maxNodes, "node budget");
  app.add_option("--geomorph", a.geomorphs, "geomorph ranges to compare (0: off)")->delimiter(',');
  app.add_option("--attribute-blend", a.blends, "attribute blending between mips to compare (1 on, 0 off)")
      ->delimiter(',')
      ->check(CLI::Range(0, 1));
  app.add_option("--msaa", a.samples, "samples per pixel")->check(CLI::Range(1u, 32u));
  app.add_flag("--cull", a.cull, "cull nodes outside the view (the frozen cut then lacks what comes into view)");
  app.add_flag("--descent", a.descent, "a fly-down onto a terrain instead of an orbit");
  CLI11_PARSE(app, argc, argv);
  uint32_t w = 0, h = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &w, &h) != 2 || w < 8 || h < 8) {
    std::fprintf(stderr, "bench_popping: bad size '%s'\n", a.size.c_str());
    return 2;
  }
  const AtlasView atlas = openAtlas(a.atlas);
  // Slow: an orbit spiralling in from 1.5 to `distance` diagonals over a quarter turn, or a fly-down.
  std::vector<Camera> path;
  if (a.descent) {
    path = descentPath(atlas.lo, atlas.hi, a.frames);
  } else {
    for (uint32_t i = 0; i < a.frames; ++i) {
      const double t = double(i) / double(a.frames - 1);
      path.push_back(orbitPath(atlas.lo, atlas.hi, 4 * a.frames, 1.5 + (a.distance - 1.5) * t, 30.0)[i]);
    }
  }
  auto context = gl::EglContext::create();
  std::printf("%s: %zu frames of a slow %s, %ux%u, tolerance %.2f px, %u nodes at most, on %s\n", a.atlas.c_str(),
              path.size(), a.descent ? "fly-down" : "spiral", w, h, a.tolerance, a.maxNodes,
              context->renderer().c_str());
  std::printf("%9s %6s %9s %9s %9s %12s %9s\n", "geomorph", "blend", "max", "mean", "p99", "pixels>16", "switches");
  std::vector<std::pair<int, double>> settings;  // (attribute blend, geomorph range)
  for (const int blend : a.blends)
    for (const double g : a.geomorphs) settings.emplace_back(blend, g);
  for (const auto& [blend, g] : settings) {
    gl::SceneOptions so;
    so.blendAttributes = blend != 0;
    so.samples = a.samples;
    so.width = w;
    so.height = h;
    so.geomorph = g;
    so.minNodeRoom = a.maxNodes;
    gl::AtlasScene scene(atlas, so);
    AdaptOptions o;
    o.tolerancePx = a.tolerance;
    o.maxNodes = a.maxNodes;
    o.frustumCull = a.cull;
    std::vector<int> largest;
    uint64_t over = 0, switches = 0;
    Cut previous = scene.renderFrame(path[0], o).cut;
    for (size_t k = 1; k < path.size(); ++k) {
      const gl::FrameResult f = scene.renderFrame(path[k], o);
      const std::vector<uint8_t> now = scene.renderer().readPixels();
      for (const CutNode& n : f.cut.nodes) {
        const int32_t at = previous.find(n.id);
        switches += at < 0 || previous.nodes[size_t(at)].resLog2 != n.resLog2;
      }
      scene.drawCut(path[k], previous);
      const auto [d, o16] = difference(now, scene.renderer().readPixels());
      largest.push_back(d);
      over += o16;
      previous = f.cut;
    }
    std::vector<int> sorted = largest;
    std::sort(sorted.begin(), sorted.end());
    double mean = 0.0;
    for (int d : largest) mean += d;
    mean /= double(largest.size());
    std::printf("%9.2f %6d %9d %9.2f %9d %12llu %9llu\n", g, blend, sorted.back(), mean,
                sorted[std::min(sorted.size() - 1, size_t(std::ceil(0.99 * double(sorted.size()))) - 1)],
                (unsigned long long)over, (unsigned long long)switches);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return guardedMain(argc, argv, run); }

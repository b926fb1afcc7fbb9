// Render throughput: triangles per second of the terrain renderer along an orbit, against the
// same context drawing one static indexed mesh with the same triangle count, in the same run.
// Usage: bench_render [DEM] [WxH] [tolerance_px]
#include <cstdio>
#include <filesystem>

#include "apps/pipeline.h"
#include "runtime/atlas_view.h"
#include "runtime/gl/egl_context.h"
#include "runtime/gl/terrain_scene.h"

using namespace gimlod;

int main(int argc, char** argv) {
  const std::filesystem::path input = argc > 1 ? argv[1] : "data/terrain/mt_rainier_90m.tif";
  uint32_t w = 640, h = 480;
  if (argc > 2) std::sscanf(argv[2], "%ux%u", &w, &h);
  const double tol = argc > 3 ? std::atof(argv[3]) : 1.0;
  const auto tmp = std::filesystem::temp_directory_path() / "gimlod_bench_render.atlas";
  BuildOptions bo;
  bo.input = input;
  bo.output = tmp;
  buildAtlas(bo);
  const AtlasView atlas = openAtlas(tmp);
  auto ctx = gl::EglContext::create();
  gl::SceneOptions so;
  so.width = w;
  so.height = h;
  gl::TerrainScene scene(atlas, so);
  const auto path = orbitPath(atlas.lo, atlas.hi, 24, 0.7, 30.0);
  AdaptOptions ao;
  ao.tolerancePx = tol;
  ao.maxNodes = 3000;
  // Warm-up: pages resident, shaders compiled.
  for (const Camera& c : path) scene.renderFrame(c, ao);
  double ms = 0.0;
  uint64_t tris = 0;
  for (const Camera& c : path) {
    const gl::FrameResult f = scene.renderFrame(c, ao);
    ms += f.draw.drawMs;
    tris += f.draw.triangles;
  }
  const uint64_t meanTris = tris / path.size();
  uint64_t staticTris = 0;
  const double staticMs = scene.renderer().drawStaticMeshMs(meanTris, uint32_t(path.size()), &staticTris);
  const double engine = double(tris) / ms * 1e-3, baseline = double(staticTris) / staticMs * 1e-3;
  std::printf("device: %s (%s)\n", ctx->renderer().c_str(), ctx->version().c_str());
  std::printf("frames %zu at %ux%u, tolerance %.2f px, mean %.0f triangles/frame\n", path.size(), w, h, tol,
              double(meanTris));
  std::printf("engine: %.2f ms/frame, %.2f M triangles/s\n", ms / path.size(), engine);
  std::printf("static mesh (%llu triangles): %.2f ms/frame, %.2f M triangles/s\n",
              (unsigned long long)staticTris, staticMs, baseline);
  std::printf("engine / static = %.2f\n", engine / baseline);
  std::filesystem::remove_all(tmp);
  return 0;
}

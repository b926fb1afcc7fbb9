// Render throughput: triangles per second of the terrain renderer along an orbit, against the
// same context drawing one static indexed mesh with the same triangle count, in the same run:
// (a) the same DEM as a regular grid mesh, same cameras, same fragment shader (equal work but
// for the vertex path: texture fetch, stitching, multi-draw); (b) a plain flat-shaded grid.
// Usage: bench_render [DEM] [WxH] [tolerance_px]
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "bench/guarded_main.h"
#include "pipeline/build.h"
#include "atlas/terrain/dem.h"
#include "bench/gl/baseline_draws.h"
#include "runtime/atlas_view.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"

using namespace gimlod;

namespace {

int run(int argc, char** argv) {
  const std::filesystem::path input = argc > 1 ? argv[1] : "data/terrain/mt_rainier_90m.tif";
  uint32_t w = 640, h = 480;
  if (argc > 2) std::sscanf(argv[2], "%ux%u", &w, &h);
  const double tol = argc > 3 ? std::atof(argv[3]) : 1.0;
  const auto tmp = std::filesystem::temp_directory_path() / "gimlod_bench_render.atlas";
  TerrainBuildOptions bo;
  bo.input = input;
  bo.output = tmp;
  buildAtlas(bo);
  const AtlasView atlas = openAtlas(tmp);
  auto ctx = gl::EglContext::create();
  gl::SceneOptions so;
  so.width = w;
  so.height = h;
  gl::AtlasScene scene(atlas, so);
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

  // (a) The DEM resampled to a regular grid of about meanTris triangles.
  const DemRaster dem = loadDem(input);
  const uint32_t side = std::max<uint32_t>(1, uint32_t(std::lround(std::sqrt(double(meanTris) / 2.0))));
  std::vector<glm::vec3> positions;
  for (uint32_t j = 0; j <= side; ++j)
    for (uint32_t i = 0; i <= side; ++i) {
      const double gx = double(i) / side * (dem.width - 1), gy = double(j) / side * (dem.height - 1);
      const uint32_t x = std::min(uint32_t(gx), dem.width - 2), y = std::min(uint32_t(gy), dem.height - 2);
      const double fx = gx - x, fy = gy - y;
      auto at = [&](uint32_t a, uint32_t b) { return double(dem.heights[size_t(b) * dem.width + a]); };
      const double z =
          (1 - fy) * ((1 - fx) * at(x, y) + fx * at(x + 1, y)) + fy * ((1 - fx) * at(x, y + 1) + fx * at(x + 1, y + 1));
      positions.emplace_back(float(gx * dem.spacing[0]), float(gy * dem.spacing[1]), float(z));
    }
  std::vector<uint32_t> indices;
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      const uint32_t a = j * (side + 1) + i, b = a + 1, c = b + side + 1, d = a + side + 1;
      indices.insert(indices.end(), {a, b, c, a, c, d});
    }
  bench::BaselineDraws baselines(scene.renderer());
  double meshMs = 0.0;
  for (const Camera& c : path)
    meshMs += baselines.drawMeshMs(positions, indices, glm::mat4(scene.viewProjection(c)), glm::vec3(c.eye), 1);
  const uint64_t meshTris = uint64_t(indices.size() / 3);

  // (b) A plain grid with a trivial shader.
  uint64_t staticTris = 0;
  const double staticMs = baselines.drawStaticMeshMs(meanTris, uint32_t(path.size()), &staticTris);
  const double engine = double(tris) / ms * 1e-3;
  const double same = double(meshTris) * path.size() / meshMs * 1e-3;
  const double plain = double(staticTris) / staticMs * 1e-3;
  std::printf("device: %s (%s)\n", ctx->renderer().c_str(), ctx->version().c_str());
  std::printf("frames %zu at %ux%u, tolerance %.2f px, mean %.0f triangles/frame\n", path.size(), w, h, tol,
              double(meanTris));
  std::printf("engine:                          %7.2f ms/frame, %7.2f M triangles/s\n", ms / path.size(), engine);
  std::printf("(a) DEM grid mesh, same shading: %7.2f ms/frame, %7.2f M triangles/s (%llu triangles)\n",
              meshMs / path.size(), same, (unsigned long long)meshTris);
  std::printf("(b) plain flat-shaded grid:      %7.2f ms/frame, %7.2f M triangles/s (%llu triangles)\n", staticMs,
              plain, (unsigned long long)staticTris);
  std::printf("engine / (a) = %.2f, engine / (b) = %.2f\n", engine / same, engine / plain);
  std::filesystem::remove_all(tmp);
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return guardedMain(argc, argv, run); }

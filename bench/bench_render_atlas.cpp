// Render throughput from an already-built atlas (no GDAL, so it runs on a bare GPU machine):
// triangles per second of the terrain renderer along an orbit, against the same context drawing
// one static indexed mesh with the same triangle count, in the same run:
// (a) the atlas's level-0 heights resampled to a regular grid mesh, same cameras, same fragment
//     shader (equal work but for the vertex path: texture fetch, stitching, multi-draw);
// (b) a plain flat-shaded grid (BaselineDraws::drawStaticMeshMs).
//
// Usage: bench_render_atlas ATLAS_DIR [WxH] [tolerance_px] [max_nodes] [frames]
//        bench_render_atlas ATLAS_DIR --sweep [max_nodes] [frames] [tolerances]
// --sweep runs, in one context, 640x480 at the first tolerance, 1920x1080 at each, and 3840x2160
// at the last (tolerances: comma-separated px, default 1,0.5,0.25), then prints a summary table.
// Defaults: 640x480, 1 px, 3000 nodes, 24 orbit frames. The page pool is made to hold cuts of the
// node budget (SceneOptions::minNodeRoom), in as many texture arrays as it takes.
//
// Times, all per frame, means over the orbit after one warm-up orbit:
//  adapt, stitch, upload: FrameResult's CPU wall times (upload = page-pool work; 0 once warm);
//  draw (wall): DrawStats::drawMs, CPU wall time of AtlasRenderer::draw, i.e. node/stitch
//    buffer packing and upload, one multi-draw-indirect, and glFinish;
//  GPU: a GL_TIME_ELAPSED query around the whole renderFrame call. No GL command is issued
//    before draw() in a warm frame, so this is the GPU time of draw() as long as the driver does
//    not flush the query's begin on its own (check: GPU <= draw (wall));
//  frame: CPU wall time of renderFrame (adapt + stitch + upload + draw + sorting etc.).
//  (a) and (b) are one glDrawElements + glFinish per frame (CPU wall, as draw (wall)).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/gl/baseline_draws.h"
#include "bench/gl/gpu_timer.h"
#include "core/atlas_format.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"
#include "runtime/gl/gl_objects.h"

using namespace gimlod;

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// The whole terrain's level-0 heights, row-major samplesX x samplesY (gy northwards), assembled
// from every chart's pyramid level 0 (chart (u, v) is global (gridX * M + u, gridY * M + v)).
struct HeightGrid {
  uint32_t width = 0, height = 0;
  std::vector<float> z;
};

HeightGrid readLevel0(const AtlasView& atlas) {
  const AtlasManifest& m = atlas.manifest;
  if (m.kind == AtlasKind::Geometry) return {};  // mesh atlases: see buildChartMesh
  const uint32_t n = m.chartSize, intervals = n - 1;
  HeightGrid g;
  g.width = m.samplesX;
  g.height = m.samplesY;
  g.z.assign(size_t(g.width) * g.height, 0.f);
  for (const ChartInfo& c : m.charts) {
    const ChartFileReader reader(atlas.dir / c.file);
    const std::vector<float> level = reader.readLevelHeights(0);
    for (uint32_t v = 0; v < n; ++v) {
      const int64_t gy = int64_t(c.gridY) * intervals + v;
      if (gy < 0 || gy >= int64_t(g.height)) continue;
      for (uint32_t u = 0; u < n; ++u) {
        const int64_t gx = int64_t(c.gridX) * intervals + u;
        if (gx < 0 || gx >= int64_t(g.width)) continue;
        g.z[size_t(gy) * g.width + size_t(gx)] = level[size_t(v) * n + u];
      }
    }
  }
  return g;
}

// A regular (side+1)^2 grid over the valid extent, bilinear in the level-0 heights.
void buildGridMesh(const HeightGrid& g, const std::array<double, 2>& spacing, uint64_t triangles,
                   std::vector<glm::vec3>& positions, std::vector<uint32_t>& indices) {
  const uint32_t side = std::max<uint32_t>(1, uint32_t(std::lround(std::sqrt(double(triangles) / 2.0))));
  positions.clear();
  indices.clear();
  positions.reserve(size_t(side + 1) * (side + 1));
  indices.reserve(size_t(side) * side * 6);
  auto at = [&](uint32_t a, uint32_t b) { return double(g.z[size_t(b) * g.width + a]); };
  for (uint32_t j = 0; j <= side; ++j)
    for (uint32_t i = 0; i <= side; ++i) {
      const double gx = double(i) / side * (g.width - 1), gy = double(j) / side * (g.height - 1);
      const uint32_t x = std::min(uint32_t(gx), g.width - 2), y = std::min(uint32_t(gy), g.height - 2);
      const double fx = gx - x, fy = gy - y;
      const double z =
          (1 - fy) * ((1 - fx) * at(x, y) + fx * at(x + 1, y)) + fy * ((1 - fx) * at(x, y + 1) + fx * at(x + 1, y + 1));
      positions.emplace_back(float(gx * spacing[0]), float(gy * spacing[1]), float(z));
    }
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      const uint32_t a = j * (side + 1) + i, b = a + 1, c = b + side + 1, d = a + side + 1;
      indices.insert(indices.end(), {a, b, c, a, c, d});
    }
}

// Mesh atlases: (a) is every chart's grid at the pyramid level whose triangle count is closest to
// `triangles`, as one static indexed mesh (the atlas surface, unwelded).
void buildChartMesh(const AtlasView& atlas, uint64_t triangles, std::vector<glm::vec3>& positions,
                    std::vector<uint32_t>& indices) {
  const AtlasManifest& m = atlas.manifest;
  const uint32_t M = m.chartSize - 1;
  uint32_t level = 0;
  auto trisAt = [&](uint32_t k) { return 2.0 * double(m.charts.size()) * double(M >> k) * double(M >> k); };
  while ((M >> (level + 1)) >= 1 &&
         std::fabs(trisAt(level + 1) - double(triangles)) < std::fabs(trisAt(level) - double(triangles)))
    ++level;
  positions.clear();
  indices.clear();
  for (const ChartInfo& c : m.charts) {
    // A chart whose finest level is coarser gives its finest (ChartInfo::finestLevel).
    const uint32_t own = std::max(level, c.finestLevel), s = (M >> own) + 1;
    const std::vector<glm::vec3> p = ChartFileReader(atlas.dir / c.file).readLevelPositions(own - c.finestLevel);
    const uint32_t base = uint32_t(positions.size());
    positions.insert(positions.end(), p.begin(), p.end());
    for (uint32_t v = 0; v + 1 < s; ++v)
      for (uint32_t u = 0; u + 1 < s; ++u) {
        const uint32_t a = base + v * s + u, b = a + 1, cc = b + s, d = a + s;
        indices.insert(indices.end(), {a, b, cc, a, cc, d});
      }
  }
}

struct Config {
  uint32_t width = 640, height = 480;
  double tolerancePx = 1.0;
};

struct Result {
  Config config;
  uint32_t frames = 0;
  double meanTris = 0, minTris = 0, maxTris = 0, meanNodes = 0, maxErrorPx = 0;
  uint32_t budgetBoundFrames = 0, pagesMissing = 0;
  double pagesLoaded = 0;  // per frame: pages read from disk and uploaded (page-pool churn)
  double adaptMs = 0, stitchMs = 0, uploadMs = 0, drawMs = 0, gpuMs = 0, frameMs = 0;
  double meshMs = 0, staticMs = 0, floorMs = 0;  // (a), (b), clear + glFinish of a 2-triangle mesh
  uint64_t meshTris = 0, staticTris = 0;
};

double mtps(double trianglesPerFrame, double msPerFrame) {
  return msPerFrame > 0 ? trianglesPerFrame / msPerFrame * 1e-3 : 0.0;
}

Result runConfig(const AtlasView& atlas, const HeightGrid& grid, const Config& cfg, uint32_t maxNodes,
                 uint32_t frames) {
  Result r;
  r.config = cfg;
  gl::SceneOptions so;
  so.width = cfg.width;
  so.height = cfg.height;
  so.minNodeRoom = maxNodes;
  gl::AtlasScene scene(atlas, so);
  const std::vector<Camera> path = orbitPath(atlas.lo, atlas.hi, frames, 0.7, 30.0);
  r.frames = uint32_t(path.size());
  AdaptOptions ao;
  ao.tolerancePx = cfg.tolerancePx;
  ao.maxNodes = maxNodes;
  bench::GpuTimer timer;
  // Warm-up: pages resident, shaders compiled.
  for (const Camera& c : path) scene.renderFrame(c, ao);
  double tris = 0, nodes = 0;
  r.minTris = 1e300;
  for (const Camera& c : path) {
    const auto t0 = Clock::now();
    timer.begin();
    const gl::FrameResult f = scene.renderFrame(c, ao);
    r.gpuMs += timer.endMs();
    r.frameMs += msSince(t0);
    r.adaptMs += f.adaptMs;
    r.stitchMs += f.stitchMs;
    r.uploadMs += f.uploadMs;
    r.drawMs += f.draw.drawMs;
    tris += double(f.draw.triangles);
    r.minTris = std::min(r.minTris, double(f.draw.triangles));
    r.maxTris = std::max(r.maxTris, double(f.draw.triangles));
    nodes += double(f.cut.nodes.size());
    r.maxErrorPx = std::max(r.maxErrorPx, f.maxErrorPx);
    r.budgetBoundFrames += f.adapt.nodeBudgetBound ? 1 : 0;
    r.pagesMissing += f.pagesMissing;
    r.pagesLoaded += f.pagesLoaded;
  }
  const double n = double(path.size());
  r.meanTris = tris / n;
  r.meanNodes = nodes / n;
  r.pagesLoaded /= n;
  for (double* v : {&r.adaptMs, &r.stitchMs, &r.uploadMs, &r.drawMs, &r.gpuMs, &r.frameMs}) *v /= n;

  // (a) The atlas's level-0 heights as one regular grid mesh of about meanTris triangles.
  std::vector<glm::vec3> positions;
  std::vector<uint32_t> indices;
  if (atlas.manifest.kind == AtlasKind::Geometry)
    buildChartMesh(atlas, uint64_t(r.meanTris), positions, indices);
  else
    buildGridMesh(grid, atlas.manifest.spacing, uint64_t(r.meanTris), positions, indices);
  r.meshTris = indices.size() / 3;
  bench::BaselineDraws baselines(scene.renderer());
  for (const Camera& c : path)
    r.meshMs += baselines.drawMeshMs(positions, indices, glm::mat4(scene.viewProjection(c)), glm::vec3(c.eye), 1);
  r.meshMs /= n;

  // (b) A plain grid with a trivial shader; and the floor: clear + glFinish of 2 triangles.
  r.staticMs = baselines.drawStaticMeshMs(uint64_t(r.meanTris), r.frames, &r.staticTris);
  r.floorMs = baselines.drawStaticMeshMs(2, r.frames, nullptr);
  return r;
}

void printResult(const Result& r) {
  const Config& c = r.config;
  std::printf(
      "\n== %ux%u, tolerance %.2f px, %u frames: %.0f triangles/frame (min %.0f, max %.0f), "
      "%.0f nodes, max error %.2f px, node budget bound in %u frames, pages loaded %.1f/frame, "
      "pages missing %u\n",
      c.width, c.height, c.tolerancePx, r.frames, r.meanTris, r.minTris, r.maxTris, r.meanNodes, r.maxErrorPx,
      r.budgetBoundFrames, r.pagesLoaded, r.pagesMissing);
  std::printf(
      "engine CPU: adapt %.3f, stitch %.3f, upload %.3f ms/frame; draw (wall: submit + "
      "glFinish) %.3f, GPU (timer query) %.3f; whole renderFrame %.3f ms/frame\n",
      r.adaptMs, r.stitchMs, r.uploadMs, r.drawMs, r.gpuMs, r.frameMs);
  const double eDraw = mtps(r.meanTris, r.drawMs), eGpu = mtps(r.meanTris, r.gpuMs),
               eFrame = mtps(r.meanTris, r.frameMs);
  const double a = mtps(double(r.meshTris), r.meshMs), b = mtps(double(r.staticTris), r.staticMs);
  std::printf("engine draw (wall):               %8.3f ms/frame, %9.2f M triangles/s\n", r.drawMs, eDraw);
  std::printf("engine GPU (timer query):         %8.3f ms/frame, %9.2f M triangles/s\n", r.gpuMs, eGpu);
  std::printf("engine whole frame (CPU + draw):  %8.3f ms/frame, %9.2f M triangles/s\n", r.frameMs, eFrame);
  std::printf("(a) atlas grid mesh, same shading:%8.3f ms/frame, %9.2f M triangles/s (%llu triangles)\n", r.meshMs, a,
              (unsigned long long)r.meshTris);
  std::printf("(b) plain flat-shaded grid:       %8.3f ms/frame, %9.2f M triangles/s (%llu triangles)\n", r.staticMs, b,
              (unsigned long long)r.staticTris);
  std::printf("floor (clear + glFinish, 2 tris): %8.3f ms/frame\n", r.floorMs);
  std::printf(
      "engine / (a) = %.2f (draw wall), %.2f (GPU), %.2f (whole frame); "
      "engine / (b) = %.2f (draw wall), %.2f (GPU), %.2f (whole frame)\n",
      eDraw / a, eGpu / a, eFrame / a, eDraw / b, eGpu / b, eFrame / b);
}

void printSummary(const std::vector<Result>& results) {
  std::printf("\nsummary (ms/frame; Mt/s = million triangles/s; e = engine draw (wall), g = engine GPU timer)\n");
  std::printf("%-10s %5s %9s %6s | %6s %6s %6s %7s %7s %7s | %8s %8s | %7s %8s | %7s %8s | %5s %5s %5s %5s\n", "size",
              "tol", "tris", "nodes", "adapt", "stitch", "upload", "draw", "gpu", "frame", "drawMt/s", "gpuMt/s",
              "(a)ms", "Mt/s", "(b)ms", "Mt/s", "e/a", "e/b", "g/a", "g/b");
  for (const Result& r : results) {
    char size[32];
    std::snprintf(size, sizeof size, "%ux%u", r.config.width, r.config.height);
    const double e = mtps(r.meanTris, r.drawMs), g = mtps(r.meanTris, r.gpuMs);
    const double a = mtps(double(r.meshTris), r.meshMs), b = mtps(double(r.staticTris), r.staticMs);
    std::printf(
        "%-10s %5.2f %9.0f %6.0f | %6.3f %6.3f %6.3f %7.3f %7.3f %7.3f | %8.1f %8.1f | %7.3f %8.1f | "
        "%7.3f %8.1f | %5.2f %5.2f %5.2f %5.2f\n",
        size, r.config.tolerancePx, r.meanTris, r.meanNodes, r.adaptMs, r.stitchMs, r.uploadMs, r.drawMs, r.gpuMs,
        r.frameMs, e, g, r.meshMs, a, r.staticMs, b, e / a, e / b, g / a, g / b);
  }
}

}  // namespace

int main(int argc, char** argv) try {
  if (argc < 2 || std::strcmp(argv[1], "-h") == 0 || std::strcmp(argv[1], "--help") == 0) {
    std::fprintf(stderr,
                 "usage: %s ATLAS_DIR [WxH] [tolerance_px] [max_nodes] [frames]\n"
                 "       %s ATLAS_DIR --sweep [max_nodes] [frames] [tol,tol,...]\n",
                 argv[0], argv[0]);
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  const bool sweep = argc > 2 && std::strcmp(argv[2], "--sweep") == 0;
  std::vector<Config> configs;
  uint32_t maxNodes = 3000, frames = 24;
  if (sweep) {
    if (argc > 3) maxNodes = uint32_t(std::strtoul(argv[3], nullptr, 10));
    if (argc > 4) frames = uint32_t(std::strtoul(argv[4], nullptr, 10));
    std::vector<double> tols{1.0, 0.5, 0.25};
    if (argc > 5) {
      tols.clear();
      for (const char* p = argv[5]; *p;) {
        char* end = nullptr;
        const double t = std::strtod(p, &end);
        if (end == p || !(t > 0)) {
          std::fprintf(stderr, "bad tolerance list '%s' (want e.g. 1,0.5,0.25)\n", argv[5]);
          return 2;
        }
        tols.push_back(t);
        p = *end == ',' ? end + 1 : end;
      }
    }
    if (tols.empty() || frames == 0) {
      std::fprintf(stderr, "need at least one tolerance and one frame\n");
      return 2;
    }
    configs.push_back({640, 480, tols.front()});
    for (double t : tols) configs.push_back({1920, 1080, t});
    configs.push_back({3840, 2160, tols.back()});
  } else {
    Config c;
    if (argc > 2 && std::sscanf(argv[2], "%ux%u", &c.width, &c.height) != 2) {
      std::fprintf(stderr, "bad frame size '%s' (want WxH)\n", argv[2]);
      return 2;
    }
    if (argc > 3) c.tolerancePx = std::atof(argv[3]);
    if (argc > 4) maxNodes = uint32_t(std::strtoul(argv[4], nullptr, 10));
    if (argc > 5) frames = uint32_t(std::strtoul(argv[5], nullptr, 10));
    if (c.width == 0 || c.height == 0 || !(c.tolerancePx > 0) || frames == 0) {
      std::fprintf(stderr, "need a positive frame size, tolerance and frame count\n");
      return 2;
    }
    configs = {c};
  }

  const AtlasView atlas = openAtlas(dir);
  const auto t0 = Clock::now();
  const HeightGrid grid = readLevel0(atlas);
  const double readMs = msSince(t0);
  auto ctx = gl::EglContext::create();
  std::printf("device: %s (%s)\n", ctx->renderer().c_str(), ctx->version().c_str());
  std::printf("GL_VENDOR: %s\nEGL: %s\n", ctx->vendor().c_str(), ctx->display().c_str());
  std::printf("atlas %s: %zu charts of %u, %ux%u samples; level 0 read in %.0f ms; max nodes %u\n",
              dir.string().c_str(), atlas.manifest.charts.size(), atlas.manifest.chartSize, grid.width, grid.height,
              readMs, maxNodes);
  std::fflush(stdout);
  std::vector<Result> results;
  for (const Config& c : configs) {
    results.push_back(runConfig(atlas, grid, c, maxNodes, frames));
    printResult(results.back());
    std::fflush(stdout);
  }
  if (results.size() > 1) printSummary(results);
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_render_atlas: %s\n", e.what());
  return 1;
}

// Adaptation time per frame against the number of selected nodes, along a moving orbit.
// Usage: bench_adapt [DEM] [depth] [tolerance_px]  (default etopo5.cdf, depth 6, 0.02 px: a
// tolerance that the node budget binds, so the budget sets the node count)
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "atlas/dem.h"
#include "atlas/terrain_atlas.h"
#include "hierarchy/hierarchy.h"
#include "runtime/adapt.h"
#include "runtime/camera.h"

using namespace gimlod;

int main(int argc, char** argv) {
  const std::filesystem::path input = argc > 1 ? argv[1] : "../shared/data/terrain/etopo5.cdf";
  const uint32_t depth = argc > 2 ? uint32_t(std::atoi(argv[2])) : 6;
  const double tolerance = argc > 3 ? std::atof(argv[3]) : 0.02;
  const uint32_t chartSize = 513;
  const DemRaster dem = loadDem(input);
  AtlasManifest m;
  m.depth = depth;
  m.maxNodeResLog2 = 6;
  m.minNodeResLog2 = 2;
  TerrainAtlasOptions topt;
  topt.chartSize = chartSize;
  fillTerrainManifest(dem, topt, m);
  const Hierarchy h = buildTerrainHierarchy(
      m, [&](uint32_t c) { return extractChart(dem, m.charts[c].gridX, m.charts[c].gridY, chartSize); });
  const glm::dvec3 lo{0, 0, dem.minHeight};
  const glm::dvec3 hi{(dem.width - 1) * dem.spacing[0], (dem.height - 1) * dem.spacing[1], dem.maxHeight};
  const uint32_t frames = 60;
  const auto path = orbitPath(lo, hi, frames, 0.35, 20.0);
  std::printf("%s: %u charts, depth %u, %u nodes in the forest; %u-frame orbit, 1280x720, tolerance %.3f px\n",
              input.c_str(), h.chartCount(), depth, h.chartCount() * nodesPerChart(depth), frames, tolerance);
  std::printf("%10s %10s %12s %12s %12s %10s\n", "max_nodes", "nodes", "adapt_us", "us_per_node", "triangles",
              "max_err_px");
  for (uint32_t budget : {100u, 250u, 500u, 1000u, 2000u, 5000u, 10000u, 20000u}) {
    double totalUs = 0.0, nodes = 0.0, tris = 0.0, err = 0.0;
    for (int rep = 0; rep < 2; ++rep)
      for (const Camera& cam : path) {
        AdaptOptions o;
        o.tolerancePx = tolerance;
        o.maxNodes = budget;
        AdaptStats st;
        const auto t0 = std::chrono::steady_clock::now();
        const Cut cut = adaptErrorThreshold(h, makeViewParams(cam, 1280, 720), o, &st);
        totalUs += std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
        nodes += double(cut.nodes.size());
        tris += double(st.triangles);
        err = std::max(err, st.maxErrorPx);
      }
    const double n = 2.0 * frames;
    std::printf("%10u %10.0f %12.1f %12.3f %12.0f %10.2f\n", budget, nodes / n, totalUs / n, totalUs / nodes,
                tris / n, err);
  }
  return 0;
}

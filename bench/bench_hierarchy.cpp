// Hierarchy build throughput: samples per second, one thread against all threads, on a real DEM
// (default ../shared/data/terrain/etopo5.cdf, 4320 x 2161). Chart heights come from memory so
// the figure is the error and bounds computation itself.
#include <chrono>
#include <cstdio>
#include <filesystem>

#include <tbb/global_control.h>
#include <tbb/info.h>

#include "bench/guarded_main.h"
#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "hierarchy/hierarchy.h"

using namespace gimlod;

namespace {

int run(int argc, char** argv) {
  const std::filesystem::path input = argc > 1 ? argv[1] : "../shared/data/terrain/etopo5.cdf";
  const uint32_t chartSize = argc > 2 ? uint32_t(std::atoi(argv[2])) : 513;
  const int repeats = 3;
  const uint32_t depth = 5;
  DemRaster dem = loadDem(input);
  AtlasManifest m;
  m.depth = depth;
  m.maxNodeResLog2 = 6;
  m.minNodeResLog2 = 2;
  TerrainAtlasOptions topt;
  topt.chartSize = chartSize;
  fillTerrainManifest(dem, topt, m);
  std::vector<std::vector<float>> charts;
  for (const ChartInfo& c : m.charts) charts.push_back(extractChart(dem, c.gridX, c.gridY, chartSize));
  const uint64_t demSamples = uint64_t(dem.width) * dem.height;
  std::printf("input %s: %ux%u samples, %zu charts of %u^2 (depth %u, R %u, min res %u)\n", input.c_str(), dem.width,
              dem.height, charts.size(), chartSize, m.depth, 1u << m.maxNodeResLog2, 1u << m.minNodeResLog2);

  const int cores = tbb::info::default_concurrency();
  double perThread[2] = {0, 0};
  for (int t : {1, cores}) {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, size_t(t));
    double best = 1e30;
    HierarchyStats st;
    for (int r = 0; r < repeats; ++r) {
      buildTerrainHierarchy(
          m, [&](uint32_t c) { return charts[c]; }, &st);
      best = std::min(best, st.seconds);
    }
    const double chartRate = double(st.samples) / best, demRate = double(demSamples) / best;
    std::printf("threads %d: best of %d %.3f s, %.1f M chart samples/s (%.1f M/s per thread), %.1f M DEM samples/s\n",
                t, repeats, best, chartRate * 1e-6, chartRate * 1e-6 / t, demRate * 1e-6);
    perThread[t == 1 ? 0 : 1] = best;
    if (cores == 1) break;
  }
  if (cores > 1) std::printf("speed-up %d threads vs 1: %.2fx\n", cores, perThread[0] / perThread[1]);
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return guardedMain(argc, argv, run); }

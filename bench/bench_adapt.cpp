// Adaptation time per frame against the number of selected nodes (the paper's figure 6), along a
// moving orbit: the coherent dual-queue adapter (ours) against the stateless top-down greedy, in
// the same run. The tolerance is small enough that the node budget sets the node count.
// Then the same curve for the quad-queue adapter under a triangle budget (the setting of the
// paper's figure 6: 4M triangles), with the mean of the per-frame max error.
// Usage: bench_adapt ATLAS_DIR [tolerance_px=0.02] [frames=240] [WxH=1280x720] [triangles=4000000]
//        [max_roots=16] (top groups above the charts, openAtlas; 0: every chart root a root)
// Reads a built atlas only (no GDAL), e.g. `gimlod build ../shared/data/terrain/etopo5.cdf
// -o out/etopo.atlas --depth 6`.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "bench/guarded_main.h"
#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"

using namespace gimlod;
using Clock = std::chrono::steady_clock;

namespace {

int run(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: bench_adapt ATLAS_DIR [tolerance_px] [frames] [WxH] [triangles] [max_roots]\n");
    return 2;
  }
  const AtlasView atlas = openAtlas(argv[1], argc > 6 ? uint32_t(std::atoi(argv[6])) : kDefaultMaxRoots);
  const Hierarchy& h = atlas.hierarchy;
  const double tolerance = argc > 2 ? std::atof(argv[2]) : 0.02;
  const uint32_t frames = argc > 3 ? uint32_t(std::atoi(argv[3])) : 240;
  uint32_t w = 1280, hgt = 720;
  if (argc > 4) std::sscanf(argv[4], "%ux%u", &w, &hgt);
  const uint64_t triangles = argc > 5 ? std::strtoull(argv[5], nullptr, 10) : 4000000ull;
  if (!(tolerance > 0.0) || frames == 0 || w == 0 || hgt == 0) {
    std::fprintf(stderr, "bench_adapt: bad arguments\n");
    return 2;
  }
  std::vector<ViewParams> views;
  for (Camera c : orbitPath(atlas.lo, atlas.hi, frames, 0.35, 20.0)) views.push_back(makeViewParams(c, w, hgt));
  std::printf("%s: %u charts, %zu top groups, depth %u, %u nodes in the forest; %u-frame orbit, %ux%u, tolerance %.3f px\n",
              argv[1], h.chartCount(), h.groups.tops.size(), h.params.depth, h.chartCount() * nodesPerChart(h.params.depth),
              frames, w, hgt, tolerance);
  std::printf("%9s %8s %10s %10s %8s %8s %11s %10s %9s\n", "max_nodes", "nodes", "ours_us", "us/node", "ops",
              "reused", "greedy_us", "greedy/us", "err_px");
  for (uint32_t budget : {100u, 250u, 500u, 1000u, 2000u, 5000u, 10000u, 20000u}) {
    AdaptOptions o;
    o.tolerancePx = tolerance;
    o.maxNodes = budget;
    DualQueueAdapter ours(h);
    for (const ViewParams& v : views) ours.update(v, o);  // one warm-up pass: a coherent state
    double us = 0.0, nodes = 0.0, ops = 0.0, reused = 0.0, greedyUs = 0.0, err = 0.0;
    for (const ViewParams& v : views) {
      AdaptStats st;
      auto t0 = Clock::now();
      const Cut& cut = ours.update(v, o, &st);
      us += std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
      nodes += double(cut.nodeCount());
      ops += ours.frameStats().splits + ours.frameStats().merges;
      reused += ours.frameStats().priorityReuses;
      err = std::max(err, st.maxErrorPx);
      t0 = Clock::now();
      const Cut g = adaptErrorThreshold(h, v, o);
      greedyUs += std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
    }
    const double n = double(views.size());
    std::printf("%9u %8.0f %10.1f %10.4f %8.1f %8.0f %11.1f %10.2f %9.4f\n", budget, nodes / n, us / n,
                us / nodes, ops / n, reused / n, greedyUs / n, greedyUs / us, err);
  }
  std::printf("\nquad queue, %llu triangles:\n%9s %8s %10s %10s %8s %8s %10s\n", (unsigned long long)triangles,
              "max_nodes", "nodes", "ours_us", "us/node", "rounds", "ops", "err_px");
  for (uint32_t budget : {100u, 250u, 500u, 1000u, 2000u, 5000u, 10000u, 20000u}) {
    BudgetOptions o;
    o.maxTriangles = triangles;
    o.maxNodes = budget;
    QuadQueueAdapter ours(h);
    for (const ViewParams& v : views) ours.update(v, o);  // warm-up pass
    double us = 0.0, nodes = 0.0, rounds = 0.0, ops = 0.0, err = 0.0;
    for (const ViewParams& v : views) {
      BudgetStats st;
      const auto t0 = Clock::now();
      const Cut& cut = ours.update(v, o, &st);
      us += std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
      nodes += double(cut.nodeCount());
      rounds += st.rounds;
      ops += st.refines + st.coarsens + st.splits + st.merges + st.undoneOps;
      err += st.maxErrorPx;
    }
    const double n = double(views.size());
    std::printf("%9u %8.0f %10.1f %10.4f %8.2f %8.0f %10.4f\n", budget, nodes / n, us / n, us / nodes, rounds / n,
                ops / n, err / n);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return guardedMain(argc, argv, run); }

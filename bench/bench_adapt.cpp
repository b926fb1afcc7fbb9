// Adaptation time per frame against the number of selected nodes (the paper's figure 6), along a
// moving orbit: the coherent dual-queue adapter (ours) against the stateless top-down greedy, in
// the same run. The tolerance is small enough that the node budget sets the node count.
// Then the same curve for the quad-queue adapter under a triangle budget (the setting of the
// paper's figure 6: 4M triangles), with the mean of the per-frame max error. Each adapter runs
// beside its reference (tests/reference: the adapter before its per-frame work was made
// incremental) on the same frames: ref/ours is the speed-up, same the frames with identical cuts.
// Usage: bench_adapt ATLAS_DIR [tolerance_px=0.02] [frames=240] [WxH=1280x720] [triangles=4000000]
//        [max_roots=16] (top groups above the charts, openAtlas; 0: every chart root a root)
//        [--budgets 100,1000,...] [--only dual|quad] [--ours-only] [--ops]
//        [--parallel-min N] (0: the adapters on one thread)
// Reads a built atlas only (no GDAL), e.g. `gimlod build ../shared/data/terrain/etopo5.cdf
// -o out/etopo.atlas --depth 6`.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench/guarded_main.h"
#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "tests/reference/adapt_dual_queue.h"
#include "tests/reference/adapt_quad_queue.h"

using namespace gimlod;
using Clock = std::chrono::steady_clock;

namespace {

struct Args {
  std::string atlas;
  double tolerance = 0.02;
  uint32_t frames = 240;
  std::string size = "1280x720";
  uint64_t triangles = 4000000ull;
  uint32_t maxRoots = kDefaultMaxRoots;
  std::vector<uint32_t> budgets{100u, 250u, 500u, 1000u, 2000u, 5000u, 10000u, 20000u};
  std::string only;
  bool oursOnly = false;      // skip the references and the greedy (for profiles of the adapters alone)
  bool opsBreakdown = false;  // the quad queue's operations per frame, by kind
  uint32_t parallelMin = kDefaultParallelMin;  // the adapters' parallelMin (0: one thread)
};

// (key, resolution) of every node, sorted: equal for equal cuts.
std::vector<std::pair<uint64_t, uint32_t>> sortedNodes(const Cut& cut) {
  std::vector<std::pair<uint64_t, uint32_t>> v;
  v.reserve(cut.nodes.size());
  for (const CutNode& n : cut.nodes) v.push_back({n.id.key(), n.resLog2});
  std::sort(v.begin(), v.end());
  return v;
}

double since(Clock::time_point t0) { return std::chrono::duration<double, std::micro>(Clock::now() - t0).count(); }

// The dual queue against its reference (the adapter before its per-frame work was made
// incremental) and the stateless top-down greedy, each on the same frames.
void benchDual(const Hierarchy& h, const std::vector<ViewParams>& views, const Args& a) {
  std::printf("dual queue, tolerance %.3f px:\n%9s %8s %10s %10s %8s %8s %10s %9s %11s %9s %9s %6s\n", a.tolerance,
              "max_nodes", "nodes", "ours_us", "us/node", "ops", "reused", "ref_us", "ref/ours", "greedy_us", "err_px",
              "ref_err", "same");
  for (uint32_t budget : a.budgets) {
    AdaptOptions o;
    o.tolerancePx = a.tolerance;
    o.maxNodes = budget;
    DualQueueAdapter ours(h, 1024, true, a.parallelMin);
    reference::DualQueueAdapter ref(h);
    for (const ViewParams& v : views) {  // warm-up: a coherent state
      ours.update(v, o);
      if (!a.oursOnly) ref.update(v, o);
    }
    double us = 0.0, nodes = 0.0, ops = 0.0, reused = 0.0, refUs = 0.0, greedyUs = 0.0, err = 0.0, refErr = 0.0;
    uint32_t same = 0;
    for (const ViewParams& v : views) {
      AdaptStats st, rst;
      auto t0 = Clock::now();
      const Cut& cut = ours.update(v, o, &st);
      us += since(t0);
      nodes += double(cut.nodeCount());
      ops += ours.frameStats().splits + ours.frameStats().merges;
      reused += ours.frameStats().priorityReuses;
      err = std::max(err, st.maxErrorPx);
      if (a.oursOnly) continue;
      t0 = Clock::now();
      const Cut& rcut = ref.update(v, o, &rst);
      refUs += since(t0);
      refErr = std::max(refErr, rst.maxErrorPx);
      same += uint32_t(sortedNodes(cut) == sortedNodes(rcut));
      t0 = Clock::now();
      const Cut g = adaptErrorThreshold(h, v, o);
      greedyUs += since(t0);
    }
    const double n = double(views.size());
    std::printf("%9u %8.0f %10.1f %10.4f %8.1f %8.0f %10.1f %9.2f %11.1f %9.4f %9.4f %6u\n", budget, nodes / n, us / n,
                us / nodes, ops / n, reused / n, refUs / n, refUs / us, greedyUs / n, err, refErr, same);
  }
}

// The quad queue against its reference, on the same frames; err_px is the mean of the per-frame
// max error.
void benchQuad(const Hierarchy& h, const std::vector<ViewParams>& views, const Args& a) {
  std::printf("quad queue, %llu triangles:\n%9s %8s %10s %10s %8s %8s %10s %9s %9s %9s %6s\n",
              (unsigned long long)a.triangles, "max_nodes", "nodes", "ours_us", "us/node", "rounds", "ops", "ref_us",
              "ref/ours", "err_px", "ref_err", "same");
  for (uint32_t budget : a.budgets) {
    BudgetOptions o;
    o.maxTriangles = a.triangles;
    o.maxNodes = budget;
    QuadQueueAdapter ours(h, a.parallelMin);
    reference::QuadQueueAdapter ref(h);
    for (const ViewParams& v : views) {  // warm-up pass
      ours.update(v, o);
      if (!a.oursOnly) ref.update(v, o);
    }
    double us = 0.0, nodes = 0.0, rounds = 0.0, ops = 0.0, err = 0.0, refUs = 0.0, refErr = 0.0;
    BudgetStats kinds;  // summed over the frames
    uint32_t same = 0;
    for (const ViewParams& v : views) {
      BudgetStats st, rst;
      auto t0 = Clock::now();
      const Cut& cut = ours.update(v, o, &st);
      us += since(t0);
      nodes += double(cut.nodeCount());
      rounds += st.rounds;
      ops += st.refines + st.coarsens + st.splits + st.merges + st.undoneOps;
      kinds.refines += st.refines, kinds.coarsens += st.coarsens, kinds.splits += st.splits;
      kinds.merges += st.merges, kinds.undoneOps += st.undoneOps, kinds.undos += st.undos + st.tieUndos;
      kinds.boundedPriorities += st.boundedPriorities;
      err += st.maxErrorPx;
      if (a.oursOnly) continue;
      t0 = Clock::now();
      const Cut& rcut = ref.update(v, o, &rst);
      refUs += since(t0);
      refErr += rst.maxErrorPx;
      same += uint32_t(sortedNodes(cut) == sortedNodes(rcut));
    }
    const double n = double(views.size());
    std::printf("%9u %8.0f %10.1f %10.4f %8.2f %8.0f %10.1f %9.2f %9.4f %9.4f %6u\n", budget, nodes / n, us / n,
                us / nodes, rounds / n, ops / n, refUs / n, refUs / us, err / n, refErr / n, same);
    if (a.opsBreakdown)
      std::printf(
          "%9s per frame: %.1f refines, %.1f coarsens, %.1f splits, %.1f merges, %.1f undone in %.2f undos; %.0f "
          "split priorities from bounds\n",
          "", kinds.refines / n, kinds.coarsens / n, kinds.splits / n, kinds.merges / n, kinds.undoneOps / n,
          kinds.undos / n, kinds.boundedPriorities / n);
  }
}

int run(int argc, char** argv) {
  Args a;
  CLI::App app{"Adaptation time per frame against the node budget, along an orbit"};
  app.add_option("atlas", a.atlas, "built atlas directory")->required();
  app.add_option("tolerance", a.tolerance, "screen-space tolerance, px")->check(CLI::PositiveNumber);
  app.add_option("frames", a.frames, "frames of the orbit")->check(CLI::Range(1u, 1000000u));
  app.add_option("size", a.size, "viewport WxH");
  app.add_option("triangles", a.triangles, "the quad queue's triangle budget")->check(CLI::PositiveNumber);
  app.add_option("max_roots", a.maxRoots, "top groups above the charts (0: every chart root a root)");
  app.add_option("--budgets", a.budgets, "node budgets")->delimiter(',');
  app.add_option("--only", a.only, "one adapter")->check(CLI::IsMember({"dual", "quad"}));
  app.add_option("--parallel-min", a.parallelMin,
                 "kept cuts of at least this many nodes are evaluated in parallel (0: never)");
  app.add_flag("--ops", a.opsBreakdown, "the quad queue's operations per frame, by kind");
  app.add_flag("--ours-only", a.oursOnly, "time the adapters alone: no reference, no greedy (ref and same columns 0)");
  CLI11_PARSE(app, argc, argv);
  uint32_t w = 0, hgt = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &w, &hgt) != 2 || w == 0 || hgt == 0) {
    std::fprintf(stderr, "bench_adapt: bad viewport size '%s' (WxH)\n", a.size.c_str());
    return 2;
  }
  const AtlasView atlas = openAtlas(a.atlas, a.maxRoots);
  const Hierarchy& h = atlas.hierarchy;
  std::vector<ViewParams> views;
  for (Camera c : orbitPath(atlas.lo, atlas.hi, a.frames, 0.35, 20.0)) views.push_back(makeViewParams(c, w, hgt));
  std::printf(
      "%s: %u charts, %zu top groups, depth %u, %u nodes in the forest; %u-frame orbit, %ux%u, tolerance %.3f px\n",
      a.atlas.c_str(), h.chartCount(), h.groups.tops.size(), h.params.depth,
      h.chartCount() * nodesPerChart(h.params.depth), a.frames, w, hgt, a.tolerance);
  if (a.only != "quad") benchDual(h, views, a);
  if (a.only.empty()) std::printf("\n");
  if (a.only != "dual") benchQuad(h, views, a);
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return guardedMain(argc, argv, run); }

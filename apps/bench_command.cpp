// `gimlod bench`: see bench_command.h.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (error-threshold and triangle-budget
// problems, the dual- and quad-queue adapters against fixed granularity and top-down greedy) and
// figure 6 (adaptation time and error against the node count).
#include "apps/bench_command.h"
#include "apps/streaming_args.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <tuple>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "core/atlas_format.h"
#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/atlas_view.h"
#include "runtime/baselines.h"
#include "runtime/camera.h"
#include "runtime/frame_controller.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const char* const kAlgorithms[] = {"ours", "fixed", "greedy"};

// One frame of one configuration.
struct Row {
  std::string algorithm;
  uint32_t maxNodes = 0;
  uint64_t maxTriangles = 0;  // budget mode only
  uint32_t repeat = 0, frame = 0;
  double adaptUs = 0.0;
  uint32_t nodes = 0;
  uint64_t triangles = 0;
  double maxErrorPx = 0.0, meanErrorPx = 0.0;
  uint32_t splits = 0, merges = 0, refines = 0, coarsens = 0;
  bool budgetBound = false;
  uint32_t constraintSplits = 0;
  uint32_t rootFloor = 0;         // visible top groups, or chart roots: no cut has fewer nodes
  bool budgetBelowRoots = false;  // maxNodes < rootFloor: the visible roots are drawn, over the budget
  double drawMs = std::numeric_limits<double>::quiet_NaN();  // --render only
};

// Adapts to one view: fills the row's adapt_us and algorithm counters, returns the drawn cut
// (valid until the next call).
using Adapter = std::function<const Cut&(const ViewParams&, Row&)>;

double microsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
}

// Comma-separated positive integers; throws InputError naming the option.
std::vector<uint64_t> parseList(const std::string& option, const std::string& text, uint64_t maxValue) {
  std::vector<uint64_t> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    item.erase(0, item.find_first_not_of(" \t"));
    item.erase(item.find_last_not_of(" \t") + 1);
    if (item.empty()) throw InputError(option + " '" + text + "' has an empty entry");
    if (item.find_first_not_of("0123456789") != std::string::npos)
      throw InputError(option + " '" + text + "': '" + item + "' is not a positive integer");
    uint64_t v = 0;
    try {
      v = std::stoull(item);
    } catch (const std::exception&) {
      throw InputError(option + " '" + text + "': '" + item + "' is out of range");
    }
    if (v == 0) throw InputError(option + " '" + text + "': budgets must be > 0");
    if (v > maxValue) throw InputError(fmt::format("{} '{}': {} is above the maximum {}", option, text, v, maxValue));
    if (std::find(out.begin(), out.end(), v) != out.end())
      throw InputError(option + " '" + text + "': " + item + " is listed twice");
    out.push_back(v);
  }
  if (out.empty() || text.back() == ',') throw InputError(option + " must be a non-empty comma-separated list");
  return out;
}

std::vector<std::string> parseAlgorithms(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (std::find(std::begin(kAlgorithms), std::end(kAlgorithms), item) == std::end(kAlgorithms))
      throw InputError("--algorithms '" + text + "': unknown algorithm '" + item + "' (ours, fixed, greedy)");
    if (std::find(out.begin(), out.end(), item) != out.end())
      throw InputError("--algorithms '" + text + "': " + item + " is listed twice");
    out.push_back(item);
  }
  if (out.empty() || text.back() == ',')
    throw InputError("--algorithms must be a non-empty list of ours, fixed, greedy");
  return out;
}

// Screen error of every drawn node at its drawn resolution, measured the same way for every
// algorithm; also nodes and triangles.
void measureCut(const Hierarchy& h, const Cut& cut, const ViewParams& v, Row& r) {
  double maxE = 0.0, sum = 0.0;
  for (const CutNode& n : cut.nodes) {
    const double e = screenError(h, n.id, n.resLog2, v);
    maxE = std::max(maxE, e);
    sum += e;
  }
  r.nodes = cut.nodeCount();
  r.triangles = cut.triangles();
  r.maxErrorPx = maxE;
  r.meanErrorPx = cut.nodes.empty() ? 0.0 : sum / double(cut.nodes.size());
}

// Error-threshold mode adapters (fresh state per configuration).
Adapter makeErrorAdapter(const Hierarchy& h, const std::string& algo, uint32_t maxNodes, double tol) {
  if (algo == "ours") {
    auto dq = std::make_shared<DualQueueAdapter>(h);
    AdaptOptions o;
    o.tolerancePx = tol;
    o.maxNodes = maxNodes;
    return [dq, o](const ViewParams& v, Row& r) -> const Cut& {
      AdaptStats st;
      const auto t0 = Clock::now();
      const Cut& cut = dq->update(v, o, &st);
      r.adaptUs = microsSince(t0);
      r.splits = dq->frameStats().splits;
      r.merges = dq->frameStats().merges;
      r.budgetBound = st.nodeBudgetBound;
      r.constraintSplits = st.constraintSplits;
      r.rootFloor = st.rootFloor;
      r.budgetBelowRoots = st.budgetBelowRoots;
      return cut;
    };
  }
  auto held = std::make_shared<Cut>();
  const bool fixed = algo == "fixed";
  return [&h, held, fixed, maxNodes, tol](const ViewParams& v, Row& r) -> const Cut& {
    AdaptStats st;
    const auto t0 = Clock::now();
    Cut cut = fixed ? adaptFixedGranularity(h, v, tol, maxNodes, &st) : adaptTopDownGreedy(h, v, tol, maxNodes, &st);
    r.adaptUs = microsSince(t0);
    r.splits = st.splits;
    r.budgetBound = st.nodeBudgetBound;
    r.constraintSplits = st.constraintSplits;
    r.rootFloor = st.rootFloor;
    r.budgetBelowRoots = st.budgetBelowRoots;
    *held = std::move(cut);
    return *held;
  };
}

// Triangle-budget mode adapters. budget_bound: at the node budget, or within 25% of the triangle
// budget (one more refinement step of a node quadruples its triangles).
Adapter makeBudgetAdapter(const Hierarchy& h, const std::string& algo, uint32_t maxNodes, uint64_t maxTris,
                          uint32_t maxRounds) {
  BudgetOptions o;
  o.maxNodes = maxNodes;
  o.maxTriangles = maxTris;
  o.maxRounds = maxRounds;
  auto fill = [maxNodes, maxTris](const BudgetStats& st, const Cut& cut, Row& r) {
    r.refines = st.refines;
    r.coarsens = st.coarsens;
    r.splits = st.splits;
    r.merges = st.merges;
    r.constraintSplits = st.constraintSplits;
    r.rootFloor = st.rootFloor;
    r.budgetBelowRoots = st.budgetBelowRoots;
    r.budgetBound = cut.nodeCount() >= maxNodes || 4 * cut.triangles() >= 3 * maxTris;
  };
  if (algo == "ours") {
    auto qq = std::make_shared<QuadQueueAdapter>(h);
    return [qq, o, fill](const ViewParams& v, Row& r) -> const Cut& {
      BudgetStats st;
      const auto t0 = Clock::now();
      const Cut& cut = qq->update(v, o, &st);
      r.adaptUs = microsSince(t0);
      fill(st, cut, r);
      return cut;
    };
  }
  auto held = std::make_shared<Cut>();
  const bool fixed = algo == "fixed";
  return [&h, held, fixed, o, fill](const ViewParams& v, Row& r) -> const Cut& {
    BudgetStats st;
    const auto t0 = Clock::now();
    Cut cut = fixed ? adaptFixedGranularityBudget(h, v, o, &st) : adaptGreedyBudget(h, v, o, &st);
    r.adaptUs = microsSince(t0);
    *held = std::move(cut);
    fill(st, *held, r);
    return *held;
  };
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t k = size_t(std::ceil(p * double(v.size())));
  return v[std::min(v.size() - 1, k == 0 ? 0 : k - 1)];
}

struct Summary {
  std::string algorithm;
  uint32_t maxNodes = 0;
  uint64_t maxTriangles = 0;
  size_t frames = 0;
  double adaptUs = 0, nodes = 0, triangles = 0, meanErr = 0, boundFrac = 0, drawMs = 0;
  double belowRootsFrac = 0;  // frames whose node budget was below the visible roots
  uint32_t rootFloorMax = 0;
  double errMean = 0, errP50 = 0, errP95 = 0, errMax = 0;
  uint32_t nodesMax = 0;
  uint64_t trianglesMax = 0;
};

Summary summarize(const std::vector<Row>& rows) {
  Summary s;
  s.algorithm = rows.front().algorithm;
  s.maxNodes = rows.front().maxNodes;
  s.maxTriangles = rows.front().maxTriangles;
  s.frames = rows.size();
  std::vector<double> err;
  for (const Row& r : rows) {
    s.adaptUs += r.adaptUs;
    s.nodes += r.nodes;
    s.triangles += double(r.triangles);
    s.meanErr += r.meanErrorPx;
    s.boundFrac += r.budgetBound;
    s.belowRootsFrac += r.budgetBelowRoots;
    s.rootFloorMax = std::max(s.rootFloorMax, r.rootFloor);
    s.drawMs += std::isnan(r.drawMs) ? 0.0 : r.drawMs;
    s.errMean += r.maxErrorPx;
    s.nodesMax = std::max(s.nodesMax, r.nodes);
    s.trianglesMax = std::max(s.trianglesMax, r.triangles);
    err.push_back(r.maxErrorPx);
  }
  const double n = double(rows.size());
  for (double* v :
       {&s.adaptUs, &s.nodes, &s.triangles, &s.meanErr, &s.boundFrac, &s.drawMs, &s.errMean, &s.belowRootsFrac})
    *v /= n;
  s.errP50 = percentile(err, 0.5);
  s.errP95 = percentile(err, 0.95);
  s.errMax = *std::max_element(err.begin(), err.end());
  return s;
}

std::string optNum(bool present, double v, const char* f = "{:.4f}") {
  return present ? fmt::format(fmt::runtime(f), v) : std::string();
}

}  // namespace

CLI::App* addBenchCommand(CLI::App& app, BenchArgs& a) {
  auto* b = app.add_subcommand("bench", "Benchmark adaptation (time, nodes, triangles, error) over a camera path");
  b->add_option("atlas", a.atlas, "Atlas directory")->required();
  b->add_option("-o,--output", a.output, "Output directory (bench.csv, summary.csv, cost_model.json)")->required();
  addCameraOptions(b, a.camera);
  b->add_option("--mode", a.mode, "error: error threshold with node budgets; budget: node x triangle budgets")
      ->capture_default_str();
  b->add_option("--nodes", a.nodes, "Node budgets, comma-separated")->capture_default_str();
  auto* tris = b->add_option("--triangles", a.triangles, "Triangle budgets, comma-separated (budget mode)")
                   ->capture_default_str();
  auto* tol = b->add_option("--tolerance", a.tolerance, "Screen-space error tolerance in pixels (error mode)")
                  ->capture_default_str();
  b->add_option("--size", a.size, "Viewport WxH for the projection")->capture_default_str();
  b->add_option("--algorithms", a.algorithms, "Subset of ours,fixed,greedy")->capture_default_str();
  b->add_option("--repeat", a.repeat, "Passes over the camera path per configuration")->capture_default_str();
  b->add_option("--max-rounds", a.maxRounds,
                "Budget mode: quad-queue split/merge rounds per frame (the per-frame work cap)")
      ->capture_default_str();
  b->add_flag("--render", a.render, "Also draw each cut (headless EGL) and record draw_ms");
  b->add_option("--gpu-cache", a.gpuCache,
                "With --render: the GPU page pool in bytes (K, M, G), the chart roots resident while they fit "
                "with room to split one, else each root a coarser stand-in; auto: a pool that holds the largest "
                "node budget's cuts")
      ->capture_default_str();
  b->add_option("--frame-ms", a.frameMs, "Cost model: target frame time in ms (needs --tri-rate)");
  b->add_option("--tri-rate", a.triRate, "Cost model: triangle throughput in triangles/s (e.g. from bench_render)");
  b->add_option("--control-frames", a.controlFrames,
                "Cost model, budget mode: frames the frame-time controller runs along the path (cycling it); 0: none")
      ->capture_default_str();
  b->add_option("--load-step", a.loadStep,
                "Cost model, budget mode: the triangle rate is multiplied by this halfway through the controller's "
                "run (a jump in load)")
      ->capture_default_str();
  b->callback([&a, tris, tol] {
    a.trianglesGiven = tris->count() > 0;
    a.toleranceGiven = tol->count() > 0;
  });
  return b;
}

// The frame-time controller (runtime/frame_controller.h) along the path on the cost model: each
// frame is adapted by 'ours' (the quad queue) at the controller's budgets; its time is the
// measured adaptation plus triangles / rate (the drawing the cost model predicts). Halfway, the
// rate is multiplied by --load-step: a jump in load the controller must absorb.
struct ControlledRun {
  std::string csv, report;
  nlohmann::json summary;
};

// Frames from `from` until the frame is on target for 5 frames in a row: its time within 10% of
// the target, or below it with both budgets unused (the view needs less: nothing left to give);
// -1 if it never is before `to`.
int settlingFrames(const std::vector<double>& ms, const std::vector<bool>& unused, size_t from, size_t to,
                   double target) {
  int run = 0;
  for (size_t i = from; i < to; ++i) {
    run = std::abs(ms[i] - target) <= 0.1 * target || (ms[i] < target && unused[i]) ? run + 1 : 0;
    if (run == 5) return int(i - 4 - from);
  }
  return -1;
}

ControlledRun runFrameController(const Hierarchy& hier, const std::vector<ViewParams>& views, const BenchArgs& a) {
  FrameControllerOptions fo;
  fo.targetMs = a.frameMs;
  FrameController control(fo, 64, 100000);
  QuadQueueAdapter adapter(hier);
  const size_t n = a.controlFrames, step = n / 2;
  std::vector<double> ms(n);
  std::vector<bool> unused(n);  // both budgets at most 90% used
  ControlledRun run;
  run.csv = "frame,max_nodes,max_triangles,nodes,triangles,adapt_ms,draw_ms,frame_ms,target_ms,tri_rate,max_error_px\n";
  for (size_t i = 0; i < n; ++i) {
    const ViewParams& v = views[i % views.size()];
    const double rate = i < step ? a.triRate : a.triRate * a.loadStep;
    BudgetOptions o;
    o.maxNodes = control.maxNodes();
    o.maxTriangles = control.maxTriangles();
    o.maxRounds = a.maxRounds;
    const auto t0 = Clock::now();
    const Cut& cut = adapter.update(v, o, nullptr);
    FrameSample f;
    f.adaptMs = microsSince(t0) * 1e-3;
    f.nodes = cut.nodeCount();
    f.triangles = cut.triangles();
    f.drawMs = double(f.triangles) / rate * 1e3;
    f.frameMs = f.adaptMs + f.drawMs;
    ms[i] = f.frameMs;
    unused[i] = f.nodes < 0.9 * o.maxNodes && double(f.triangles) < 0.9 * double(o.maxTriangles);
    Row r;
    measureCut(hier, cut, v, r);
    run.csv += fmt::format("{},{},{},{},{},{:.4f},{:.4f},{:.4f},{},{:.6g},{:.4f}\n", i, o.maxNodes, o.maxTriangles,
                           f.nodes, f.triangles, f.adaptMs, f.drawMs, f.frameMs, a.frameMs, rate, r.maxErrorPx);
    control.update(f);
  }
  const double t = a.frameMs;
  const int settleStart = settlingFrames(ms, unused, 0, step, t), settleStep = settlingFrames(ms, unused, step, n, t);
  const size_t unusedFrames = size_t(std::count(unused.begin(), unused.end(), true));
  // Overshoot: past the target on the far side once it was first reached (from below at the start,
  // from above after the step), as a fraction of the target.
  const auto overshoot = [&](size_t from, size_t to, bool fromBelow) {
    size_t i = from;
    while (i < to && (fromBelow ? ms[i] < t : ms[i] > t)) ++i;
    double worst = 0.0;
    for (; i < to; ++i) worst = std::max(worst, fromBelow ? ms[i] / t - 1.0 : 1.0 - ms[i] / t);
    return worst;
  };
  const bool startBelow = ms.empty() || ms[0] < t;
  const double overStart = overshoot(0, step, startBelow), overStep = overshoot(step, n, a.loadStep > 1.0);
  double peak = 0.0;
  for (size_t i = step; i < n; ++i) peak = std::max(peak, ms[i]);
  // Steady state: the mean absolute deviation over the last quarter of each half.
  const auto deviation = [&](size_t from, size_t to) {
    double sum = 0.0;
    for (size_t i = from; i < to; ++i) sum += std::abs(ms[i] - t) / t;
    return to > from ? sum / double(to - from) : 0.0;
  };
  const double devStart = deviation(step - step / 4, step), devStep = deviation(n - (n - step) / 4, n);
  run.summary = {{"target_ms", t},
                 {"frames", n},
                 {"load_step_frame", step},
                 {"load_step_factor", a.loadStep},
                 {"settling_frames_start", settleStart},
                 {"settling_frames_after_step", settleStep},
                 {"overshoot_start", overStart},
                 {"overshoot_after_step", overStep},
                 {"peak_ms_after_step", peak},
                 {"steady_deviation_start", devStart},
                 {"steady_deviation_after_step", devStep},
                 {"frames_view_needs_less", unusedFrames}};
  const auto frames = [](int f) { return f < 0 ? std::string("never") : fmt::format("{} frames", f); };
  run.report = fmt::format(
      "frame-time controller ({} frames, target {} ms, triangle rate x{} at frame {}): within 10% after {} from "
      "the start (overshoot {:.1f}%) and {} after the step (peak {:.2f} ms, overshoot {:.1f}%); steady |error| "
      "{:.1f}% and {:.1f}%; {} frames needed less than both budgets (controller.csv)\n",
      n, t, a.loadStep, step, frames(settleStart), 100.0 * overStart, frames(settleStep), peak, 100.0 * overStep,
      100.0 * devStart, 100.0 * devStep, unusedFrames);
  return run;
}

// The options of a run, checked; throws InputError naming a bad one.
struct BenchPlan {
  bool budgetMode = false;
  std::vector<uint64_t> nodeBudgets, triBudgets;
  std::vector<std::string> algorithms;
  uint32_t width = 0, height = 0;
  bool costModel = false;  // --frame-ms and --tri-rate given
};

BenchPlan benchPlan(const BenchArgs& a) {
  BenchPlan p;
  p.budgetMode = a.mode == "budget";
  const bool budgetMode = p.budgetMode;
  if (a.mode != "error" && !budgetMode) throw InputError("--mode '" + a.mode + "' must be error or budget");
  p.nodeBudgets = parseList("--nodes", a.nodes, 1u << 24);
  if (budgetMode) {
    p.triBudgets = parseList("--triangles", a.triangles, uint64_t(1) << 40);
    if (a.toleranceGiven) throw InputError("--tolerance applies to --mode error only");
  } else {
    if (a.trianglesGiven) throw InputError("--triangles applies to --mode budget only");
    p.triBudgets = {0};
    if (!(a.tolerance > 0.0) || !std::isfinite(a.tolerance)) throw InputError("--tolerance must be > 0 pixels");
  }
  p.algorithms = parseAlgorithms(a.algorithms);
  parseFrameSize(a.size, &p.width, &p.height);
  validateCameraArgs(a.camera);
  if (a.repeat == 0 || a.repeat > 1000) throw InputError("--repeat must be in [1, 1000]");
  if (a.maxRounds > 1000) throw InputError("--max-rounds must be in [0, 1000]");
  p.costModel = a.frameMs != 0.0 || a.triRate != 0.0;
  if (p.costModel) {
    if (!(a.frameMs > 0.0) || !std::isfinite(a.frameMs)) throw InputError("--frame-ms must be > 0 (with --tri-rate)");
    if (!(a.triRate > 0.0) || !std::isfinite(a.triRate))
      throw InputError("--tri-rate must be > 0 triangles/s (with --frame-ms); measure it with bench_render");
    if (std::find(p.algorithms.begin(), p.algorithms.end(), "ours") == p.algorithms.end())
      throw InputError(
          "the cost model (--frame-ms, --tri-rate) fits the adaptation cost of 'ours': add it to --algorithms");
  }
  if (a.controlFrames > 100000) throw InputError("--control-frames must be at most 100000");
  if (!(a.loadStep > 0.0) || !(a.loadStep <= 100.0)) throw InputError("--load-step must be in (0, 100]");
  return p;
}

// The scene bench --render draws the cuts with, in a headless context it makes.
std::unique_ptr<gl::AtlasScene> benchScene(const BenchArgs& a, const BenchPlan& p, const AtlasView& atlas,
                                           std::unique_ptr<gl::EglContext>& context) {
  context = gl::EglContext::create();
  spdlog::info("OpenGL: {} ({})", context->renderer(), context->version());
  gl::SceneOptions so;
  so.width = p.width;
  so.height = p.height;
  // The pool holds every budget's cuts.
  so.minNodeRoom = uint32_t(*std::max_element(p.nodeBudgets.begin(), p.nodeBudgets.end()));
  so.gpuCacheBytes = a.gpuCache == "auto" ? 0 : parseBytes("--gpu-cache", a.gpuCache);
  auto scene = std::make_unique<gl::AtlasScene>(atlas, so);
  spdlog::info("--render: a page pool of {} pages in {} texture array(s), room for cuts of {} nodes",
               scene->renderer().pageCapacity(), scene->renderer().pageArrays(), scene->nodeRoom());
  if (so.gpuCacheBytes > 0 && scene->nodeRoom() < so.minNodeRoom)
    spdlog::warn(
        "--gpu-cache {} holds cuts of {} nodes: the cuts of larger node budgets draw without some of their "
        "pages (their draw_ms is not a full frame's)",
        a.gpuCache, scene->nodeRoom());
  return scene;
}

// Every configuration (node budget x triangle budget x algorithm) over every frame and pass: one
// row each, drawn too where there is a scene.
std::vector<std::vector<Row>> runConfigurations(const BenchArgs& a, const BenchPlan& p, const Hierarchy& hier,
                                                const std::vector<Camera>& cams, const std::vector<ViewParams>& views,
                                                gl::AtlasScene* scene) {
  const bool budgetMode = p.budgetMode;
  std::vector<std::vector<Row>> configs;
  bool warnedBelowRoots = false;
  for (uint64_t maxNodes : p.nodeBudgets) {
    for (uint64_t maxTris : p.triBudgets) {
      for (const std::string& algo : p.algorithms) {
        Adapter adapt;
        if (budgetMode)
          adapt = makeBudgetAdapter(hier, algo, uint32_t(maxNodes), maxTris, a.maxRounds);
        else
          adapt = makeErrorAdapter(hier, algo, uint32_t(maxNodes), a.tolerance);
        std::vector<Row> rows;
        for (uint32_t rep = 0; rep < a.repeat; ++rep) {
          for (size_t i = 0; i < cams.size(); ++i) {
            Row r;
            r.algorithm = algo;
            r.maxNodes = uint32_t(maxNodes);
            r.maxTriangles = maxTris;
            r.repeat = rep;
            r.frame = uint32_t(i);
            const Cut& cut = adapt(views[i], r);
            measureCut(hier, cut, views[i], r);
            if (r.budgetBelowRoots && !warnedBelowRoots) {
              spdlog::warn(
                  "node budget {} is below the {} visible {} (frame {}): no cut has fewer "
                  "nodes, so such frames draw the visible roots (root_floor, budget_below_roots in "
                  "bench.csv)",
                  maxNodes, r.rootFloor, hier.groups.empty() ? "chart roots" : "top groups", i);
              warnedBelowRoots = true;
            }
            if (scene) r.drawMs = scene->drawCut(cams[i], cut).drawMs;
            rows.push_back(std::move(r));
          }
        }
        configs.push_back(std::move(rows));
      }
    }
  }
  return configs;
}

// bench.csv: one row per frame per configuration.
void writeBenchCsv(const BenchArgs& a, bool budgetMode, const std::vector<std::vector<Row>>& configs,
                   const fs::path& out) {
  std::string csv =
      "mode,algorithm,max_nodes,max_triangles,tolerance_px,frame,adapt_us,nodes,triangles,max_error_px,"
      "mean_error_px,splits,merges,refines,coarsens,budget_bound,repeat,constraint_splits,draw_ms,root_floor,"
      "budget_below_roots\n";
  for (const auto& rows : configs)
    for (const Row& r : rows)
      csv += fmt::format("{},{},{},{},{},{},{:.3f},{},{},{:.5f},{:.5f},{},{},{},{},{},{},{},{},{},{}\n", a.mode,
                         r.algorithm, r.maxNodes, budgetMode ? std::to_string(r.maxTriangles) : std::string(),
                         optNum(!budgetMode, a.tolerance, "{}"), r.frame, r.adaptUs, r.nodes, r.triangles, r.maxErrorPx,
                         r.meanErrorPx, r.splits, r.merges, r.refines, r.coarsens, int(r.budgetBound), r.repeat,
                         r.constraintSplits, optNum(!std::isnan(r.drawMs), r.drawMs), r.rootFloor,
                         int(r.budgetBelowRoots));
  atomicWriteFile(out / "bench.csv", csv.data(), csv.size());
}

// summary.csv: per configuration, means over frames; printed as a table too.
std::vector<Summary> writeSummary(const BenchArgs& a, bool budgetMode, const std::vector<std::vector<Row>>& configs,
                                  const fs::path& out) {
  std::vector<Summary> sums;
  for (const auto& rows : configs) sums.push_back(summarize(rows));
  std::string sum =
      "mode,algorithm,max_nodes,max_triangles,tolerance_px,frames,adapt_us_mean,nodes_mean,nodes_max,"
      "triangles_mean,triangles_max,max_error_px_mean,max_error_px_p50,max_error_px_p95,max_error_px_max,"
      "mean_error_px_mean,budget_bound_frac,draw_ms_mean,root_floor_max,budget_below_roots_frac\n";
  for (const Summary& s : sums)
    sum += fmt::format(
        "{},{},{},{},{},{},{:.3f},{:.2f},{},{:.1f},{},{:.5f},{:.5f},{:.5f},{:.5f},{:.5f},{:.3f},{},{},"
        "{:.3f}\n",
        a.mode, s.algorithm, s.maxNodes, budgetMode ? std::to_string(s.maxTriangles) : std::string(),
        optNum(!budgetMode, a.tolerance, "{}"), s.frames, s.adaptUs, s.nodes, s.nodesMax, s.triangles, s.trianglesMax,
        s.errMean, s.errP50, s.errP95, s.errMax, s.meanErr, s.boundFrac, optNum(a.render, s.drawMs), s.rootFloorMax,
        s.belowRootsFrac);
  atomicWriteFile(out / "summary.csv", sum.data(), sum.size());

  std::cout << fmt::format("{:>8} {:>10} {:>12} {:>10} {:>12} {:>10} {:>10} {:>10}\n", "algo", "max_nodes", "max_tris",
                           "adapt_us", "nodes", "triangles", "err_p50", "err_p95");
  for (const Summary& s : sums)
    std::cout << fmt::format("{:>8} {:>10} {:>12} {:>10.1f} {:>12.1f} {:>10.0f} {:>10.3f} {:>10.3f}\n", s.algorithm,
                             s.maxNodes, budgetMode ? std::to_string(s.maxTriangles) : std::string("-"), s.adaptUs,
                             s.nodes, s.triangles, s.errP50, s.errP95);
  return sums;
}

// Of the swept budgets of "ours", the one of least mean error whose predicted frame time
// (a0 + b * nodes microseconds of adaptation, triangles at --tri-rate) fits --frame-ms.
void chooseBudgets(const BenchArgs& a, const std::vector<Summary>& sums, double a0, double b, nlohmann::json& cm) {
  nlohmann::json cands = nlohmann::json::array();
  const Summary* best = nullptr;
  double bestMs = 0;
  for (const Summary& s : sums) {
    if (s.algorithm != "ours") continue;
    const double ms = (a0 + b * s.maxNodes) * 1e-3 + double(s.maxTriangles) / a.triRate * 1e3;
    const double msMean = (a0 + b * s.nodes) * 1e-3 + s.triangles / a.triRate * 1e3;
    const bool fits = ms <= a.frameMs;
    cands.push_back({{"max_nodes", s.maxNodes},
                     {"max_triangles", s.maxTriangles},
                     {"predicted_ms", ms},
                     {"predicted_ms_at_mean_use", msMean},
                     {"max_error_px_mean", s.errMean},
                     {"fits", fits}});
    if (fits &&
        (!best || s.errMean < best->errMean || (s.errMean == best->errMean && s.maxTriangles < best->maxTriangles))) {
      best = &s;
      bestMs = ms;
    }
  }
  cm["frame_ms"] = a.frameMs;
  cm["tri_rate"] = a.triRate;
  cm["candidates"] = cands;
  if (best) {
    cm["choice"] = {{"max_nodes", best->maxNodes},
                    {"max_triangles", best->maxTriangles},
                    {"predicted_ms", bestMs},
                    {"max_error_px_mean", best->errMean}};
    std::cout << fmt::format(
        "cost model: for {} ms at {:.3g} triangles/s use --nodes {} --triangles {} (predicted {:.3f} ms, "
        "mean max error {:.3f} px)\n",
        a.frameMs, a.triRate, best->maxNodes, best->maxTriangles, bestMs, best->errMean);
  } else {
    cm["choice"] = nullptr;
    std::cout << fmt::format("cost model: no swept configuration fits {} ms at {:.3g} triangles/s\n", a.frameMs,
                             a.triRate);
  }
}

// The cost model: adapt_us = a + b * nodes, least squares over the rows of "ours"; in budget mode
// with --frame-ms and --tri-rate, the budgets it chooses.
nlohmann::json fitCostModel(const BenchArgs& a, const BenchPlan& p, const std::vector<std::vector<Row>>& configs,
                            const std::vector<Summary>& sums) {
  nlohmann::json cm;
  cm["mode"] = a.mode;
  double sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0, n = 0;
  for (const auto& rows : configs)
    for (const Row& r : rows)
      if (r.algorithm == "ours") {
        sx += r.nodes, sy += r.adaptUs, sxx += double(r.nodes) * r.nodes, sxy += r.nodes * r.adaptUs;
        syy += r.adaptUs * r.adaptUs, n += 1;
      }
  if (n == 0) {
    std::cout << "adaptation cost fit: skipped ('ours' not in --algorithms)\n";
    return cm;
  }
  const double varX = sxx - sx * sx / n, cov = sxy - sx * sy / n, varY = syy - sy * sy / n;
  const double b = varX > 0 ? cov / varX : (sx > 0 ? sy / sx : 0.0);
  const double a0 = varX > 0 ? (sy - b * sx) / n : 0.0;
  const double r2 = varX > 0 && varY > 0 ? cov * cov / (varX * varY) : 0.0;
  cm["adapt_fit"] = {{"intercept_us", a0}, {"us_per_node", b}, {"r2", r2}, {"rows", size_t(n)}};
  std::cout << fmt::format("adaptation cost fit (ours, {} frames): adapt_us = {:.2f} + {:.4f} * nodes (r^2 {:.3f})\n",
                           size_t(n), a0, b, r2);
  if (p.budgetMode && p.costModel) {
    chooseBudgets(a, sums, a0, b, cm);
  } else if (p.costModel) {
    std::cout << "cost model: --frame-ms/--tri-rate choose (nodes, triangles) in --mode budget only; "
                 "error mode reports the per-node cost fit\n";
  }
  return cm;
}

int runBench(const BenchArgs& a) {
  const BenchPlan p = benchPlan(a);
  const AtlasView atlas = openAtlas(a.atlas, a.camera.maxRoots);
  const Hierarchy& hier = atlas.hierarchy;
  const std::vector<Camera> cams = loadCameras(a.camera, atlas);
  if (cams.empty()) throw InputError(a.camera.path + ": the camera path has no frames");
  std::vector<ViewParams> views;
  for (const Camera& c : cams) views.push_back(makeViewParams(c, p.width, p.height));

  const fs::path out = a.output;
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) throw InputError(a.output + ": cannot create output directory");
  if (::access(out.c_str(), W_OK) != 0) throw InputError(a.output + ": output directory is not writable");

  std::unique_ptr<gl::EglContext> context;
  std::unique_ptr<gl::AtlasScene> scene;
  if (a.render) scene = benchScene(a, p, atlas, context);

  std::cout << fmt::format("bench {} mode: {} frames x {} pass(es), {}x{}, {} node budget(s){}, algorithms {}\n",
                           a.mode, cams.size(), a.repeat, p.width, p.height, p.nodeBudgets.size(),
                           p.budgetMode ? fmt::format(" x {} triangle budget(s)", p.triBudgets.size())
                                        : fmt::format(", tolerance {} px", a.tolerance),
                           a.algorithms);
  const std::vector<std::vector<Row>> configs = runConfigurations(a, p, hier, cams, views, scene.get());
  writeBenchCsv(a, p.budgetMode, configs, out);
  const std::vector<Summary> sums = writeSummary(a, p.budgetMode, configs, out);
  nlohmann::json cm = fitCostModel(a, p, configs, sums);
  if (p.budgetMode && p.costModel && a.controlFrames > 0) {
    const ControlledRun run = runFrameController(hier, views, a);
    atomicWriteFile(out / "controller.csv", run.csv.data(), run.csv.size());
    cm["controller"] = run.summary;
    std::cout << run.report;
  }
  const std::string json = cm.dump(1) + "\n";
  atomicWriteFile(out / "cost_model.json", json.data(), json.size());

  std::cout << fmt::format("wrote {}/bench.csv ({} rows), summary.csv, cost_model.json\n", a.output,
                           configs.size() * cams.size() * a.repeat);
  std::cout << fmt::format("plots (python3 + matplotlib): python3 scripts/plot_bench.py '{}'\n", a.output);
  return 0;
}

}  // namespace gimlod

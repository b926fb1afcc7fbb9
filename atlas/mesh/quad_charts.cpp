// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (quadrangulate, resample); Purnomo, Cohen,
// Kumar, "Seamless Texture Atlases", SGP 2004.
#include "atlas/mesh/quad_charts.h"

#include <algorithm>
#include <bit>
#include <functional>
#include <limits>
#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <glm/geometric.hpp>
#include <spdlog/spdlog.h>
#include <tbb/task_arena.h>

#include "atlas/mesh/layout_refine.h"
#include "core/stage_meter.h"

namespace fs = std::filesystem;

namespace gimlod {

// Ends the meter's running stage as `name`, and logs it.
void finishStage(StageMeter& meter, const std::string& name) {
  const StageTiming& s = meter.finish(name);
  spdlog::info("stage {:<10} {:8.2f} s wall {:8.2f} s cpu  peak RSS {:7.1f} MiB", name, s.seconds, s.cpuSeconds,
               double(s.peakRssBytes) / (1 << 20));
}

uint64_t meshRepairWorkBudget(double repairBudget, uint64_t layoutTriangles) {
  return uint64_t(std::llround(repairBudget * double(std::min(layoutTriangles, kRepairTrianglesCounted))));
}

double meshSampleCap(uint64_t triangles) { return std::max(kMaxSamplesPerTriangle * double(triangles), kMinSampleCap); }

uint32_t patchChartSizeForDensity(uint64_t triangles, uint64_t quads, uint32_t smallest, uint32_t largest) {
  const double wanted = kSamplesPerTriangle * double(triangles);
  uint32_t intervals = smallest - 1;
  while (intervals + 1 < largest && double(std::max<uint64_t>(quads, 1)) * intervals * intervals < wanted)
    intervals *= 2;
  return intervals + 1;
}

uint32_t meshChartSizeForDensity(uint64_t triangles, uint64_t quads) {
  return patchChartSizeForDensity(triangles, quads, 65, kMaxDensityChartSize);
}

namespace {

// The option's name as the options' front end spells it in messages.
std::string spelled(const QuadChartOptions& o, std::string_view name) {
  return o.spellOption ? o.spellOption(name) : std::string(name);
}

// The diagonal of the layout's bounding box.
double layoutDiagonal(const PatchLayout& layout) {
  MeshBounds b;
  for (const glm::vec3& p : layout.positions) b.extend(p);
  return b.empty() ? 0.0 : glm::length(glm::dvec3(b.max) - glm::dvec3(b.min));
}

// Samples per layout triangle in `charts` charts of chartSize^2 samples (intervals squared).
// Whether `charts` charts of chartSize^2 samples reach the samples a layout may grow to
// (meshSampleCap).
bool atSampleCap(const PatchLayout& layout, uint64_t charts, uint32_t chartSize) {
  return double(charts) * double(chartSize - 1) * double(chartSize - 1) >= meshSampleCap(layout.triangles.size());
}

double samplesPerTriangle(const PatchLayout& layout, uint64_t charts, uint32_t chartSize) {
  return double(charts) * double(chartSize - 1) * double(chartSize - 1) /
         double(std::max<size_t>(layout.triangles.size(), 1));
}

// The quad charts of a layout (before any repair).
uint64_t layoutQuadCount(const PatchLayout& layout, QuadLayout quads) {
  uint64_t n = 0;
  for (const Patch& pa : layout.patches) n += patchQuadCount(uint32_t(pa.sides.size()), quads);
  return n;
}

uint64_t threadCount(const QuadChartOptions& o) {
  return o.threads ? o.threads : uint64_t(std::max(1, tbb::this_task_arena::max_concurrency()));
}

uint64_t bytesPerSample(const PatchLayout& layout) { return layout.colours.empty() ? 16 : 20; }

// A patch's charts (up to 8 quads) and their working arrays at o.chartSize, on every thread.
uint64_t chartsInFlightBytes(const PatchLayout& layout, const QuadChartOptions& o) {
  return threadCount(o) * uint64_t(o.chartSize) * o.chartSize * (8 * bytesPerSample(layout) + 32);
}

// Refuses a chart size whose charts cannot be made: each chart's samples go to a spill file in
// the staging directory once measured, and are read back one chart at a time per thread to be
// written, so what must fit is a patch's charts (up to 8 quads) and their working arrays on every
// thread at once in memory, and the spill plus the chart files (with their pyramids) on disk.
void checkChartRoom(const PatchLayout& layout, uint64_t quads, const QuadChartOptions& o, const fs::path& dir) {
  const uint64_t samples = uint64_t(o.chartSize) * o.chartSize;
  const uint64_t perSample = bytesPerSample(layout);
  const uint64_t threads = threadCount(o);
  const uint64_t inFlight = chartsInFlightBytes(layout, o);
  if (inFlight > o.maxMemory)
    throw InputError(
        fmt::format("{}: quad charts of {}^2 samples need {:.1f} GiB of geometry images at once "
                    "({} threads), more than {} ({:.1f} GiB): lower {} or {}, or raise {}",
                    o.input.string(), o.chartSize, double(inFlight) / double(1ull << 30), threads,
                    optionRef("maxMemory"), double(o.maxMemory) / double(1ull << 30), optionRef("chartSize"),
                    optionRef("threads"), optionRef("maxMemory")));
  const uint64_t disk = quads * samples * perSample * 3;  // the spill, and chart files a third larger
  std::error_code ec;
  const fs::space_info space = fs::space(dir, ec);
  if (!ec && disk > space.available)
    throw InputError(
        fmt::format("{}: {} quad charts of {}^2 samples need about {:.1f} GiB of disk in {}, which has "
                    "{:.1f} GiB free: lower {} or {}",
                    o.input.string(), quads, o.chartSize, double(disk) / double(1ull << 30), dir.parent_path().string(),
                    double(space.available) / double(1ull << 30), optionRef("chartSize"), optionRef("patches")));
}

// What the patches' parameterizations may hold at once (ParamGate): maxMemory less what the
// process holds now (once the heap has handed freed pages back), the parameterization cache's
// share (maxMemory / 8) and the charts in flight at o.chartSize.
uint64_t paramGateBudget(const PatchLayout& layout, const QuadChartOptions& o) {
  releaseFreedMemory();
  const uint64_t taken = residentBytes() + o.maxMemory / 8 + chartsInFlightBytes(layout, o);
  return o.maxMemory > taken ? o.maxMemory - taken : 0;
}

// Logs (at debug level) every chart left with flipped texels: its patch's size and sides (edges
// and length of each), so that where folds remain can be told apart.
void logFoldingCharts(const PatchLayout& layout, const GeometryImageSet& set) {
  for (const GeometryImage& g : set.charts) {
    if (g.quality.flippedTexels == 0) continue;
    const Patch& patch = layout.patches[g.patch];
    std::string sides;
    for (const PatchSide& side : patch.sides) {
      sides += fmt::format(" {}:{:.4g}{}", side.vertices.size() - 1, sideLength(layout, side),
                           side.neighbourPatch < 0 ? "(open)" : "");
    }
    spdlog::debug("chart {} of patch {} ({} triangles, {} sides): {} flipped texels; sides (edges:length){}", g.quad,
                  g.patch, patch.triangles.size(), patch.sides.size(), g.quality.flippedTexels, sides);
  }
}

// The chart size the auto quad layout goes on to when neither layout met the bound at `current`
// (0: none). As many doublings as the smaller sampling error `error` asks of `bound` if each
// quarters it (a smooth surface's interpolation error goes with the spacing squared; on the shared
// scans a doubling took it down 2.2 to 2.6 times), at least one: a size that cannot meet the bound
// is not repaired in vain (the horse: 65^2 straight to 257^2). Fewer while the charts would pass
// kMaxDensityChartSize or kMaxSamplesPerTriangle (counted with `charts`, the fewer layout's; one
// doubling may cross it, as the one-layout flow's), or the room checkChartRoom allows.
uint32_t grownChartSize(const PatchLayout& layout, const QuadChartOptions& options, uint32_t current, uint64_t charts,
                        double error, double bound, const fs::path& dir) {
  if (current >= kMaxDensityChartSize || atSampleCap(layout, charts, current)) return 0;
  // The least k >= 1 with bound * 4^k >= error, by exact multiplications.
  uint32_t asked = 1;
  for (double reach = 4.0 * std::max(bound, 1e-300); reach < error && asked < 64; reach *= 4.0) ++asked;
  QuadChartOptions larger = options;
  larger.chartSize = current;
  for (uint32_t k = 0; k < asked && larger.chartSize < kMaxDensityChartSize &&
                       (k == 0 || !atSampleCap(layout, charts, larger.chartSize));
       ++k)
    larger.chartSize = 2 * larger.chartSize - 1;
  for (; larger.chartSize > current; larger.chartSize = (larger.chartSize + 1) / 2) {
    try {
      checkChartRoom(layout, layoutQuadCount(layout, QuadLayout::kKites), larger, dir);
      return larger.chartSize;
    } catch (const InputError& e) {
      spdlog::info("chart size not {}: {}", larger.chartSize,
                   options.spellOption ? e.message(options.spellOption) : std::string(e.what()));
    }
  }
  return 0;
}

// The stats' quad map name.
std::string quadMapName(MeshQuadMap m) {
  return m == MeshQuadMap::kStretch ? "stretch" : m == MeshQuadMap::kFolding ? "folding" : "bilinear";
}

// The resampler's options for `quads` from the quad chart options (the chart size set by the
// caller), for a layout of `bounds`.
ResampleOptions resampleOptions(const QuadChartOptions& o, QuadLayout quads, ChartSpill* spill,
                                const MeshBounds& bounds) {
  ResampleOptions ro;
  if (o.positionStep) ro.minSampleGap = 2.0 * o.positionStep(bounds);
  ro.threads = o.threads;
  ro.spill = spill;
  ro.quads = quads;
  ro.unfold = o.unfold;
  ro.quadMap = o.quadMap == MeshQuadMap::kStretch   ? QuadMap::kStretch
               : o.quadMap == MeshQuadMap::kFolding ? QuadMap::kFolding
                                                    : QuadMap::kBilinear;
  return ro;
}

// The patches with an odd side count.
std::vector<uint32_t> oddPatches(const PatchLayout& layout) {
  std::vector<uint32_t> odd;
  for (uint32_t p = 0; p < layout.patches.size(); ++p)
    if (layout.patches[p].sides.size() % 2 == 1) odd.push_back(p);
  return odd;
}

// Logs, at debug level, each patch left with an odd side count: its sides' edges and neighbours.
void logOddPatches(const PatchLayout& layout) {
  if (!spdlog::should_log(spdlog::level::debug)) return;
  for (const uint32_t p : oddPatches(layout)) {
    std::string sides;
    for (const PatchSide& s : layout.patches[p].sides)
      sides += fmt::format(" [{} edges, {}]", s.vertices.size() - 1,
                           s.neighbourPatch < 0 ? std::string("open")
                                                : fmt::format("patch {} of {} sides", s.neighbourPatch,
                                                              layout.patches[s.neighbourPatch].sides.size()));
    spdlog::debug("odd patch {} ({} triangles):{}", p, layout.patches[p].triangles.size(), sides);
  }
}

// Makes every patch's side count even for the sides quad layout (st.evenSideCorners the corners
// added); false when some patch cannot have one. With `repair`, where evenSides leaves patches odd,
// the sides of one edge of the patches left odd, and if need be of the patches within 2, 4 and 8
// links of them (for the chains between), are split at their midpoints so that they can take a
// corner (splitSingleEdgeSides; st.sideEdgesSplit), evenSides trying again after each step; the
// surface is the same. If patches are still odd, the triangles and vertices are as they were (the
// caller restores the patches).
bool evenLayout(PatchLayout& layout, MeshResampleStats& st, bool repair) {
  const uint32_t holeCorners = splitTwoSidedHoles(layout);
  EvenSidesResult even = evenSides(layout);
  st.evenSideCorners = holeCorners + even.corners;
  if (even.oddLeft != 0 && repair) {
    const size_t positions = layout.positions.size(), colours = layout.colours.size();
    const std::vector<std::array<uint32_t, 3>> triangles = layout.triangles;
    auto again = [&] {
      even = evenSides(layout);
      st.evenSideCorners += even.corners;
      return even.oddLeft == 0;
    };
    bool done = false;
    for (uint32_t reach = 0; reach <= 8 && !done; reach = std::max(2 * reach, 2u)) {
      const uint32_t split = splitSingleEdgeSides(layout, patchesNear(layout, oddPatches(layout), reach));
      st.sideEdgesSplit += split;
      done = split > 0 && again();
    }
    if (even.oddLeft != 0) {
      layout.triangles = triangles;
      layout.positions.resize(positions);
      layout.colours.resize(colours);
      st.sideEdgesSplit = 0;
    } else {
      spdlog::info("side counts made even with {} edges split at their midpoints", st.sideEdgesSplit);
    }
  }
  if (even.oddLeft != 0) {
    logOddPatches(layout);
    return false;
  }
  st.evenSideCorners += mendTwoChartCorners(layout).corners;
  return true;
}

// In the sides layout, the corners where only two charts meet (st.twoQuadCorners), with a warning.
void countTwoQuadCorners(const PatchLayout& layout, const QuadChartOptions& o, MeshResampleStats& st) {
  if (!st.sideQuads) return;
  st.twoQuadCorners = twoQuadCorners(layout);
  if (st.twoQuadCorners > 0)
    spdlog::warn(
        "{}: {} corners of the sides quad layout have only two charts meeting (their corner texels fold "
        "flat onto each other)",
        o.input.string(), st.twoQuadCorners);
}

// The figures a build reports of its charts, from the set.
void setChartFigures(const GeometryImageSet& set, MeshResampleStats& st) {
  st.charts = set.charts.size();
  st.param = set.param;
  st.image = set.image;
  st.perChart.clear();
  st.perChart.reserve(set.charts.size());
  for (const GeometryImage& g : set.charts) st.perChart.push_back({g.patch, g.quad, g.side(set.chartSize), g.quality});
}

// One resampling and repair of `layout` in quad layout `quads`: its patches change (side counts
// made even for the sides layout, the repair's cuts). Stages "resample" and "chart_repair", named
// with `suffix`. With the sides layout, false in `evened` (and nothing else done) when some patch
// cannot be given an even side count. A chart size chosen by density is `size` when given (else
// meshChartSizeForDensity's), and doubled where the bound asks it only with `grow`.
ResampledMesh resampleInLayout(PatchLayout& layout, const QuadChartOptions& options, QuadLayout quads,
                               const fs::path& dir, StageMeter& meter, const std::string& suffix, bool* evened,
                               uint32_t size = 0, bool grow = true) {
  ResampledMesh r;
  MeshResampleStats& st = r.stats;
  QuadChartOptions o = options;
  if (o.maxSampleError == kAutoSampleError) o.maxSampleError = o.chartSize == 0 ? kDefaultSampleError : 0.0;
  st.sideQuads = quads == QuadLayout::kSides;
  st.unfold = o.unfold;
  st.quadMap = quadMapName(o.quadMap);
  // One chart size: the auto flow builds kites from the charted patches too, so no repair may
  // change the triangles.
  if (st.sideQuads && !(*evened = evenLayout(layout, st, false))) return r;
  const uint64_t quadCharts = layoutQuadCount(layout, quads);
  if (o.chartSize == 0) {
    o.chartSize = meshChartSizeForDensity(layout.triangles.size(), quadCharts);
    st.chartSizeByDensity = true;
    st.densityChartSize = o.chartSize;
    if (size > 0) o.chartSize = size;
    spdlog::info("chart size {}{} for {} quad charts ({}) of {} triangles ({:.1f} samples per triangle)", o.chartSize,
                 o.chartSize != st.densityChartSize
                     ? fmt::format(" (doubled from the density's {})", st.densityChartSize)
                     : std::string(),
                 quadCharts, st.sideQuads ? "sides" : "kites", layout.triangles.size(),
                 samplesPerTriangle(layout, quadCharts, o.chartSize));
  }
  st.chartSize = o.chartSize;
  checkChartRoom(layout, quadCharts, o, dir);

  // Quads, parameterization and resampling.
  const fs::path spillFile = dir / (st.sideQuads ? "samples_sides.tmp" : "samples_kites.tmp");
  r.spill = std::make_unique<ChartSpill>(spillFile, !layout.colours.empty());
  for (const glm::vec3& q : layout.positions) r.bounds.extend(q);
  ResampleOptions ro = resampleOptions(o, quads, r.spill.get(), r.bounds);
  ro.chartSize = o.chartSize;
  ParamGate gate(paramGateBudget(layout, o));
  ro.gate = &gate;
  GeometryImageSet first = resampleLayout(layout, ro);
  // Doubles the chart size (saying `why`) and resamples the layout into `first`, its patches
  // first set to `restore` if given; false, unchanged, when the larger charts do not fit
  // (checkChartRoom with `charts` quad charts).
  auto doubleChartSize = [&](uint64_t charts, const std::string& why, const std::vector<Patch>* restore) {
    QuadChartOptions larger = o;
    larger.chartSize = 2 * o.chartSize - 1;
    try {
      checkChartRoom(layout, charts, larger, dir);
    } catch (const InputError& e) {
      spdlog::info("chart size stays {}: {}", o.chartSize,
                   o.spellOption ? e.message(o.spellOption) : std::string(e.what()));
      return false;
    }
    spdlog::info("chart size {} -> {}: {}", o.chartSize, larger.chartSize, why);
    o.chartSize = larger.chartSize;
    if (restore) layout.patches = *restore;
    first = GeometryImageSet{};
    r.spill.reset();  // (removes its file)
    r.spill = std::make_unique<ChartSpill>(spillFile, !layout.colours.empty());
    ro.chartSize = o.chartSize;
    ro.spill = r.spill.get();
    first = resampleLayout(layout, ro);
    return true;
  };
  // A chart size chosen by density is doubled (and the layout resampled) while the patches whose
  // charts sample the surface more coarsely than maxSampleError hold more than
  // kCoarseSurfaceToDouble of its triangles, up to kMaxSamplesPerTriangle: the repair then has a
  // few patches to cut, not many.
  const double diagonal = layoutDiagonal(layout);
  const double maxError = o.maxSampleError * diagonal;
  while (grow && st.chartSizeByDensity && maxError > 0.0 && o.chartSize < kMaxDensityChartSize) {
    const std::vector<uint8_t> over = patchesOverSampleError(first, layout.patches.size(), maxError);
    uint64_t overTriangles = 0;
    for (uint32_t p = 0; p < layout.patches.size(); ++p)
      overTriangles += over[p] ? layout.patches[p].triangles.size() : 0;
    if (double(overTriangles) <= kCoarseSurfaceToDouble * double(layout.triangles.size()) ||
        atSampleCap(layout, first.charts.size(), o.chartSize))
      break;
    const std::string why = fmt::format(
        "patches with {:.0f}% of the triangles sample the surface more coarsely than {:.4f}% of the diagonal",
        100.0 * double(overTriangles) / double(layout.triangles.size()), 100.0 * o.maxSampleError);
    if (!doubleChartSize(quadCharts, why, nullptr)) break;
  }
  st.chartSize = o.chartSize;
  finishStage(meter, "resample" + suffix);
  // Each repair cut adds working memory: the repair stops cutting once the process holds 3/4 of
  // maxMemory, or once it has parameterized repairBudget times the triangles again.
  const uint64_t layoutTriangles = layout.triangles.size();
  ChartRepairOptions repair;
  repair.rounds = o.repairRounds;
  repair.workBudget = meshRepairWorkBudget(o.repairBudget, layoutTriangles);
  repair.maxSampleError = maxError;
  st.maxSampleError = repair.maxSampleError;
  // A chart size chosen by density is also doubled, and the layout resampled and repaired again,
  // when the repair cannot bring every chart within maxSampleError by cutting (the sides layout's
  // cuts must keep side counts even and leave no two-chart corner, so some patches cannot be cut).
  const std::vector<Patch> unrepaired = layout.patches;
  for (;;) {
    r.set = repairCharts(layout, std::move(first), ro, repair, &st.repair,
                         [&] { return residentBytes() < o.maxMemory / 4 * 3; });
    if (!grow || !st.chartSizeByDensity || !(maxError > 0.0) || r.set.image.sampleError <= maxError ||
        st.repair.stoppedForWork || st.repair.stoppedForMemory || o.chartSize >= kMaxDensityChartSize ||
        atSampleCap(layout, r.set.charts.size(), o.chartSize))
      break;
    const std::string why =
        fmt::format("the repair left a sampling error of {:.4f}% of the diagonal (bound {:.4f}%)",
                    100.0 * r.set.image.sampleError / std::max(diagonal, 1e-300), 100.0 * o.maxSampleError);
    if (!doubleChartSize(layoutQuadCount(layout, quads), why, &unrepaired)) break;
    ++st.repairDoublings;
    st.repair = {};
  }
  st.chartSize = o.chartSize;
  const GeometryImageSet& set = r.set;
  if (spdlog::should_log(spdlog::level::debug)) logFoldingCharts(layout, set);
  const std::string left =
      fmt::format("{} flipped texels left, largest sampling error {:.4f}% of the diagonal", set.image.flippedTexels,
                  100.0 * set.image.sampleError / std::max(diagonal, 1e-300));
  if (st.repair.stoppedForMemory)
    spdlog::warn("{}: the chart repair stopped at 3/4 of {} ({}); raise {} to repair more", o.input.string(),
                 spelled(o, "maxMemory"), left, spelled(o, "maxMemory"));
  st.repairWork = double(st.repair.trianglesWholeRounds + st.repair.trianglesTrials) /
                  double(std::max<uint64_t>(layoutTriangles, 1));
  if (st.repair.stoppedForWork)
    spdlog::warn(
        "{}: the chart repair stopped at its budget, {:.2f} times the surface's triangles parameterized "
        "again ({}); raise {} to repair more",
        o.input.string(), st.repairWork, left, spelled(o, "repairBudget"));
  st.patches = layout.patches.size();
  countTwoQuadCorners(layout, o, st);
  finishStage(meter, "chart_repair" + suffix);
  setChartFigures(set, st);
  return r;
}

// At most this many cuts lead from a charted patch to any of its parts under per-patch sizing.
constexpr uint32_t kMaxSizingCuts = 4;
// The L2 stretch past which a patch's parameterization is cut before it is doubled: doubling from
// the smallest density size (65^2) to the largest (kMaxDensityChartSize) shrinks texels 16 times,
// so a map that squeezes the surface more than that cannot be sampled within the bound by growing.
// (The mean-value map of a tube closed at one end squeezes its tip exponentially in the tube's
// length; the shared scans' patches stay under 6.)
constexpr double kCollapsedStretch = double(kMaxDensityChartSize - 1) / 64.0;
// A doubling that keeps this share of a patch's sampling error or more is flat (a smooth surface's
// error falls about four times).
constexpr double kFlatDoubling = 0.9;

// Per-patch sizing (MeshSizing::kPatch): each patch's charts and size, and the rounds that
// resample them.
struct PatchSizing {
  struct Entry {
    uint32_t size = 0;                  // its charts' side
    std::vector<GeometryImage> charts;  // its quads' charts, at that size
    PatchResampleStats stats;
    // Before its last doubling (previousSize 0: none), to go back to where the doubling made
    // folds: its size, charts and stats.
    uint32_t previousSize = 0;
    std::vector<GeometryImage> previousCharts;
    PatchResampleStats previousStats;
    bool todo = false;        // to be resampled at `size`
    bool settled = false;     // neither doubled nor cut again
    bool uncuttable = false;  // no cut was found, or none that folds less
    bool cutAsked = false;    // it cannot grow: cut it next round
    // Doubled because it folds, no cut helps and it meets the bound: the finer texels are kept
    // only where they fold less (a fold narrower than a texel is the sampling's).
    bool grownForFolds = false;
    uint32_t cuts = 0;  // cuts on the way from a charted patch
    // Doublings in a row, up to its last, that lowered its sampling error by less than a tenth.
    uint32_t flatDoublings = 0;
  };
  PatchLayout& layout;
  ResampleOptions ro;
  std::vector<glm::dvec3> normals;  // layoutVertexNormals, once
  std::vector<Entry> patches;
  uint64_t trianglesParameterized = 0;
  uint64_t cutWork = 0;  // layout triangles the cuts' trials parameterized
  // The patches' parameterizations, kept for their next resampling (a doubling) when they fit.
  std::unique_ptr<ParamCache> params;
  // The smallest size a patch starts at, and the quad layout (for a patch's own start size).
  uint32_t smallest = 0;
  QuadLayout quads = QuadLayout::kSides;

  // The size patch p starts at: its own density's, from `smallest` up to `base`.
  uint32_t startSize(uint32_t p, uint32_t base) const {
    const Patch& patch = layout.patches[p];
    return patchChartSizeForDensity(patch.triangles.size(), patchQuadCount(uint32_t(patch.sides.size()), quads),
                                    std::min(smallest ? smallest : base, base), base);
  }

  // The worst sampling error of patch p's charts.
  double error(uint32_t p) const { return worstError(patches[p].charts); }
  // The samples the charts hold, (size - 1)^2 a chart.
  double samples() const {
    double n = 0.0;
    for (const Entry& e : patches) n += double(e.charts.size()) * double(e.size - 1) * double(e.size - 1);
    return n;
  }
  // Takes patch p's charts (and stats) out of `set`, a resampling of the current layout.
  void take(GeometryImageSet& set, uint32_t p) {
    Entry& e = patches[p];
    e.stats = set.patches[p];
    e.charts.clear();
    for (uint32_t i = 0; i < e.stats.quads; ++i) e.charts.push_back(std::move(set.charts[e.stats.firstChart + i]));
  }
  // Resamples the patches marked todo, a resampling per size.
  void resampleTodo() {
    std::vector<uint32_t> sizes;
    for (const Entry& e : patches)
      if (e.todo) sizes.push_back(e.size);
    std::sort(sizes.begin(), sizes.end());
    sizes.erase(std::unique(sizes.begin(), sizes.end()), sizes.end());
    for (const uint32_t s : sizes) {
      std::vector<uint8_t> only(patches.size(), 0);
      for (uint32_t p = 0; p < patches.size(); ++p) only[p] = patches[p].todo && patches[p].size == s;
      ResampleReuse reuse;
      reuse.normals = &normals;
      reuse.only = &only;
      reuse.params = params.get();
      ro.chartSize = s;
      GeometryImageSet part = resampleLayout(layout, ro, reuse);
      trianglesParameterized += part.trianglesParameterized;
      for (uint32_t p = 0; p < patches.size(); ++p)
        if (only[p]) take(part, p);
    }
    for (Entry& e : patches) e.todo = false;
  }
  // The worst sampling error and the flipped texels of charts.
  static double worstError(const std::vector<GeometryImage>& charts) {
    double worst = 0.0;
    for (const GeometryImage& g : charts) worst = std::max(worst, g.quality.sampleError);
    return worst;
  }
  static uint64_t flips(const std::vector<GeometryImage>& charts) {
    uint64_t n = 0;
    for (const GeometryImage& g : charts) n += g.quality.flippedTexels;
    return n;
  }
  // Doubles patch p's size, keeping its charts to go back to.
  void grow(uint32_t p) {
    Entry& e = patches[p];
    e.flatDoublings = e.previousSize > 0 && flatDoubling(e) ? e.flatDoublings + 1 : 0;
    e.previousSize = e.size;
    e.previousCharts = std::move(e.charts);
    e.previousStats = e.stats;
    e.size = 2 * e.size - 1;
    e.todo = true;
  }
  // Its last doubling lowered its sampling error by less than a tenth.
  static bool flatDoubling(const Entry& e) {
    return worstError(e.charts) >= kFlatDoubling * worstError(e.previousCharts);
  }
  // Puts patch p back at the size before its last doubling.
  void shrink(uint32_t p) {
    Entry& e = patches[p];
    e.size = e.previousSize;
    e.charts = std::move(e.previousCharts);
    e.stats = e.previousStats;
    e.previousSize = 0;
  }
  // Where a cut of a patch goes: through a fold of its charts, else across in halves, else at its
  // neck (kFirst); through the input vertex farthest from its charts (kWorstVertex); or through
  // its vertex farthest from its boundary (kDeepest), for a parameterization collapsed round a tip.
  enum class CutAt { kFirst, kWorstVertex, kDeepest };
  // Patch p's parameterization squeezes the surface more than doubling can make up for: its stretch
  // is past kCollapsedStretch, or its charts sample it more coarsely than `bound` where their
  // texels are already too short to halve.
  bool collapsed(uint32_t p, double bound) const {
    const Entry& e = patches[p];
    if (e.stats.param.stretchL2 > kCollapsedStretch) return true;
    return error(p) > bound && 0.5 * shortestTexelSide(e.charts) < ro.minSampleGap;
  }
  static double shortestTexelSide(const std::vector<GeometryImage>& charts) {
    double shortest = std::numeric_limits<double>::infinity();
    for (const GeometryImage& g : charts) shortest = std::min(shortest, g.quality.shortestTexelSide);
    return shortest;
  }
  // A layout triangle of patch p at the input vertex farthest from its charts' surface (~0u when
  // none is known).
  uint32_t worstTriangle(uint32_t p) const {
    const GeometryImage* worst = nullptr;
    for (const GeometryImage& g : patches[p].charts)
      if (g.quality.sampleErrorVertex != ~0u && (!worst || g.quality.sampleError > worst->quality.sampleError))
        worst = &g;
    if (!worst) return ~0u;
    return patchTriangleAt(layout, p, worst->quality.sampleErrorVertex);
  }
  // Cuts patch p (kFirst) through the first layout triangle its charts fold over
  // (splitPatchThrough), or where they do not fold in halves (halvePatch), or where no such cut
  // exists at its neck (splitPatchAtNeck); or (kWorstVertex) through a triangle at the input vertex
  // farthest from its charts. Its side counts are made even again for the sides layout without a
  // new two-chart corner. The parts start at
  // `base` and every patch the cut changed is marked to be resampled. False, the layout as it
  // was (`saved`, the patches before it), when no such cut exists.
  bool cut(uint32_t p, uint32_t base, bool sides, const std::vector<Patch>& saved, CutAt at) {
    const uint32_t cornersBefore = sides ? twoQuadCorners(layout) : 0;
    uint32_t fold = ~0u;
    for (const GeometryImage& g : patches[p].charts)
      if (fold == ~0u && !g.foldTriangles.empty()) fold = g.foldTriangles.front();
    // As the repair cuts (repairCharts): 9 sides at most in the sides layout, whose side counts
    // are made even after, and no part there with fewer than 4 border edges.
    const uint32_t maxSides = sides ? 9 : 8;
    bool done = false;
    if (at == CutAt::kDeepest) {
      done = splitPatchFromDeepest(layout, p, maxSides);
    } else if (at == CutAt::kWorstVertex) {
      const uint32_t worst = worstTriangle(p);
      if (worst == ~0u) return false;
      done = splitPatchThrough(layout, p, worst, maxSides);
    } else {
      done =
          fold != ~0u ? splitPatchThrough(layout, p, fold, maxSides) : halvePatch(layout, p, maxSides, sides ? 4 : 0);
      if (!done) layout.patches = saved;  // (a failed cut may have left a corner)
      done = done || splitPatchAtNeck(layout, p);
    }
    if (!done) layout.patches = saved;
    if (done) {
      std::vector<uint32_t> parts{p};
      for (uint32_t q = uint32_t(saved.size()); q < layout.patches.size(); ++q) parts.push_back(q);
      moveSideEars(layout, parts, false);
      done = !sides || (evenSides(layout).oddLeft == 0 && alignSpokes(layout) <= cornersBefore);
    }
    if (!done) {
      layout.patches = saved;
      return false;
    }
    const uint32_t cuts = patches[p].cuts + 1;
    patches.resize(layout.patches.size());
    for (uint32_t q = 0; q < layout.patches.size(); ++q) {
      if (q < saved.size() && q != p && patchSamplesAlike(saved[q], layout.patches[q], q)) continue;
      Entry& e = patches[q];
      if (q == p || q >= saved.size()) {
        e.size = base;
        e.cuts = cuts;
      }
      e.previousSize = 0;
      e.previousCharts.clear();
      e.settled = e.uncuttable = e.cutAsked = false;
      e.todo = true;
    }
    return true;
  }
  // The flipped texels of the patches flagged in `which`.
  uint64_t flipsOf(const std::vector<uint8_t>& which) const {
    uint64_t n = 0;
    for (uint32_t q = 0; q < which.size() && q < patches.size(); ++q)
      if (which[q]) n += flips(patches[q].charts);
    return n;
  }
  // cut(p), kept only if the patches it changed, resampled at once, fold less than they did (where
  // `folding`), or no more (else). A patch whose sampling error is over twice the bound (the
  // Hausdorff distance's) is missing surface, not detail: there a cut is also kept where the
  // patches it changed halve that error, folds or not (their folds are cut or grown out in the
  // rounds after), and if the first cut is not kept, the cut through its worst vertex is tried.
  // False, the layout and the charts as they were, otherwise.
  bool tryCut(uint32_t p, uint32_t base, bool sides, bool folding, double bound) {
    const double before = error(p);
    const bool missing = before > 2.0 * bound;
    if (collapsed(p, bound) && tryCutAt(p, base, sides, folding, CutAt::kDeepest, 0.5 * before)) return true;
    if (tryCutAt(p, base, sides, folding, CutAt::kFirst, missing ? 0.5 * before : 0.0)) return true;
    return missing && tryCutAt(p, base, sides, folding, CutAt::kWorstVertex, 0.5 * before);
  }
  // One cut of tryCut, also kept where the changed patches' worst error falls below `halved` (0:
  // never).
  bool tryCutAt(uint32_t p, uint32_t base, bool sides, bool folding, CutAt at, double halved) {
    const std::vector<Patch> saved = layout.patches;
    const std::vector<Entry> was = patches;
    if (!cut(p, base, sides, saved, at)) return false;
    std::vector<uint8_t> before(was.size(), 0), after(patches.size(), 0);
    for (uint32_t q = 0; q < patches.size(); ++q) {
      after[q] = patches[q].todo;
      if (q < was.size()) before[q] = patches[q].todo;
    }
    uint64_t flipsBefore = 0;
    for (uint32_t q = 0; q < was.size(); ++q)
      if (before[q]) flipsBefore += flips(was[q].charts);
    for (uint32_t q = 0; q < patches.size(); ++q)
      if (after[q]) cutWork += layout.patches[q].triangles.size();
    resampleTodo();
    const uint64_t flipsAfter = flipsOf(after);
    if (folding ? flipsAfter < flipsBefore : flipsAfter <= flipsBefore) return true;
    if (halved > 0.0) {
      double worst = 0.0;
      for (uint32_t q = 0; q < patches.size(); ++q)
        if (after[q]) worst = std::max(worst, error(q));
      if (worst < halved) return true;
    }
    layout.patches = saved;
    patches = was;
    return false;
  }
  // The charts gathered into one set of chartSize `top`, patch by patch, each at its level.
  GeometryImageSet gather(uint32_t top, QuadLayout quads) {
    GeometryImageSet set;
    set.chartSize = top;
    const std::vector<std::array<RootNeighbour, 4>> neighbours = quadNeighbours(layout, quads);
    std::vector<ParamQuality> initial, final;
    std::vector<ImageQuality> images;
    for (uint32_t p = 0; p < patches.size(); ++p) {
      Entry& e = patches[p];
      e.stats.firstChart = uint32_t(set.charts.size());
      set.patches.push_back(e.stats);
      initial.push_back(e.stats.paramInitial);
      final.push_back(e.stats.param);
      const uint8_t level = uint8_t(std::countr_zero(top - 1) - std::countr_zero(e.size - 1));
      for (GeometryImage& g : e.charts) {
        g.patch = p;
        g.level = level;
        g.neighbours = neighbours[set.charts.size()];
        images.push_back(g.quality);
        set.charts.push_back(std::move(g));
      }
      e.charts.clear();
    }
    set.paramInitial = combineQuality(initial);
    set.param = combineQuality(final);
    set.image = combineImageQuality(images);
    set.trianglesParameterized = trianglesParameterized;
    return set;
  }
};

// Per-patch sizing, after the first resampling. Each patch whose charts sample the surface more
// coarsely than `bound` is resampled at twice the size, up to kMaxDensityChartSize, the samples
// `cap`, and texel sides of ResampleOptions::minSampleGap. A patch is cut at its neck instead, its parts starting again
// at `base`, where:
//   - a doubling did not halve its sampling error (a smooth surface's drops about four times: this
//     one's parameterization squeezes it), or it cannot grow;
//   - its charts fold, or a doubling made them fold more (the finer texels resolve a fold of the
//     parameterization); where no cut is found, it goes back to the size before if that one met
//     the bound;
//   - its parameterization has collapsed (PatchSizing::collapsed): then the cut goes first through
//     its vertex farthest from its boundary, down both sides (splitPatchFromDeepest).
// Each cut is resampled at once and kept only where the patches it changed fold less than before
// (a cut for folds) or no more (a cut for the sampling error).
// Where no cut is found it goes on growing while it can: the sampling bound (and so the Hausdorff
// distance) goes before the folds. A patch that meets the bound but still folds, with no cut that
// helps, is doubled too, and each such doubling is kept only where its charts fold less (a fold
// narrower than a texel is the sampling's). The cuts stop once their trials have parameterized
// --repair-budget times the layout's triangles (st.repair.stoppedForWork), as the repair's do.
// Returns the sizing rounds.
uint32_t sizePatches(PatchSizing& z, const QuadChartOptions& o, uint32_t base, double bound, double cap, bool sides,
                     MeshResampleStats& st, const fs::path& dir) {
  QuadChartOptions room = o;
  uint32_t rounds = 0;
  auto mayCut = [&](const PatchSizing::Entry& e) { return !e.uncuttable && e.cuts < kMaxSizingCuts; };
  for (bool any = true; any; ++rounds) {
    any = false;
    std::vector<std::pair<double, uint32_t>> asking, squeezed;
    for (uint32_t p = 0; p < z.patches.size(); ++p) {
      PatchSizing::Entry& e = z.patches[p];
      if (e.settled) continue;
      const double err = z.error(p);
      const uint64_t flips = PatchSizing::flips(e.charts);
      if (e.grownForFolds) {
        e.grownForFolds = false;
        if (flips >= PatchSizing::flips(e.previousCharts)) {
          z.shrink(p);
          e.settled = true;
          continue;
        }
      }
      const bool doubled = e.previousSize > 0;
      const bool foldedMore = doubled && flips > PatchSizing::flips(e.previousCharts);
      if (foldedMore && !mayCut(e) && PatchSizing::worstError(e.previousCharts) <= bound) {
        z.shrink(p);
        e.settled = true;
        continue;
      }
      // Two doublings in a row that lowered the error by less than a tenth, and no cut left: the
      // error is not the sampling's (a vertex no chart of this map passes near), and more doublings
      // would only add samples (and raise the largest chart size, and with it every chart's
      // coarsest level). It stays, at the smaller error of the two sizes.
      if (doubled && !mayCut(e) && err > bound && e.flatDoublings >= 1 && PatchSizing::flatDoubling(e) &&
          flips <= PatchSizing::flips(e.previousCharts)) {
        if (err > PatchSizing::worstError(e.previousCharts)) z.shrink(p);
        e.settled = true;
        ++st.patchesAtFlatError;
        continue;
      }
      // Below the layout's density size a patch's error comes from its creases and kinked sides as
      // much as from its map, and falls only with the texel size: there a doubling that does not
      // halve it is no squeeze.
      const bool squeezing =
          doubled && err > bound && e.previousSize >= base && err > 0.5 * PatchSizing::worstError(e.previousCharts);
      if ((flips > 0 || squeezing || e.cutAsked || z.collapsed(p, bound)) && mayCut(e))
        squeezed.push_back({double(flips) + err / bound, p});
      else if (err > bound || flips > 0)
        asking.push_back({err / bound, p});
    }
    // Cuts first, each kept only where it folds less (or, for the sampling error, no more).
    std::sort(squeezed.begin(), squeezed.end(), std::greater<>());
    std::vector<uint8_t> cutNow(z.patches.size(), 0);
    const uint64_t cutBudget = meshRepairWorkBudget(o.repairBudget, z.layout.triangles.size());
    for (const auto& [n, p] : squeezed) {
      const bool folding = PatchSizing::flips(z.patches[p].charts) > 0;
      z.patches[p].cutAsked = false;
      if (z.cutWork >= cutBudget) {
        st.repair.stoppedForWork = true;
        z.patches[p].uncuttable = true;
        continue;
      }
      if (z.tryCut(p, base, sides, folding, bound)) {
        ++st.repair.patchesSplit;
        cutNow[p] = 1;
      } else {
        PatchSizing::Entry& e = z.patches[p];
        e.uncuttable = true;
        if (e.previousSize > 0 && PatchSizing::flips(e.charts) > PatchSizing::flips(e.previousCharts) &&
            PatchSizing::worstError(e.previousCharts) <= bound) {
          z.shrink(p);
          e.settled = true;
        }
      }
      any = true;
    }
    // Then the doublings, of the patches no cut changed this round.
    std::sort(asking.begin(), asking.end(), std::greater<>());
    double samples = z.samples();
    for (const auto& [n, p] : asking) {
      if (p < cutNow.size() && cutNow[p]) continue;
      const PatchSizing::Entry& e = z.patches[p];
      const double m = double(e.size - 1);
      const double growth = 3.0 * double(e.charts.size()) * m * m;
      room.chartSize = 2 * e.size - 1;
      // Halved texel sides must stay ResampleOptions::minSampleGap (two lattice steps of the coding)
      // long: on texels of a step or so, the coding's rounding puts samples on one point or three
      // on one line.
      const double shortest = PatchSizing::shortestTexelSide(e.charts);
      uint32_t* stop = e.size >= kMaxDensityChartSize       ? &st.patchesAtLargestSize
                       : samples + growth > cap             ? &st.patchesAtSampleCap
                       : 0.5 * shortest < z.ro.minSampleGap ? &st.patchesAtLattice
                                                            : nullptr;
      if (!stop) {
        try {
          checkChartRoom(z.layout, e.charts.size(), room, dir);
        } catch (const InputError&) {
          stop = &st.patchesAtMemory;
        }
      }
      const bool forFolds = z.error(p) <= bound;  // asked for its folds alone
      if (stop) {
        // Cut next round where it may be; else it stays.
        if (mayCut(e)) {
          z.patches[p].cutAsked = true;
          any = true;
        } else {
          z.patches[p].settled = true;
          if (!forFolds) ++*stop;
        }
        continue;
      }
      z.grow(p);
      z.patches[p].grownForFolds = forFolds;
      samples += growth;
      ++st.patchesDoubled;
      any = true;
    }
    if (spdlog::should_log(spdlog::level::debug))
      spdlog::debug("sizing round {}: {} patches doubled or cut, {} of them cut", rounds + 1,
                    asking.size() + squeezed.size(), squeezed.size());
    z.resampleTodo();
  }
  return rounds;
}

// The smallest size a patch's charts start at when the layout's density asks `base`: the coarsest
// finest level the hierarchy lets a chart of `base` samples have, at most 3 levels down, and at
// least 9 samples.
uint32_t startSizeFloor(uint32_t base, const QuadChartOptions& o) {
  const uint32_t intervalsLog2 = uint32_t(std::countr_zero(base - 1));
  uint32_t levels = std::min<uint32_t>(3, intervalsLog2 > 3 ? intervalsLog2 - 3 : 0);
  if (o.coarsestLevel) levels = std::min(levels, o.coarsestLevel(base));
  return ((base - 1) >> levels) + 1;
}

// Resamples `layout` (straightened, its side counts even for the sides layout) with each patch's
// charts at their own size (MeshSizing::kPatch), from the density's size up: every patch at that
// size, the folds there cut (repairCharts, flips only: a fold that stays as the texels shrink is
// the parameterization's, not the sampling's), then sizePatches. Stage "resample".
ResampledMesh resamplePerPatch(PatchLayout& layout, const QuadChartOptions& o, QuadLayout quads, const fs::path& dir,
                               StageMeter& meter) {
  ResampledMesh r;
  MeshResampleStats& st = r.stats;
  st.perPatchSize = true;
  st.sideQuads = quads == QuadLayout::kSides;
  st.unfold = o.unfold;
  st.quadMap = quadMapName(o.quadMap);
  const uint64_t quadCharts = layoutQuadCount(layout, quads);
  const uint32_t base = meshChartSizeForDensity(layout.triangles.size(), quadCharts);
  st.chartSizeByDensity = true;
  st.densityChartSize = base;
  QuadChartOptions room = o;
  room.chartSize = base;
  checkChartRoom(layout, quadCharts, room, dir);
  const double diagonal = layoutDiagonal(layout);
  for (const glm::vec3& q : layout.positions) r.bounds.extend(q);
  const double bound = (o.maxSampleError == kAutoSampleError ? kDefaultSampleError : o.maxSampleError) * diagonal;
  st.maxSampleError = bound;
  spdlog::info(
      "charts from {}^2 for {} quad charts ({}) of {} triangles ({:.1f} samples per triangle), each patch's "
      "doubled while they sample the surface more coarsely than {:.4f}% of the diagonal",
      base, quadCharts, st.sideQuads ? "sides" : "kites", layout.triangles.size(),
      samplesPerTriangle(layout, quadCharts, base), 100.0 * bound / std::max(diagonal, 1e-300));

  r.spill = std::make_unique<ChartSpill>(dir / "samples.tmp", !layout.colours.empty());
  PatchSizing z{layout, resampleOptions(o, quads, r.spill.get(), r.bounds), layoutVertexNormals(layout), {}, 0, 0,
                nullptr};
  z.ro.chartSize = base;
  // Charts below the density's size are charged for the chords they cut across their shared sides.
  z.ro.chordsBelow = base;
  // A patch is parameterized once for all its sizes, within an eighth of the memory.
  z.params = std::make_unique<ParamCache>(o.maxMemory / 8);
  QuadChartOptions baseSize = o;
  baseSize.chartSize = base;
  ParamGate gate(paramGateBudget(layout, baseSize));
  z.ro.gate = &gate;
  // Each patch starts at its own density's size: the layout's, or less for a patch with fewer
  // triangles than its quads' share (a small piece, a sliver between large patches), down to the
  // coarsest finest level the hierarchy leaves a chart of the layout's size.
  z.smallest = startSizeFloor(base, o);
  z.quads = quads;
  {
    ResampleReuse all;
    all.normals = &z.normals;
    all.params = z.params.get();
    GeometryImageSet first = resampleLayout(layout, z.ro, all);
    if (first.image.flippedTexels > 0 && o.repairRounds > 0) {
      ChartRepairOptions repair;
      repair.rounds = o.repairRounds;
      repair.workBudget = meshRepairWorkBudget(o.repairBudget, layout.triangles.size());
      repair.normals = &z.normals;
      repair.params = z.params.get();
      // No stop for memory: the gate keeps the cut patches' working memory within --max-memory,
      // and their charts go to the spill, so the work budget alone ends the repair, and where it
      // ends depends on neither the machine nor what the heap holds.
      first = repairCharts(layout, std::move(first), z.ro, repair, &st.repair);
    }
    z.trianglesParameterized = first.trianglesParameterized;
    z.patches.resize(layout.patches.size());
    std::vector<std::vector<GeometryImage>> atBase(layout.patches.size());
    std::vector<PatchResampleStats> statsAtBase(layout.patches.size());
    for (uint32_t p = 0; p < layout.patches.size(); ++p) {
      z.patches[p].size = base;
      z.take(first, p);
      const uint32_t own = z.startSize(p, base);
      if (own < base && PatchSizing::flips(z.patches[p].charts) == 0) {
        atBase[p] = std::move(z.patches[p].charts);
        statsAtBase[p] = z.patches[p].stats;
        z.patches[p].size = own;
        z.patches[p].todo = true;
      }
    }
    z.resampleTodo();
    // A patch that folds at its own size keeps the layout's, where it did not.
    for (uint32_t p = 0; p < layout.patches.size(); ++p) {
      if (atBase[p].empty() || PatchSizing::flips(z.patches[p].charts) == 0) continue;
      z.patches[p].size = base;
      z.patches[p].charts = std::move(atBase[p]);
      z.patches[p].stats = statsAtBase[p];
    }
  }
  const double cap = meshSampleCap(layout.triangles.size());
  st.sizeRounds = sizePatches(z, o, base, bound, cap, st.sideQuads, st, dir);
  // The largest size is the set's; a patch sampled coarser than the hierarchy lets a chart be is
  // resampled at the coarsest it allows.
  uint32_t top = base;
  for (const PatchSizing::Entry& e : z.patches) top = std::max(top, e.size);
  const uint32_t coarsest = o.coarsestLevel ? o.coarsestLevel(top) : 31;
  for (PatchSizing::Entry& e : z.patches) {
    if (uint32_t(std::countr_zero(top - 1) - std::countr_zero(e.size - 1)) <= coarsest) continue;
    e.size = ((top - 1) >> coarsest) + 1;
    e.todo = true;
  }
  z.resampleTodo();
  for (const PatchSizing::Entry& e : z.patches) {
    if (e.size < base) {
      ++st.patchesBelowDensitySize;
      continue;
    }
    const uint32_t doublings = uint32_t(std::countr_zero(e.size - 1) - std::countr_zero(base - 1));
    if (st.patchesBySize.size() <= doublings) st.patchesBySize.resize(doublings + 1, 0);
    ++st.patchesBySize[doublings];
  }
  const double samples = z.samples();
  if (gate.waits() > 0)
    spdlog::info(
        "{} patches waited for others to be resampled, to keep their working memory within {:.0f} MiB "
        "(of {})",
        gate.waits(), double(gate.budget()) / double(1 << 20), spelled(o, "maxMemory"));
  r.set = z.gather(top, quads);
  GeometryImageSet& set = r.set;
  st.chartSize = top;
  st.patches = layout.patches.size();
  spdlog::info(
      "patches by chart size from {}^2 up, doubling: {}, and {} below it ({} rounds, {} patch doublings, {} "
      "cuts, {:.1f} samples per triangle)",
      base, fmt::join(st.patchesBySize, ", "), st.patchesBelowDensitySize, st.sizeRounds, st.patchesDoubled,
      st.repair.patchesSplit, samples / double(std::max<size_t>(layout.triangles.size(), 1)));
  if (set.image.flippedTexels > 0 || set.image.sampleError > bound)
    spdlog::warn(
        "{}: {} flipped texels and a sampling error of {:.4f}% of the diagonal (bound {:.4f}%) are left; "
        "patches over the bound that could not grow: {} at {}^2, {} at the samples' cap ({:.0f} per "
        "triangle), {} at texels as short as the position lattice allows, {} at {}, {} whose doublings stopped "
        "lowering their error",
        o.input.string(), set.image.flippedTexels, 100.0 * set.image.sampleError / std::max(diagonal, 1e-300),
        100.0 * bound / std::max(diagonal, 1e-300), st.patchesAtLargestSize, kMaxDensityChartSize,
        st.patchesAtSampleCap, cap / double(std::max<size_t>(layout.triangles.size(), 1)), st.patchesAtLattice,
        st.patchesAtMemory, spelled(o, "maxMemory"), st.patchesAtFlatError);
  if (st.repair.stoppedForWork)
    spdlog::warn(
        "{}: the cuts stopped at their budget, {} times the surface's triangles parameterized again; raise {} "
        "to cut more",
        o.input.string(), o.repairBudget, spelled(o, "repairBudget"));
  countTwoQuadCorners(layout, o, st);
  if (spdlog::should_log(spdlog::level::debug)) logFoldingCharts(layout, set);
  finishStage(meter, "resample");
  setChartFigures(set, st);
  return r;
}

// Per-patch sizing in one quad layout: sides (straightened by `straighten`, their side counts made
// even), or kites where some patch cannot have an even side count or with --quads kites.
ResampledMesh quadChartsPerPatch(PatchLayout& layout, const QuadChartOptions& options, const fs::path& dir,
                                 StageMeter& meter, const std::function<void(QuadLayout)>& straighten) {
  QuadLayout quads = options.quads == MeshQuads::kKites ? QuadLayout::kKites : QuadLayout::kSides;
  MeshResampleStats even;
  if (quads == QuadLayout::kSides) {
    // The charted patches are kept only until the sides are known to be possible (a copy of every
    // patch's triangle list: 75 MB at 18.7M triangles, freed before the resampling).
    std::vector<Patch> charted = layout.patches;
    straighten(QuadLayout::kSides);
    if (!evenLayout(layout, even, true)) {
      spdlog::warn(
          "{}: some patches cannot be given an even number of sides for the sides quad layout (no chain "
          "of sides with inner vertices joins them to another such patch or to a hole); built with kites",
          options.input.string());
      layout.patches = std::move(charted);
      quads = QuadLayout::kKites;
      even = {};
    }
  }
  if (quads == QuadLayout::kKites) straighten(QuadLayout::kKites);
  ResampledMesh r = resamplePerPatch(layout, options, quads, dir, meter);
  r.stats.evenSideCorners = even.evenSideCorners;
  r.stats.sideEdgesSplit = even.sideEdgesSplit;
  return r;
}

}  // namespace

ResampledMesh makeQuadCharts(PatchLayout&& layout, const QuadChartOptions& options, const fs::path& dir,
                             StageMeter& meter) {
  const std::vector<std::string> bad = validatePatchLayout(layout);
  if (!bad.empty()) throw InputError(options.input.string() + ": the chart layout is invalid: " + bad.front());
  finishStage(meter, "validate");
  const uint64_t layoutTriangles = layout.triangles.size();
  // Shared sides straightened and side ears moved, for one quad layout. The sides layout makes a
  // 4-sided patch a single chart, so there no straightening may leave a patch a sliver of itself;
  // kites keep the straightening they were measured with.
  uint32_t lengthened = 0, straightened = 0, ears = 0;
  EarSplits earSplits;  // the last straightening's, undone before the next (from the charted patches)
  auto straighten = [&](QuadLayout quads, const std::string& suffix) {
    earSplits.undo(layout);
    lengthened = lengthenShortSides(layout);
    straightened =
        options.straightenRounds ? straightenSides(layout, options.straightenRounds, quads == QuadLayout::kSides) : 0;
    ears = moveSideEars(layout);
    ears += splitOpenSideEars(layout, &earSplits);
    finishStage(meter, "straighten" + suffix);
  };
  ResampledMesh r;
  bool evened = true;
  if (options.sizing == MeshSizing::kPatch && options.chartSize == 0) {
    r = quadChartsPerPatch(layout, options, dir, meter, [&](QuadLayout quads) { straighten(quads, ""); });
  } else if (options.quads == MeshQuads::kKites) {
    straighten(QuadLayout::kKites, "");
    r = resampleInLayout(layout, options, QuadLayout::kKites, dir, meter, "", &evened);
  } else {
    // Sides first (about half the charts). The sides layout keeps them unless some patch cannot
    // be given an even side count (a surface of a few triangles, whose sides have no inner
    // vertex). Auto tries both layouts at one chart size, from the density's up, doubling it only
    // while neither meets the sampling bound: kites (about twice as many charts) cut more freely
    // than sides, whose cuts must keep side counts even, and often meet the bound at a size where
    // sides would need every chart doubled. At the density's size it stops at sides if they leave
    // no flipped texel, no two-chart corner and no chart over the bound; at a larger one it builds
    // sides only where kites meet the bound. Of the layouts built at the last size it keeps
    // whichever leaves fewer flipped texels; on a tie, the one within the bound; both within it,
    // the fewer samples (sides on a tie); both over it, the smaller sampling error. Each layout is
    // straightened its own way from the charted patches.
    auto withinBound = [](const ResampledMesh& m) {
      return !(m.stats.maxSampleError > 0.0) || m.set.image.sampleError <= m.stats.maxSampleError;
    };
    auto samples = [](const ResampledMesh& m) {
      return uint64_t(m.set.charts.size()) * m.set.chartSize * m.set.chartSize;
    };
    const bool automatic = options.quads == MeshQuads::kAuto;
    // Auto tries up to two layouts at each of several sizes: each repair takes a quarter of the
    // budget. A repair that cannot meet the bound spends all it has (the horse: all 8 times its
    // triangles at 65^2, in each layout); those that met it on the shared scans needed under a
    // quarter (the bunny's kites: 1.9 times).
    QuadChartOptions each = options;
    if (automatic) each.repairBudget = options.repairBudget / 4;
    const std::vector<Patch> charted = layout.patches;
    bool sidesPossible = true;
    uint32_t size = 0;  // the density's
    for (std::string suffix;;) {
      const bool first = size == 0;
      ResampledMesh sides;
      std::vector<Patch> sidesPatches;
      uint32_t sidesStraightened = 0, sidesEars = 0;
      auto buildSides = [&] {
        layout.patches = charted;
        straighten(QuadLayout::kSides, suffix);
        sides = resampleInLayout(layout, each, QuadLayout::kSides, dir, meter, suffix, &evened, size, !automatic);
        if (!evened) {
          sidesPossible = false;
          spdlog::warn(
              "{}: some patches cannot be given an even number of sides for the sides quad layout (no chain "
              "of sides with inner vertices joins them to another such patch or to a hole); built with {} "
              "kites",
              options.input.string(), spelled(options, "quads"));
          return;
        }
        sidesPatches = layout.patches;
        sidesStraightened = straightened, sidesEars = ears;
      };
      if (sidesPossible && first) {
        buildSides();
        if (sidesPossible && (!automatic || (sides.set.image.flippedTexels == 0 && sides.stats.twoQuadCorners == 0 &&
                                             withinBound(sides)))) {
          r = std::move(sides);
          break;
        }
      }
      layout.patches = charted;
      straighten(QuadLayout::kKites, suffix + " (kites)");
      ResampledMesh kites = resampleInLayout(layout, each, QuadLayout::kKites, dir, meter, suffix + " (kites)", &evened,
                                             size, !automatic);
      const bool kitesClean = kites.set.image.flippedTexels == 0 && withinBound(kites);
      std::vector<Patch> kitesPatches = layout.patches;
      const uint32_t kitesStraightened = straightened, kitesEars = ears;
      // At a grown size, sides only where kites meet the bound, for their fewer samples: kites cut
      // more freely, and on every shared scan they left the smaller sampling error at every size.
      if (automatic && !first && kitesClean && sidesPossible) buildSides();
      // Neither within the bound: the next size (grownChartSize), unless the density did not choose
      // this one or a repair stopped for memory.
      const bool sidesBuilt = static_cast<bool>(sides.spill);
      if (automatic && !withinBound(kites) && !(sidesBuilt && withinBound(sides)) && kites.stats.chartSizeByDensity &&
          !kites.stats.repair.stoppedForMemory && !(sidesBuilt && sides.stats.repair.stoppedForMemory)) {
        const ResampledMesh& fewer = sidesBuilt && samples(sides) < samples(kites) ? sides : kites;
        const double error = std::min(kites.set.image.sampleError,
                                      sidesBuilt ? sides.set.image.sampleError : kites.set.image.sampleError);
        const uint32_t next = grownChartSize(layout, options, kites.stats.chartSize, fewer.set.charts.size(), error,
                                             kites.stats.maxSampleError, dir);
        if (next > 0) {
          const double percent = 100.0 / std::max(layoutDiagonal(layout), 1e-300);
          spdlog::info(
              "chart size {} -> {}: neither layout meets the sampling bound ({}kites {:.4f}% of the "
              "diagonal, bound {:.4f}%)",
              kites.stats.chartSize, next,
              sidesBuilt ? fmt::format("sides {:.4f}%, ", percent * sides.set.image.sampleError) : "",
              percent * kites.set.image.sampleError, percent * kites.stats.maxSampleError);
          size = next;
          suffix = fmt::format(" at {}", size);
          continue;
        }
      }
      bool keepSides = sidesBuilt && sides.stats.twoQuadCorners == 0 &&
                       sides.set.image.flippedTexels <= kites.set.image.flippedTexels &&
                       (withinBound(sides) || !withinBound(kites));
      if (keepSides && sides.set.image.flippedTexels == kites.set.image.flippedTexels &&
          withinBound(sides) == withinBound(kites))
        keepSides = withinBound(sides) ? samples(sides) <= samples(kites)
                                       : sides.set.image.sampleError <= kites.set.image.sampleError;
      if (sidesBuilt) {
        spdlog::info(
            "quad layout: sides ({} charts of {}^2) left {} flipped texels, {} two-chart corners and a "
            "sampling error {:.3g}, kites ({} charts of {}^2) {} flipped texels and {:.3g} (bound {:.3g}): "
            "keeping {}",
            sides.set.charts.size(), sides.set.chartSize, sides.set.image.flippedTexels, sides.stats.twoQuadCorners,
            sides.set.image.sampleError, kites.set.charts.size(), kites.set.chartSize, kites.set.image.flippedTexels,
            kites.set.image.sampleError, sides.stats.maxSampleError, keepSides ? "sides" : "kites");
      }
      if (keepSides) {
        sides.stats.alternativeFlippedTexels = int64_t(kites.set.image.flippedTexels);
        r = std::move(sides);
        layout.patches = std::move(sidesPatches);
        straightened = sidesStraightened;
        ears = sidesEars;
      } else {
        if (sidesBuilt) kites.stats.alternativeFlippedTexels = int64_t(sides.set.image.flippedTexels);
        r = std::move(kites);
        layout.patches = std::move(kitesPatches);
        straightened = kitesStraightened;
        ears = kitesEars;
      }
      break;
    }
  }
  r.stats.sidesLengthened = lengthened;
  r.stats.sidesStraightened = straightened;
  r.stats.sideEarsMended = ears;
  r.triangles = layoutTriangles;
  layout = PatchLayout{};
  return r;
}

}  // namespace gimlod

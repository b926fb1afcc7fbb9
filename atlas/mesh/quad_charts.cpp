// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (quadrangulate, resample); Purnomo, Cohen,
// Kumar, "Seamless Texture Atlases", SGP 2004.
#include "atlas/mesh/quad_charts.h"

#include <algorithm>
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


double meshSampleCap(uint64_t triangles) {
  return std::max(kMaxSamplesPerTriangle * double(triangles), kMinSampleCap);
}

uint32_t meshChartSizeForDensity(uint64_t triangles, uint64_t quads) {
  const double wanted = kSamplesPerTriangle * double(triangles);
  uint32_t intervals = 64;
  while (intervals + 1 < kMaxDensityChartSize && double(std::max<uint64_t>(quads, 1)) * intervals * intervals < wanted) intervals *= 2;
  return intervals + 1;
}

namespace {

// The option's name as the options' front end spells it in messages.
std::string spelled(const QuadChartOptions& o, std::string_view name) {
  return o.spellOption ? o.spellOption(name) : std::string(name);
}

// The diagonal of the layout's bounding box.
double layoutDiagonal(const ChartLayout& layout) {
  MeshBounds b;
  for (const glm::vec3& p : layout.positions) b.extend(p);
  return b.empty() ? 0.0 : glm::length(glm::dvec3(b.max) - glm::dvec3(b.min));
}

// Samples per layout triangle in `charts` charts of chartSize^2 samples (intervals squared).
// Whether `charts` charts of chartSize^2 samples reach the samples a layout may grow to
// (meshSampleCap).
bool atSampleCap(const ChartLayout& layout, uint64_t charts, uint32_t chartSize) {
  return double(charts) * double(chartSize - 1) * double(chartSize - 1) >= meshSampleCap(layout.triangles.size());
}

double samplesPerTriangle(const ChartLayout& layout, uint64_t charts, uint32_t chartSize) {
  return double(charts) * double(chartSize - 1) * double(chartSize - 1) /
         double(std::max<size_t>(layout.triangles.size(), 1));
}

// The quad charts of a layout (before any repair).
uint64_t layoutQuadCount(const ChartLayout& layout, QuadLayout quads) {
  uint64_t n = 0;
  for (const Patch& pa : layout.patches) n += patchQuadCount(uint32_t(pa.sides.size()), quads);
  return n;
}

// Refuses a chart size whose charts cannot be made: each chart's samples go to a spill file in
// the staging directory once measured, and are read back one chart at a time per thread to be
// written, so what must fit is a patch's charts (up to 8 quads) and their working arrays on every
// thread at once in memory, and the spill plus the chart files (with their pyramids) on disk.
void checkChartRoom(const ChartLayout& layout, uint64_t quads, const QuadChartOptions& o, const fs::path& dir) {
  const uint64_t samples = uint64_t(o.chartSize) * o.chartSize;
  const uint64_t perSample = layout.colours.empty() ? 16 : 20;
  const uint64_t threads = o.threads ? o.threads : uint64_t(std::max(1, tbb::this_task_arena::max_concurrency()));
  const uint64_t inFlight = threads * samples * (8 * perSample + 32);
  if (inFlight > o.maxMemory)
    throw InputError(fmt::format("{}: quad charts of {}^2 samples need {:.1f} GiB of geometry images at once "
                                 "({} threads), more than {} ({:.1f} GiB): lower {} or {}, or raise {}",
                                 o.input.string(), o.chartSize, double(inFlight) / double(1ull << 30), threads,
                                 optionRef("maxMemory"), double(o.maxMemory) / double(1ull << 30),
                                 optionRef("chartSize"), optionRef("threads"), optionRef("maxMemory")));
  const uint64_t disk = quads * samples * perSample * 3;  // the spill, and chart files a third larger
  std::error_code ec;
  const fs::space_info space = fs::space(dir, ec);
  if (!ec && disk > space.available)
    throw InputError(fmt::format("{}: {} quad charts of {}^2 samples need about {:.1f} GiB of disk in {}, which has "
                                 "{:.1f} GiB free: lower {} or {}",
                                 o.input.string(), quads, o.chartSize, double(disk) / double(1ull << 30),
                                 dir.parent_path().string(), double(space.available) / double(1ull << 30),
                                 optionRef("chartSize"), optionRef("charts")));
}


// Logs (at debug level) every chart left with flipped texels: its patch's size and sides (edges
// and length of each), so that where folds remain can be told apart.
void logFoldingCharts(const ChartLayout& layout, const GeometryImageSet& set) {
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
uint32_t grownChartSize(const ChartLayout& layout, const QuadChartOptions& options, uint32_t current, uint64_t charts,
                        double error, double bound, const fs::path& dir) {
  if (current >= kMaxDensityChartSize || atSampleCap(layout, charts, current)) return 0;
  const uint32_t asked = std::max(1u, uint32_t(std::ceil(std::log(error / std::max(bound, 1e-300)) / std::log(4.0))));
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

// One resampling and repair of `layout` in quad layout `quads`: its patches change (side counts
// made even for the sides layout, the repair's cuts). Stages "resample" and "chart_repair", named
// with `suffix`. With the sides layout, false in `evened` (and nothing else done) when some patch
// cannot be given an even side count. A chart size chosen by density is `size` when given (else
// meshChartSizeForDensity's), and doubled where the bound asks it only with `grow`.
ResampledMesh resampleInLayout(ChartLayout& layout, const QuadChartOptions& options, QuadLayout quads,
                               const fs::path& dir, StageMeter& meter, const std::string& suffix, bool* evened,
                               uint32_t size = 0, bool grow = true) {
  ResampledMesh r;
  MeshResampleStats& st = r.stats;
  QuadChartOptions o = options;
  if (o.maxSampleError == kAutoSampleError) o.maxSampleError = o.chartSize == 0 ? kDefaultSampleError : 0.0;
  st.sideQuads = quads == QuadLayout::kSides;
  st.unfold = o.unfold;
  st.quadMap = o.quadMap == MeshQuadMap::kStretch ? "stretch" : o.quadMap == MeshQuadMap::kFolding ? "folding" : "bilinear";
  if (st.sideQuads) {
    const uint32_t holeCorners = splitTwoSidedHoles(layout);
    const EvenSidesResult even = evenSides(layout);
    st.evenSideCorners = holeCorners + even.corners;
    *evened = even.oddLeft == 0;
    if (!*evened) return r;
    st.evenSideCorners += mendTwoChartCorners(layout).corners;
  }
  const uint64_t quadCharts = layoutQuadCount(layout, quads);
  if (o.chartSize == 0) {
    o.chartSize = meshChartSizeForDensity(layout.triangles.size(), quadCharts);
    st.chartSizeByDensity = true;
    st.densityChartSize = o.chartSize;
    if (size > 0) o.chartSize = size;
    spdlog::info("chart size {}{} for {} quad charts ({}) of {} triangles ({:.1f} samples per triangle)", o.chartSize,
                 o.chartSize != st.densityChartSize ? fmt::format(" (doubled from the density's {})", st.densityChartSize)
                                                    : std::string(),
                 quadCharts, st.sideQuads ? "sides" : "kites", layout.triangles.size(),
                 samplesPerTriangle(layout, quadCharts, o.chartSize));
  }
  st.chartSize = o.chartSize;
  checkChartRoom(layout, quadCharts, o, dir);

  // Quads, parameterization and resampling.
  const fs::path spillFile = dir / (st.sideQuads ? "samples_sides.tmp" : "samples_kites.tmp");
  r.spill = std::make_unique<ChartSpill>(spillFile, o.chartSize, !layout.colours.empty());
  ResampleOptions ro;
  ro.chartSize = o.chartSize;
  ro.threads = o.threads;
  ro.spill = r.spill.get();
  ro.quads = quads;
  ro.unfold = o.unfold;
  ro.quadMap = o.quadMap == MeshQuadMap::kStretch   ? QuadMap::kStretch
               : o.quadMap == MeshQuadMap::kFolding ? QuadMap::kFolding
                                                    : QuadMap::kBilinear;
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
      spdlog::info("chart size stays {}: {}", o.chartSize, o.spellOption ? e.message(o.spellOption) : std::string(e.what()));
      return false;
    }
    spdlog::info("chart size {} -> {}: {}", o.chartSize, larger.chartSize, why);
    o.chartSize = larger.chartSize;
    if (restore) layout.patches = *restore;
    first = GeometryImageSet{};
    r.spill.reset();  // (removes its file)
    r.spill = std::make_unique<ChartSpill>(spillFile, o.chartSize, !layout.colours.empty());
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
  for (const glm::vec3& q : layout.positions) r.bounds.extend(q);
  const double maxError = o.maxSampleError * diagonal;
  while (grow && st.chartSizeByDensity && maxError > 0.0 && o.chartSize < kMaxDensityChartSize) {
    const std::vector<uint8_t> over = patchesOverSampleError(first, layout.patches.size(), maxError);
    uint64_t overTriangles = 0;
    for (uint32_t p = 0; p < layout.patches.size(); ++p) overTriangles += over[p] ? layout.patches[p].triangles.size() : 0;
    if (double(overTriangles) <= kCoarseSurfaceToDouble * double(layout.triangles.size()) ||
        atSampleCap(layout, first.charts.size(), o.chartSize))
      break;
    const std::string why =
        fmt::format("patches with {:.0f}% of the triangles sample the surface more coarsely than {:.4f}% of the diagonal",
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
  repair.workBudget = uint64_t(std::llround(o.repairBudget * double(layoutTriangles)));
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
    const std::string why = fmt::format("the repair left a sampling error of {:.4f}% of the diagonal (bound {:.4f}%)",
                                        100.0 * r.set.image.sampleError / std::max(diagonal, 1e-300),
                                        100.0 * o.maxSampleError);
    if (!doubleChartSize(layoutQuadCount(layout, quads), why, &unrepaired)) break;
    ++st.repairDoublings;
    st.repair = {};
  }
  st.chartSize = o.chartSize;
  const GeometryImageSet& set = r.set;
  if (spdlog::should_log(spdlog::level::debug)) logFoldingCharts(layout, set);
  const std::string left = fmt::format("{} flipped texels left, largest sampling error {:.4f}% of the diagonal",
                                       set.image.flippedTexels,
                                       100.0 * set.image.sampleError / std::max(diagonal, 1e-300));
  if (st.repair.stoppedForMemory)
    spdlog::warn("{}: the chart repair stopped at 3/4 of {} ({}); raise {} to repair more", o.input.string(),
                 spelled(o, "maxMemory"), left, spelled(o, "maxMemory"));
  st.repairWork = double(st.repair.trianglesWholeRounds + st.repair.trianglesTrials) /
                  double(std::max<uint64_t>(layoutTriangles, 1));
  if (st.repair.stoppedForWork)
    spdlog::warn("{}: the chart repair stopped at its budget, {:.2f} times the surface's triangles parameterized "
                 "again ({}); raise {} to repair more",
                 o.input.string(), st.repairWork, left, spelled(o, "repairBudget"));
  st.patches = layout.patches.size();
  if (st.sideQuads) {
    st.twoQuadCorners = twoQuadCorners(layout);
    if (st.twoQuadCorners > 0)
      spdlog::warn("{}: {} corners of the sides quad layout have only two charts meeting (their corner texels fold "
                   "flat onto each other)",
                   o.input.string(), st.twoQuadCorners);
  }
  finishStage(meter, "chart_repair" + suffix);
  st.charts = set.charts.size();
  st.param = set.param;
  st.image = set.image;
  st.perChart.reserve(set.charts.size());
  for (const GeometryImage& g : set.charts) st.perChart.push_back({g.patch, g.quad, g.quality});
  return r;
}

}  // namespace

ResampledMesh makeQuadCharts(ChartLayout&& layout, const QuadChartOptions& options, const fs::path& dir,
                             StageMeter& meter) {
  const std::vector<std::string> bad = validateChartLayout(layout);
  if (!bad.empty()) throw InputError(options.input.string() + ": the chart layout is invalid: " + bad.front());
  finishStage(meter, "validate");
  const uint64_t layoutTriangles = layout.triangles.size();
  // Shared sides straightened and side ears moved, for one quad layout. The sides layout makes a
  // 4-sided patch a single chart, so there no straightening may leave a patch a sliver of itself;
  // kites keep the straightening they were measured with.
  uint32_t straightened = 0, ears = 0;
  auto straighten = [&](QuadLayout quads, const std::string& suffix) {
    straightened = options.straightenRounds
                       ? straightenSides(layout, options.straightenRounds, quads == QuadLayout::kSides)
                       : 0;
    ears = moveSideEars(layout);
    finishStage(meter, "straighten" + suffix);
  };
  ResampledMesh r;
  bool evened = true;
  if (options.quads == MeshQuads::kKites) {
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
          spdlog::warn("{}: some patches cannot be given an even number of sides for the sides quad layout (no chain "
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
      ResampledMesh kites = resampleInLayout(layout, each, QuadLayout::kKites, dir, meter, suffix + " (kites)",
                                             &evened, size, !automatic);
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
          spdlog::info("chart size {} -> {}: neither layout meets the sampling bound ({}kites {:.4f}% of the "
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
        spdlog::info("quad layout: sides ({} charts of {}^2) left {} flipped texels, {} two-chart corners and a "
                     "sampling error {:.3g}, kites ({} charts of {}^2) {} flipped texels and {:.3g} (bound {:.3g}): "
                     "keeping {}",
                     sides.set.charts.size(), sides.set.chartSize, sides.set.image.flippedTexels,
                     sides.stats.twoQuadCorners, sides.set.image.sampleError, kites.set.charts.size(),
                     kites.set.chartSize, kites.set.image.flippedTexels, kites.set.image.sampleError,
                     sides.stats.maxSampleError, keepSides ? "sides" : "kites");
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
  r.stats.sidesStraightened = straightened;
  r.stats.sideEarsMended = ears;
  r.triangles = layoutTriangles;
  layout = ChartLayout{};
  return r;
}

}  // namespace gimlod

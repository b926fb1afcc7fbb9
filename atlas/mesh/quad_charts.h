// The mesh stage's quad charts: how a chart layout's patches become sampled quad charts, behind
// one call (makeQuadCharts): the quad layout (sides, kites, or both tried), the chart size (by the
// input's density, doubled where the sampling bound asks it), the resampling, and the repair that
// cuts patches whose charts fold or sample the surface too coarsely.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (quadrangulate, resample); Purnomo, Cohen,
// Kumar, "Seamless Texture Atlases", SGP 2004.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "atlas/mesh/patch_layout.h"
#include "atlas/mesh/layout_refine.h"
#include "atlas/mesh/mesh_io.h"
#include "atlas/mesh/resample.h"
#include "core/stage_meter.h"

namespace gimlod {

// The sampling bound's sentinel (chosen by the chart size) and default, as fractions of the
// bounding-box diagonal (QuadChartOptions::maxSampleError). The default spends the 0.1% Hausdorff
// distance an atlas promises: 0.08% for the samples, the position tolerance's 0.005% on top
// (kDefaultPositionTolerance, pipeline/build_options.h), and the rest for what a check at the
// input's vertices does not see between them.
inline constexpr double kAutoSampleError = -1.0;
inline constexpr double kDefaultSampleError = 0.0008;

// How patches become quad charts (atlas/mesh/resample.h QuadLayout): kites (n charts an n-sided
// patch), sides (about n/2; side counts made even first), or auto: sides, and kites too if sides
// leave flipped texels, corners where only two charts meet or a sampling error over the bound,
// both at one chart size, from the density's up, doubled only while neither meets the bound.
enum class MeshQuads : uint8_t { kAuto, kSides, kKites };
// How a quad chart's square maps into its patch's parameterization (atlas/mesh/resample.h QuadMap).
enum class MeshQuadMap : uint8_t { kBilinear, kStretch, kFolding };
// How big the charts are.
//   patch: each patch's charts at a size of their own. Every patch is parameterized and resampled
//     at the density's size, and the folds there are cut (repairCharts). Then a patch with fewer
//     triangles than its quads' share of the density's samples (a small piece, a sliver between
//     large patches) is resampled at its own density's size (patchChartSizeForDensity, down to
//     the coarsest finest level the hierarchy allows a chart of the density's size, at most 3
//     levels down), kept unless it folds there. A patch whose charts sample the surface more
//     coarsely than the sampling bound, or fold, is resampled at twice the size, again while that
//     does not mend it, up to kMaxDensityChartSize and the samples meshSampleCap allows, or cut
//     where it folds or a doubling from the density's size up does not halve its error
//     (sizePatches). One quad layout is built: sides (kites where some patch cannot have an even
//     side count, or if asked for). A shared side is sampled by arc length at each patch's own count, and those
//     counts differ by powers of two, so the coarser patch's samples are the finer one's, bit for
//     bit (sampleSide in atlas/mesh/resample.cpp). Charts of a patch sampled coarser than the
//     largest size keep that as their finest pyramid level (ChartInfo::finestLevel).
//   layout: every chart at one size, with the chart repair cutting the patches whose charts fold
//     or sample too coarsely, and, with the auto quad layout, both layouts tried (makeQuadCharts).
enum class MeshSizing : uint8_t { kPatch, kLayout };

// Samples per input triangle the default chart size starts from; the sampling error then doubles it
// where the surface needs it (the paper's scans hold about 4 to 8).
inline constexpr double kSamplesPerTriangle = 2.0;

// The default quad chart size for `quads` charts of a mesh of `triangles` triangles: the smallest
// 2^m + 1 in [65, kMaxDensityChartSize] whose quads * (size - 1)^2 samples reach
// kSamplesPerTriangle * triangles. With the auto quad layout (the default) the build doubles it
// only while neither layout's repair brings every chart within maxSampleError. With one layout
// asked for, it doubles it (up to kMaxSamplesPerTriangle) before the repair while the patches whose
// charts sample the surface more coarsely than maxSampleError hold more than
// kCoarseSurfaceToDouble of its triangles (below that, the repair cuts those patches, which costs
// far fewer samples than doubling every chart), and after it while the repair leaves the bound
// unmet. Where the doubling stops at kMaxSamplesPerTriangle, a chart may keep a sampling error
// past maxSampleError.
inline constexpr double kCoarseSurfaceToDouble = 0.25;
inline constexpr uint32_t kMaxDensityChartSize = 1025;
inline constexpr double kMaxSamplesPerTriangle = 64.0;
// The samples the doubling may grow the charts to: kMaxSamplesPerTriangle per input triangle, but
// never fewer than kMinSampleCap. A mesh of a few thousand triangles has as many patches as a
// large one and its charts start at 65^2, so a cap by triangles alone left it no doubling at all:
// a generated genus-3 plate of 6,400 triangles kept a chart at 3.2 times the sampling bound and a
// Hausdorff distance of 0.16% of its diagonal. Charts that do not need the samples keep coarser
// finest levels when written (ChartCoarsening), so the cap bounds the resampling, not the atlas.
inline constexpr double kMinSampleCap = double(1u << 22);
double meshSampleCap(uint64_t triangles);
// The triangles the repair (and the sizing's cuts) may parameterize again: repairBudget times the
// layout's triangles, counting at most kRepairTrianglesCounted of them. Past a million triangles
// the repair's work stops growing with the surface: its cuts mend folds of a few texels, each at
// the cost of parameterizing a patch again, and on the 18.7M-triangle sphere those patches hold
// 350k to 670k triangles each.
inline constexpr uint64_t kRepairTrianglesCounted = uint64_t(1) << 20;
uint64_t meshRepairWorkBudget(double repairBudget, uint64_t layoutTriangles);
uint32_t meshChartSizeForDensity(uint64_t triangles, uint64_t quads);
// A patch's own start size under per-patch sizing: the smallest 2^m + 1 in [smallest, largest]
// whose quads * (size - 1)^2 samples reach kSamplesPerTriangle * triangles.
uint32_t patchChartSizeForDensity(uint64_t triangles, uint64_t quads, uint32_t smallest, uint32_t largest);

struct QuadChartOptions {
  std::filesystem::path input;  // the mesh, named in messages
  // How messages spell an option (optionRef names: "chartSize", "maxMemory", ...); none: the name.
  std::function<std::string(std::string_view)> spellOption;
  // Quad chart side in samples, 2^m + 1; 0: by the input's density (meshChartSizeForDensity).
  uint32_t chartSize = 0;
  uint32_t threads = 0;             // worker threads; 0: all cores
  uint64_t maxMemory = 4ull << 30;  // the charts' samples and the repair's working memory
  uint32_t straightenRounds = 2;    // rounds of straightening shared sides (layout_refine.h)
  // Rounds of each repair (repairCharts), and its work cap: layout triangles parameterized again,
  // as a multiple of the layout's triangles, counting at most kRepairTrianglesCounted of them.
  uint32_t repairRounds = 4;
  double repairBudget = 8.0;
  // The largest sampling error a chart may keep, a fraction of the diagonal; kAutoSampleError:
  // kDefaultSampleError when the chart size is chosen by density, else 0 (flips only).
  double maxSampleError = kAutoSampleError;
  MeshQuads quads = MeshQuads::kAuto;
  MeshQuadMap quadMap = MeshQuadMap::kBilinear;
  bool unfold = true;  // ResampleOptions::unfold
  // Per-patch sizes (the default) unless chartSize is given, which asks for one size.
  MeshSizing sizing = MeshSizing::kPatch;
  // The coding's position lattice step for a surface of these bounds (ResampleOptions::minSampleGap
  // is two of them); none: no lattice.
  std::function<double(const MeshBounds&)> positionStep;
  // Under patch sizing: the coarsest pyramid level a chart may be sampled at when the largest
  // chart size is the argument (HierarchyParams::maxFinestLevel); none: no limit.
  std::function<uint32_t(uint32_t)> coarsestLevel;
};

// One quad chart's figures.
struct ChartQuality {
  uint32_t patch = 0;    // layout patch
  uint32_t quad = 0;     // quad within the patch
  uint32_t side = 0;     // samples a side of its image
  ImageQuality quality;  // of its sampled image
};

// Resample and repair: layout checks, side straightening, resampling and the flip repair.
struct MeshResampleStats {
  uint64_t charts = 0;
  ParamQuality param;            // all patches' parameterizations
  ImageQuality image;            // all charts' sampled images
  uint32_t sidesLengthened = 0;  // short sides lengthened (lengthenShortSides)
  uint32_t sidesStraightened = 0;
  uint32_t sideEarsMended = 0;
  bool sideQuads = false;                 // the sides quad layout (else kites)
  std::string quadMap = "bilinear";       // the quad map: bilinear, stretch or folding
  bool unfold = true;                     // samples round flipped texels slid (ResampleOptions::unfold)
  uint32_t evenSideCorners = 0;           // corners made so every patch has an even side count
  uint32_t sideEdgesSplit = 0;            // edges split at their midpoints so that sides could take a corner
  int64_t alternativeFlippedTexels = -1;  // auto: the other layout's flipped texels; -1: not built
  uint32_t twoQuadCorners = 0;            // sides layout: corners where only two charts meet
  ChartRepairStats repair;
  uint32_t chartSize = 0;                // the quad charts' side in samples
  bool chartSizeByDensity = false;       // chosen by meshChartSizeForDensity
  uint32_t densityChartSize = 0;         // what meshChartSizeForDensity chose, before any doubling
  uint32_t repairDoublings = 0;          // times it was doubled after a repair left the bound unmet
  double maxSampleError = 0.0;           // the repair's bound, in the input's units (0: none)
  double repairWork = 0.0;               // layout triangles parameterized again / layout triangles
  uint64_t patches = 0;                  // after the repair
  bool perPatchSize = false;             // MeshSizing::kPatch: charts at their patches' own sizes
  uint32_t sizeRounds = 0;               // per-patch sizing: resampling rounds
  uint32_t patchesDoubled = 0;           // per-patch sizing: patch resamplings at a doubled size
  std::vector<uint32_t> patchesBySize;   // per-patch sizing: [k] patches of (density size - 1) * 2^k + 1
  uint32_t patchesBelowDensitySize = 0;  // per-patch sizing: patches at their own size below the density's
  // Per-patch sizing: patches left over the sampling bound, by what stopped their growth: the
  // largest chart size (kMaxDensityChartSize), the samples cap (meshSampleCap), texels as short as
  // the coding's lattice allows (ResampleOptions::minSampleGap), or the memory.
  uint32_t patchesAtLargestSize = 0, patchesAtSampleCap = 0, patchesAtLattice = 0, patchesAtMemory = 0;
  uint32_t patchesAtFlatError = 0;  // two doublings in a row lowered its error by less than a tenth
  std::vector<ChartQuality> perChart;
};

// A layout's charts, sampled.
struct ResampledMesh {
  GeometryImageSet set;
  std::unique_ptr<ChartSpill> spill;  // where the charts' samples are, in dir
  MeshResampleStats stats;
  MeshBounds bounds;       // of the layout
  uint64_t triangles = 0;  // of the layout
};

// Resample and repair: checks the layout, chooses the chart size if options.chartSize is 0
// (meshChartSizeForDensity, reported in stats.chartSize), and refuses a chart size whose geometry
// images exceed options.maxMemory or the free disk in dir; straightens the shared sides,
// resamples, and repairs flipped texels and sampling errors over options.maxSampleError (until
// 3/4 of maxMemory is resident or repairBudget is spent). layout is freed. Stages "validate",
// "straighten", "resample", "chart_repair". Throws
// InputError naming the file and the parameter to change.
ResampledMesh makeQuadCharts(PatchLayout&& layout, const QuadChartOptions& options, const std::filesystem::path& dir,
                             StageMeter& meter);

// Ends the meter's running stage as `name`, and logs its time and peak memory.
void finishStage(StageMeter& meter, const std::string& name);

}  // namespace gimlod

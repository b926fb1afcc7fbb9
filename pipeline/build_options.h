// Options of `gimlod build`: one struct per input kind, over the fields they share.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include "atlas/fidelity/fidelity.h"
#include "atlas/mesh/quad_charts.h"

namespace gimlod {

// The smallest l with 2^l >= v (log2 of a power of two; 0 for v <= 1).
inline uint32_t log2u(uint32_t v) {
  uint32_t l = 0;
  while ((1u << l) < v) ++l;
  return l;
}

// Quadtree levels per chart when none is asked for: a DEM's charts take kDefaultDepth; a mesh's
// take as many levels as leave its finest nodes 32 intervals wide, at most kDefaultDepth (the
// leaves of a 513-sample chart at that depth). A mesh's charts follow its density and may be as
// small as 65 samples: at depth 5 those would hold 341 nodes each, the finest 4 intervals wide,
// and their bounds and errors would weigh a third of the atlas.
inline constexpr uint32_t kAutoDepth = 0;
inline constexpr uint32_t kDefaultDepth = 5;
inline uint32_t terrainDepth(uint32_t depth) { return depth == kAutoDepth ? kDefaultDepth : depth; }
inline uint32_t meshDepth(uint32_t depth, uint32_t intervalsLog2) {
  return depth != kAutoDepth ? depth : uint32_t(std::clamp(int(intervalsLog2) - 4, 1, int(kDefaultDepth)));
}

inline constexpr uint32_t kAutoChartSize = 0;

// What every build takes.
struct CommonBuildOptions {
  std::filesystem::path input;   // the DEM or mesh to read
  std::filesystem::path output;  // the atlas directory; an earlier atlas there is replaced
  uint32_t depth = kAutoDepth;   // quadtree levels per chart (kAutoDepth: see terrainDepth, meshDepth)
  uint32_t nodeRes = 64;         // maximum node resolution R (intervals, power of two)
  uint32_t minNodeRes = 4;       // minimum node resolution (intervals, power of two)
  uint32_t threads = 0;          // worker threads; 0: all cores
  // Compressed chart files (atlas format version 2, core/block_codec.h); false: format version 1
  // (raw samples).
  bool compress = true;
  // Spells an option's parameter name ("maxMemory") in logged warnings, e.g. as the front end's
  // flag; empty: the parameter name itself.
  std::function<std::string(std::string_view)> spellOption;
};

// The step non-integer heights are quantized to in a compressed terrain atlas, metres: for a
// source of whole metres (SRTM), 1 (the filled voids are rounded like the source), else 0.01.
inline constexpr double kAutoHeightPrecision = 0.0;
inline constexpr double kDefaultHeightPrecision = 0.01;

// A terrain atlas from a DEM (any single-band raster GDAL reads).
struct TerrainBuildOptions : CommonBuildOptions {
  std::string subdataset;  // netCDF variable; empty: the first 2D one
  uint32_t band = 0;       // the heights' band, from 1 (DemOptions::band); 0: band 1, refusing an RGB image
  std::array<double, 2> spacing{0.0, 0.0};  // metres between samples, east and north; 0: from the georeference
  // Samples per chart side, 2^m + 1 in [9, kMaxTerrainChartSize]; kAutoChartSize: from the DEM's
  // size (planTerrain).
  uint32_t chartSize = kAutoChartSize;
  double zScale = 1.0;  // height multiplier; finite and non-zero
  // Colour imagery draped over the DEM (atlas/terrain/imagery.h); empty path: none.
  std::filesystem::path imagery;
  int imageryScaleLog2 = -1;                           // kAutoImageryScale, or 0..2
  std::optional<std::array<double, 4>> imageryExtent;  // for imagery without a georeference
  // The build's memory cap, bytes. A DEM whose in-memory build would exceed it (about
  // kTerrainBytesPerSample per sample) is built window by window within it instead; with imagery
  // that is refused. 0: three quarters of the machine's memory.
  uint64_t maxMemory = 0;
  // Compressed atlases: integer heights are stored losslessly, others quantized to
  // heightPrecision metres before anything is measured, so the hierarchy's errors bound the
  // decoded surface.
  double heightPrecision = kAutoHeightPrecision;
  // Build window by window within maxMemory (atlas/terrain/terrain_windowed.h) even when the DEM
  // would fit in memory; without it that happens only when it would not.
  bool outOfCore = false;
  // A planet atlas (core/planet.h): the DEM, in longitude and latitude, drawn on a sphere of
  // planetRadius metres, or with planetFlattening > 0 on an ellipsoid of that equatorial radius
  // (kEllipsoids: WGS84); a DEM circling the planet wraps at the antimeridian and closes at the
  // poles (atlas/terrain/planet_grid.h).
  bool planet = false;
  double planetRadius = kEarthRadius;
  double planetFlattening = 0.0;
};
// Peak resident bytes per DEM sample of the in-memory terrain build, above what the process holds
// before it, measured: 16.9 on the shipped tile upsampled 4 times (23M samples, 144k voids: the
// fill's pyramid and copies), 9.4 on ETOPO5 (no voids).
inline constexpr double kTerrainBytesPerSample = 17.0;

// A geometry atlas from a mesh (PLY, OBJ, OFF, STL).
// 2^18 steps across the diagonal (0.0004% of it). Settled (below), igea's and the turbine blade's
// atlases take 0.66 and 0.86 times the bytes at 2^18 that they take at 2^22, with the same
// Hausdorff figures; where samples lie closer than a step, settling keeps them apart
// (settlePositions).
inline constexpr uint32_t kDefaultPositionBits = 18;
// How far, as a fraction of the bounding-box diagonal, a position off its chart's border may be
// settled from its lattice point so that it codes cheaply (core/block_codec.h settlePositions),
// and by how many packed steps a normal byte may; the Hausdorff distance grows by at most the
// former. Settled in the interpolation order, the coarser pyramid levels (which subsample level
// 0) code as cheaply as level 0; twice the tolerance (0.01%) takes 0.95, 0.99 and 0.95 times the
// bytes on the bunny, the armadillo and the generated torus, at Hausdorff distances 0.001% to
// 0.002% of the diagonal larger (docs/mesh_stage.md, Compressed mesh atlases).
inline constexpr double kDefaultPositionTolerance = 0.00005;
inline constexpr uint32_t kDefaultNormalTolerance = 1;
inline constexpr uint32_t kAutoPatches = ~0u;

// Where a compressed mesh atlas's normals come from: stored with every sample, or derived from the
// positions on reading (core/atlas_format.h geometryImageNormals; block borders stored); auto:
// derived where the charts keep at most kDerivedNormalsSamplesPerTriangle samples per input
// triangle. Sampled more densely, the derived normals show the input's flat triangles, which the
// resampled (interpolated vertex) normals smooth over.
enum class MeshNormals : uint8_t { kAuto, kStored, kDerived };
inline constexpr double kDerivedNormalsSamplesPerTriangle = 16.0;

// The shape term of the patch clustering (atlas/mesh/charting.h ChartMetric).
enum class MeshChartMetric : uint8_t { kAuto, kPlanar, kDevelopable };

struct MeshBuildOptions : CommonBuildOptions {
  // Quad chart side in samples, 2^m + 1 in [9, 8193]; 0: by the input's density
  // (meshChartSizeForDensity, after the charting).
  uint32_t chartSize = 0;
  // Target patches before quadrangulation (each becomes 1 to 5 quad charts, or 3 to 8 kites, and
  // the repair may cut more); kAutoPatches: meshPatchTarget of the input's triangles; 0:
  // maxPatchError.
  uint32_t patches = kAutoPatches;
  double maxPatchError = 0.01;  // with patches = 0: RMS plane distance / bbox diagonal
  // Patches as planar as may be, or as developable (planes, cylinders, cones): fewer, larger
  // patches that parameterize with less stretch. kAuto: meshChartMetric of the input's triangles.
  MeshChartMetric chartMetric = MeshChartMetric::kAuto;
  uint32_t straightenRounds = 2;  // rounds of straightening shared sides (atlas/layout_refine.h)
  // Rounds of each repair (atlas/layout_refine.h repairCharts: cutting patches whose charts have
  // flipped texels or a sampling error over maxSampleError), in [0, 16]; 0 keeps the charting's.
  uint32_t repairRounds = 4;
  double repairBudget = 8.0;  // the repair's work cap: layout triangles parameterized again,
                              // as a multiple of the layout's triangles (counting at most
                              // kRepairTrianglesCounted of them), in [0, 100]
  // The largest sampling error a chart may keep (ImageQuality::sampleError) as a fraction of the
  // bounding-box diagonal, in [0, 0.1]; 0: only flips are repaired; kAutoSampleError:
  // kDefaultSampleError when the chart size is chosen by density (chartSize 0), else 0 (a chart
  // size given is kept as it is, with the patches it was given).
  double maxSampleError = kAutoSampleError;
  uint64_t maxMemory = 4ull << 30;              // bytes, at least 64 MiB; above a quarter of it the cells
                                                // (out-of-core) path runs
  bool measureFidelity = true;                  // two-sided Hausdorff distance input <-> atlas (out of core on
                                                // that path)
  MeshFidelity fidelity = MeshFidelity::kFast;  // how, in memory (the out-of-core path measures by blocks)
  // Compressed atlases: positions are quantized on one lattice of 2^positionBits steps across the
  // bounding-box diagonal (a power-of-two step), before the hierarchy and the fidelity are
  // measured, so shared seams stay bit-identical and the errors bound what is drawn.
  uint32_t positionBits = kDefaultPositionBits;
  // Compressed atlases: positions off a chart's border settle within this fraction of the
  // diagonal, in [0, 0.01], normal bytes within normalTolerance packed steps, in [0, 16], where
  // that makes their residuals 0 (kDefaultPositionTolerance; core/block_codec.h settlePositions).
  double positionTolerance = kDefaultPositionTolerance;
  uint32_t normalTolerance = kDefaultNormalTolerance;
  MeshNormals normals = MeshNormals::kAuto;
  // How patches become quad charts (atlas/mesh/resample.h QuadLayout): kites (n charts an n-sided
  // patch), sides (about n/2; side counts made even first), or auto: sides, and kites too if sides
  // leave flipped texels, corners where only two charts meet or a sampling error over the bound,
  // both at one chart size, from the density's up, doubled only while neither meets the bound
  // (see resampleMesh in pipeline/mesh_build.cpp).
  MeshQuads quads = MeshQuads::kAuto;
  // Each patch's charts at their own size, doubled where they fold or sample the surface more
  // coarsely than maxSampleError (one quad layout, no repair), or one size for every chart with the
  // repair and the layout search (atlas/mesh/quad_charts.h MeshSizing). A chartSize given asks for
  // one size.
  MeshSizing sizing = MeshSizing::kPatch;
  // How each quad chart's square maps into its quad of the patch's domain (atlas/mesh/resample.h
  // QuadMap): bilinear, least stretch, or least stretch for the charts that fold under bilinear.
  MeshQuadMap quadMap = MeshQuadMap::kBilinear;
  // Inner samples round flipped texels slide over the surface to unfold them (ResampleOptions::unfold).
  bool unfold = true;
  // Each chart keeps only the pyramid levels from the coarsest whose surface stays within
  // maxSampleError of the input (atlas/mesh/mesh_atlas.h ChartCoarsening; ChartInfo::finestLevel),
  // when maxSampleError is set, and the squares of each chart's finest level whose surface the two
  // triangles of their corners follow within what maxSampleError leaves move onto them, for the
  // block codec to store their corners alone (geometryPyramid's PlanarPlacement); false: every
  // chart keeps its whole pyramid, every sample where it was resampled.
  bool coarsenCharts = true;
};

// The default charting of a mesh of `triangles` triangles: few large charts, on the order of the
// paper's scans (30 charts on a 1M-triangle scan, 140 at 10M).
// - Up to kFewPatchesTriangles: 24 developable patches (67 to 120 quad charts in the sides layout
//   on the shared scans, after the repair's cuts). Planar patches that large fold on scans with
//   holes and thin parts (the bunny: 5 flipped texels left after the repair, the armadillo 1).
// - Above: planar patches, sqrt(triangles) / 80 of them, at least 48 (54 at 18.7M triangles: 171
//   quad charts). The repair of developable patches that large ran past 50 minutes on the 18.7M
//   sphere (single-threaded per patch), against 29 for planar ones.
inline constexpr uint64_t kFewPatchesTriangles = 4'000'000;
uint32_t meshPatchTarget(uint64_t triangles);
MeshChartMetric meshChartMetric(uint64_t triangles);

// The option's name as opts spell it in messages (CommonBuildOptions::spellOption).
inline std::string spelledOption(const CommonBuildOptions& opts, std::string_view name) {
  return opts.spellOption ? opts.spellOption(name) : std::string(name);
}

}  // namespace gimlod

// Mesh atlas stages 2-3: cluster a triangle mesh into a conforming chart layout of disk-shaped
// patches with minSides..maxSides sides (atlas/mesh/patch_layout.h), ready for quadrangulation.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (per-cell then global clustering);
// Garland, Willmott, Heckbert, "Hierarchical Face Clustering on Polygonal Surfaces", I3D 2001
// (greedy dual-edge collapse on planarity plus compactness); Purnomo, Cohen, Kumar, "Seamless
// Texture Atlases", SGP 2004 (n-sided patches, conforming layout).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "atlas/mesh/patch_layout.h"
#include "atlas/mesh/mesh_io.h"

namespace gimlod {

// The merge cost of clusters A and B (Garland et al. 2001, in normalised coordinates: bounding-
// box diagonal 1) is
//   area(AB) / area(mesh) * ( msd(AB) / 0.01^2 + 4 * spread(AB) + compactnessWeight * compact(AB) )
// msd: mean squared distance to the least-squares plane (smallest eigenvalue of the aggregated
// covariance / area); spread: 1 - |sum of area-weighted normals| / area (0 flat, 1 folded shut);
// compact: perimeter^2 / (4 pi area). The area factor makes small clusters merge first.
// With ChartMetric::kDevelopable the planarity and spread terms become
//   cone(AB) / 0.01 + spread(AB)
// cone: the least variance of the unit normals along an axis (coneFitVariance in
// charting_internal.h; the cone fit of D-Charts, Julius, Kraevoy, Sheffer, Eurographics 2005):
// 0 on planes, cylinders and cones, so clusters may curve one way (a limb, a flank) as long as
// they stay developable, which the n-gon parameterization flattens with little stretch.
// A merge is made only if the union stays a closed topological disk: A and B must meet in
// exactly one boundary arc (shared vertices = shared edges + 1).
enum class ChartMetric : uint8_t { kPlanar, kDevelopable };

struct ChartingOptions {
  // Stop merging at this many clusters. 0: merge until no merge keeps every chart within
  // maxError. Side fixing (splitting patches with more than maxSides sides) may add charts, and
  // merges that would break the disk property are refused, so the result can be above it.
  uint32_t targetPatches = 0;
  // Only when targetPatches == 0: the largest RMS distance of a chart's triangles to the chart's
  // least-squares plane, as a fraction of the bounding-box diagonal; > 0.
  double maxError = 0.01;
  // Weight of the compactness term perimeter^2 / (4 pi area) (1 for a disc) in the merge cost
  // above; >= 0. 0 ranks merges by planarity alone.
  double compactnessWeight = 1.0;
  // The shape term of the merge cost: planarity (plane fit and normal spread) or developability
  // (cone fit). maxError is a plane distance either way.
  ChartMetric metric = ChartMetric::kPlanar;
  // Sides per patch, inclusive. minSides >= 3; maxSides >= max(4, 2 * minSides - 3) so that a
  // split of a patch with too many sides leaves two valid halves.
  uint32_t maxSides = 8;
  uint32_t minSides = 3;
  // Worker threads for the per-cell / per-block clustering (the global merge and the side
  // fixing are serial). 0: all cores.
  unsigned threads = 0;
};

struct ChartingStats {
  uint64_t inputTriangles = 0;
  uint64_t outputTriangles = 0;      // inputTriangles - droppedDegenerate - droppedDuplicate
  uint64_t inputVertices = 0;        // positions referenced by the input triangles
  uint64_t outputVertices = 0;       // PatchLayout::positions
  uint64_t verticesWelded = 0;       // referenced positions merged into an equal earlier one
  uint64_t droppedDegenerate = 0;    // triangles with a repeated vertex after welding
  uint64_t droppedDuplicate = 0;     // triangles repeating another's 3 vertices after welding
  uint64_t nonManifoldEdges = 0;     // edges with > 2 triangles or inconsistent orientation
  uint64_t nonManifoldVertices = 0;  // vertices whose triangles form more than one fan
  uint64_t verticesSplit = 0;        // vertex copies made by the repair (bow-ties, fins)
  uint64_t boundaryEdges = 0;        // open edges after repair
  uint32_t charts = 0;
  uint32_t chartsBeforeFixing = 0;       // clusters when the greedy merging stopped
  uint32_t mergesRefusedNotDisk = 0;     // merge candidates refused by the disk check
  uint32_t cornersInserted = 0;          // extra corners for patches with < minSides sides
  uint32_t patchesSplit = 0;             // splits of patches with > maxSides sides
  uint32_t patchesUnfixed = 0;           // patches no split could fix (then the layout is invalid:
                                         // validatePatchLayout names them); 0 on all test meshes
  std::vector<uint32_t> sidesHistogram;  // [n] = patches with n sides
  double maxPlanarityError = 0.0;        // max over charts of the RMS plane distance / diagonal
  double meanPlanarityError = 0.0;       // area-weighted mean of the same
  double weldSeconds = 0.0;              // weld, repair, adjacency
  double clusterSeconds = 0.0;           // greedy merging (cells and global)
  double cellSeconds = 0.0;              // of which the per-cell / per-block phase (read, weld and
                                         // clustering of each cell, in parallel)
  double sidesSeconds = 0.0;             // corners, side fixing, layout output
  double seconds = 0.0;                  // total
  uint64_t peakBytesEstimate = 0;        // largest sum of the big arrays held at once
  // Cells of buildPatchLayoutFromCells, or spatial blocks of buildPatchLayout (large meshes).
  uint32_t cells = 0;
  uint32_t cellClusters = 0;           // clusters handed from the cells / blocks to the global stage
  uint32_t cellClustersDissolved = 0;  // of those, not disks in the global mesh (re-split)
};

// Clusters an in-memory mesh into a conforming layout.
// 1. Welds exactly equal positions (+0 and -0 equal), drops triangles that become degenerate or
//    duplicate (same 3 vertices, any order).
// 2. Repair: half-edges are paired per undirected edge; an edge with more than 2 triangles, or 2
//    with the same direction (inconsistent orientation), pairs its first opposite half-edges
//    and leaves the rest open (nonManifoldEdges). Every vertex whose triangles then form more
//    than one fan is split into one vertex per fan (verticesSplit), so a fin or a flipped
//    triangle becomes an open border and PatchLayout::positions may hold copies of a position.
// 3. Greedy merging (cost above) down to targetPatches, or while within maxError. Above 32768
//    triangles the surface is first cut into spatial blocks of about 8192 triangles, each
//    clustered on its own (in parallel) to clusters of about a quarter of the final chart size
//    (1024 triangles in error mode), then merged globally: the two phases of the cells path,
//    several times faster than one global queue, with charts as good.
// 4. Sides: a corner is a vertex where 3 or more patches meet, or 2 patches and the open
//    boundary. Patches with fewer than minSides corners get corners at the middle (by length) of
//    their longest runs; the patch across gains a side there, so the layout stays conforming.
//    Patches with more than maxSides sides are split along a shortest interior path between two
//    corners about half the corners apart (falling back to paths ending at non-corner boundary
//    vertices, which become corners), repeatedly; the count can therefore end above target.
// The triangles keep their winding (counter-clockwise assumed outward); PatchLayout::triangles
// holds the surviving triangles in input order (renumbered vertices). Throws InputError on bad
// options, indices out of range, non-finite referenced positions, or no triangle left.
PatchLayout buildPatchLayout(const IndexedMesh& mesh, const ChartingOptions& options = {},
                             ChartingStats* stats = nullptr);

// Clusters the cells written by gridify (atlas/mesh/gridify.h). Each cell is welded and clustered
// on its own, in parallel, down to clusters of about a quarter of the final chart size; the global
// stage then welds all cells together (recovering the boundaries between cells), keeps every cell
// cluster that is still a disk, and merges on to the target as buildPatchLayout does.
// note: reduced out-of-core: the global stage holds all triangles (the PatchLayout returned
// holds them anyway); only the per-cell clustering is cell-local. The global stage's peak is
// about 2.3 times the returned layout (positions, triangles, half-edge twins, labels): 932 MiB
// for an 18.7M-triangle sphere. Throws InputError as readGridManifest / readCell, and as
// buildPatchLayout.
PatchLayout buildPatchLayoutFromCells(const std::filesystem::path& gridDir, const ChartingOptions& options = {},
                                      ChartingStats* stats = nullptr);

}  // namespace gimlod

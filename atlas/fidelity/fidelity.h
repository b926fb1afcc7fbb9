// Atlas fidelity: the two-sided distance between the input mesh and the atlas surface, as the
// atlas's quality figure (a sampled Hausdorff distance, in units of the input's bounding-box
// diagonal). Uses CGAL's AABB tree for the closest-point queries.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include <glm/vec3.hpp>

namespace gimlod {

struct FidelityStats {
  double diagonal = 0.0;        // of the input mesh's bounding box
  double maxAtlasToMesh = 0.0;  // over every atlas vertex: distance to the input surface
  double meanAtlasToMesh = 0.0;
  double maxMeshToAtlas = 0.0;  // over every input vertex and triangle centroid: to the atlas
  double meanMeshToAtlas = 0.0;
  double hausdorff = 0.0;         // max of the two maxima
  double hausdorffPercent = 0.0;  // hausdorff / diagonal * 100
  double meanPercent = 0.0;       // mean of the two means / diagonal * 100
  uint64_t atlasSamples = 0, meshSamples = 0;
  double seconds = 0.0;
  // Out of core (measureFidelityOutOfCore) only:
  uint32_t blocks = 0;               // blocks of grid cells measured one at a time
  uint64_t samplesBeyondMargin = 0;  // samples whose closest point lay beyond their block's margin
                                     // (found by a second pass over the whole other surface)
  bool exact = true;                 // false: some samples beyond the margin were not resolved
                                     // (too many to hold); they count at the margin, so the
                                     // maximum is a lower bound
  // Chart by chart (measureFidelityByCharts) only:
  uint64_t atlasSamplesTotal = 0;  // the atlas's samples, of which atlasSamples were measured
  // With a subset measured: with 99% confidence, at most this fraction of the atlas samples lie
  // farther from the input than maxAtlasToMesh (ln(100) / atlasSamples); 0 when all were.
  double atlasFractionAbove = 0.0;
};

// Where the distances lie, sample by sample (for inspection).
struct FidelityDetail {
  std::vector<float> atlasDistances;   // per atlas position: to the input surface
  std::vector<glm::vec3> meshSamples;  // the input's samples: its used vertices, then its triangles'
                                       // centroids (non-degenerate ones, in order)
  std::vector<float> meshDistances;    // per input sample: to the atlas surface
  std::vector<glm::vec3> meshClosest;  // per input sample: the closest point of the atlas surface
};

// Both surfaces as positions + triangles. The atlas side is sampled at its vertices (the chart
// samples), the mesh side at its vertices and triangle centroids. detail, if given, receives
// every sample's distance. Throws std::invalid_argument when either surface has no triangles.
FidelityStats measureFidelity(const std::vector<glm::vec3>& meshPositions,
                              const std::vector<std::array<uint32_t, 3>>& meshTriangles,
                              const std::vector<glm::vec3>& atlasPositions,
                              const std::vector<std::array<uint32_t, 3>>& atlasTriangles,
                              FidelityDetail* detail = nullptr);

// How the atlas fidelity is measured: fast reads the atlas a chart at a time (the input side exact,
// the atlas side on about a million samples, with the confidence stated; measureFidelityByCharts),
// full welds the whole atlas surface and measures every sample of both (measureFidelity).
enum class MeshFidelity : uint8_t { kFast, kFull };

struct ChartFidelityOptions {
  // Atlas samples measured against the input: every one when the atlas has at most this many,
  // else a subset of about this many, each sample kept or not by a hash of its chart and index
  // (independent draws, so the maximum over them bounds all but a stated fraction; see
  // FidelityStats::atlasFractionAbove).
  uint64_t atlasSamples = 1ull << 20;
  // A mesh sample is measured against the charts whose box, widened by this fraction of the
  // diagonal, holds it; one left with nothing that close is measured again against every chart.
  double marginFraction = 0.005;
};

// measureFidelity against the geometry atlas in atlasDir as it is drawn at level 0 (each chart at
// its finest level, stitched to its neighbours as readAtlasSurface stitches them), read a chart at
// a time (its samples and a tree of its triangles on one thread; the whole atlas is never held):
// the mesh side is exact, every input vertex and triangle centroid against every chart that could
// be closest; the atlas side measures every sample, or the subset options.atlasSamples chooses.
// Throws InputError naming the atlas or chart file on a bad atlas, std::invalid_argument when
// either surface has no triangles or the options are absurd.
FidelityStats measureFidelityByCharts(const std::vector<glm::vec3>& meshPositions,
                                      const std::vector<std::array<uint32_t, 3>>& meshTriangles,
                                      const std::filesystem::path& atlasDir, const ChartFidelityOptions& options = {});

struct OutOfCoreFidelityOptions {
  uint64_t memoryBytes = 1ull << 30;  // what one block's surfaces, trees and samples may take (estimated)
  double marginFraction = 0.005;      // search margin around a block, as a fraction of the diagonal
  uint32_t maxBlockCells = 0;         // at most this many grid cells per block side; 0 = as many as fit
};

// measureFidelity for a mesh held as gridify cell files (atlas/mesh/gridify.h) and the level-0
// surface of a geometry atlas on disk (as readAtlasSurface triangulates it), without holding either
// surface: space is cut into blocks of grid cells, as large as fit in options.memoryBytes. A
// block's samples (the input's distinct vertex positions and its triangles' centroids, the atlas's
// distinct sample positions, each in the one block holding it) are measured against the triangles
// of both surfaces within the margin around the block; a sample with nothing that close is measured
// again in a second pass over the whole other surface. So the figures are exact, and those of
// measureFidelity on the same surfaces (up to input vertices that share a position). Throws
// InputError naming the file on a bad grid or atlas, std::invalid_argument when either surface has
// no triangles or the options are absurd.
FidelityStats measureFidelityOutOfCore(const std::filesystem::path& gridDir, const std::filesystem::path& atlasDir,
                                       const OutOfCoreFidelityOptions& options = {});

}  // namespace gimlod

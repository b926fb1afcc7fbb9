// The mesh atlas on disk: geometry charts (the quad charts of a resampled chart layout) written
// as chart files with their pyramids, and the atlas surface read back as one welded mesh (the
// `gimlod export` command), so that its fidelity can be checked with any mesh tool.
// Based on: Niski, Purnomo, Cohen, I3D 2007, sections 3 and 5 (seamless geometry-image atlas,
// 2^k+1 pyramids by subsampling).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include <glm/vec3.hpp>

#include "atlas/mesh/resample.h"
#include "core/atlas_format.h"

namespace gimlod {

// The pyramid of one geometry chart: level k keeps every 2^k-th sample of level 0 (so shared
// borders stay bit-identical at every level), down to 2 intervals per side. Compressed coding:
// level 0's positions are settled on the coding's lattice and its normals within the coding's
// tolerances (settlePositions, settleNormals: the border to the nearest lattice point, the rest
// within the tolerances), as a compressed chart file decodes them; the other levels subsample it.
// finestLevel (ChartInfo::finestLevel): the pyramid starts at the image's level finestLevel,
// subsampled before it is settled.
// Planar squares (compressed coding, planar.budget > 0): then the settled finest level's squares
// (blocks of planar.blockIntervals samples, their halves, ... down to 2 intervals, largest first,
// never a chart-border sample) whose samples may move onto the two triangles of their corners, as
// the block codec's planar squares put them (planarSquareSample), do: where the surface drawn from
// that level then stays within planar.budget of every level-0 sample of the square's footprint, or
// no farther than it did before. Measured again on the whole result: squares beside a sample over
// it stay as they were. The codec then stores their corners alone. planarSamples, if given,
// receives the number of samples moved.
// Throws std::invalid_argument on images that do not match chartSize, or a finest level past its
// pyramid.
struct PlanarPlacement {
  double budget = 0.0;  // input units; 0: none
  uint32_t blockIntervals = 64;
};
ChartPyramid geometryPyramid(const GeometryImage& image, uint32_t chartSize, const ChartCoding& coding = {},
                             uint32_t finestLevel = 0, const PlanarPlacement& planar = {},
                             uint64_t* planarSamples = nullptr);

// The angles between the normals a reader derives (geometryImageNormals) and the resampled
// ones, over the samples whose normals are derived (level 0, off block borders), in degrees.
struct NormalAngles {
  uint64_t samples = 0;
  double mean = 0.0, median = 0.0, p99 = 0.0, max = 0.0;
};

struct GeometryChartsWritten {
  uint64_t bytes = 0;
  double seconds = 0.0;
  std::array<float, 6> bounds{};              // min x, y, z, max x, y, z over every sample
  NormalAngles normalAngles;                  // coding.deriveGeometryNormals only
  std::vector<uint32_t> chartsByFinestLevel;  // [finest level]: charts that keep it (ChartInfo)
  uint64_t finestSamples = 0;                 // the charts' finest levels' samples, summed
  uint64_t planarSamples = 0;                 // of those, the ones moved onto planar squares
};

// How far writeGeometryCharts may coarsen each chart (ChartInfo::finestLevel): to the coarsest
// pyramid level, at most maxFinestLevel, whose surface stays within `bound` of the input vertices:
// the chart's sampling error (ImageQuality::sampleError, to its level 0) plus the farthest its
// level-0 samples lie from that level's surface (as the renderer triangulates it). bound 0: none.
struct ChartCoarsening {
  double bound = 0.0;  // input units
  uint32_t maxFinestLevel = 0;
};

// The finest level `c` allows a chart of chartSize^2 positions whose sampling error is
// sampleError: the largest k <= c.maxFinestLevel with sampleError + levelError(k) <= c.bound,
// levelError(k) the largest distance from a level-0 sample to the surface of level k' at its
// (u, v), over k' <= k (so that it never drops as k grows).
uint32_t chartFinestLevel(const std::vector<glm::vec3>& positions, uint32_t chartSize, double sampleError,
                          const ChartCoarsening& c);
// chartFinestLevel of every chart of `set` (in parallel; spilled charts read back from `spill`),
// as a level of set.chartSize: a chart sampled at its own size (GeometryImage::level) keeps at
// least that level, and is coarsened from there, never past a level with more flipped texels than
// its own samples have (GeometryImage::flippedAtLevel), so the flipped texels a build reports are
// those of the levels it keeps.
std::vector<uint32_t> chartFinestLevels(const GeometryImageSet& set, const ChartSpill* spill, const ChartCoarsening& c);

// Writes set's charts to dir/charts/chart_NNNN.bin (atomically, in parallel) and fills m's
// kind ("geometry"), chart size, block size, chart list (file names, neighbours) and height
// range (z of the bounds). blockIntervals: a power of two <= chartSize - 1. Charts whose samples
// were spilled are read back from `spill`, one at a time per thread. Compressed coding settles
// the samples first (geometryPyramid; the bounds are of the settled positions) and records the
// lattice and the tolerances in m.compression; with coding.deriveGeometryNormals it stores the
// normals of block borders only and measures the derived ones against the resampled ones.
// Throws InputError when a file cannot be written, std::invalid_argument on an empty or
// inconsistent set. With finestLevels (one per chart, as chartFinestLevels gives), each chart keeps
// only the levels from its finest (never finer than its own samples, GeometryImage::level; without
// finestLevels, its own), subsampled from its samples before they are settled, in a file
// of its own size (blocks of at most its intervals), and m's chart records the level. planarBound
// (input units, > 0; compressed coding): each chart's finest level moves its planar squares within
// planarBound less the chart's sampling error (geometryPyramid's PlanarPlacement).
GeometryChartsWritten writeGeometryCharts(const GeometryImageSet& set, const std::filesystem::path& dir,
                                          uint32_t blockIntervals, AtlasManifest& m, const ChartSpill* spill = nullptr,
                                          const ChartCoding& coding = {},
                                          const std::vector<uint32_t>& finestLevels = {}, double planarBound = 0.0);

// The surface of a geometry atlas (or a planet atlas, its heights on the sphere) at pyramid level
// `level`: every chart's grid, triangulated as
// the renderer draws it (split along the (0,0)-(1,1) diagonal, counter-clockwise in (u, v)), with
// vertices of bit-identical positions welded into one (the seams), so a seamless atlas gives a
// watertight mesh wherever the input was closed.
struct AtlasSurface {
  std::vector<glm::vec3> positions;
  std::vector<std::array<uint32_t, 3>> triangles;
  uint64_t samples = 0;        // chart samples read (before welding)
  uint64_t boundaryEdges = 0;  // edges used by one triangle only (0 for a closed input)
};
// Throws InputError naming the atlas or chart file on a missing or corrupt atlas, a flat height-field
// atlas, or a level the charts do not have.
AtlasSurface readAtlasSurface(const std::filesystem::path& atlasDir, uint32_t level);

// Chart i of the atlas in atlasDir (manifest m) at `level` as the renderer draws it, side
// ((m.chartSize - 1) >> max(level, finestLevel)) + 1 samples: at its own finest level where that
// is coarser, and its border samples facing a neighbour drawn coarser moved onto that
// neighbour's lattice. Throws InputError naming the chart file as readAtlasSurface does.
std::vector<glm::vec3> readDrawnChartLevel(const std::filesystem::path& atlasDir, const AtlasManifest& m, size_t i,
                                           uint32_t level);

// Writes a binary little-endian PLY (float x y z, uchar-list int vertex_indices), atomically.
void writePly(const std::filesystem::path& path, const std::vector<glm::vec3>& positions,
              const std::vector<std::array<uint32_t, 3>>& triangles);

}  // namespace gimlod

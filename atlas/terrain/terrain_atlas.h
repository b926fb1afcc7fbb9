// Height-field atlas: partitions a DEM into (2^m+1)^2 charts with a one-sample overlap, builds
// each chart's subsampled pyramid and normal map, and writes them in blocks.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, sections 4 and 6 (height-field case).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

#include "atlas/terrain/dem.h"
#include "core/atlas_format.h"

namespace gimlod {

struct TerrainAtlasOptions {
  uint32_t chartSize = 513;      // samples per chart side; must be 2^m + 1, 9..8193
  uint32_t blockIntervals = 64;  // block / max node resolution R; power of two, 4..1024
  ChartCoding coding;            // how chart files store blocks (compressed: format version 2)
};

struct TerrainAtlasStats {
  uint32_t charts = 0;
  uint64_t samples = 0;        // DEM samples
  uint64_t storedSamples = 0;  // samples in all pyramid levels of all charts
  uint64_t bytesOnDisk = 0;
  double seconds = 0.0;
};

// Throws InputError if chartSize is not 2^m+1 in 9..8193, or blockIntervals is not a power of
// two in 4..1024 and <= chartSize-1. Messages name the parameters (optionRef: "chartSize",
// "blockIntervals").
void validateTerrainAtlasOptions(const TerrainAtlasOptions& options);

// The step a compressed atlas quantizes a DEM's heights that are not whole to: `requested` if it
// is > 0, else 1 for a DEM of whole metres and `fallback` otherwise. Throws InputError naming
// `input` when heights in [lo, hi] span more than 2^23 steps of it.
double terrainHeightPrecision(const std::filesystem::path& input, double requested, bool integerHeights,
                              double fallback, float lo, float hi);
// A height as a compressed atlas stores it: whole metres exactly, others quantized to `precision`.
float storedHeight(float h, double precision);

// Relative path of chart `id`'s file inside the atlas directory: "charts/chart_0007.bin".
std::string chartFileName(uint32_t id);

// The chart's level-0 heights, (chartSize)^2 row-major (row = v = north), edge-clamped outside
// the DEM. Shared by the writer and the tests.
std::vector<float> extractChart(const DemRaster& dem, int32_t gridX, int32_t gridY,
                                uint32_t chartSize);

// Rows [y0, y0 + rows) and columns [x0, x0 + cols) of a DEM's heights, row-major: what a group
// of charts' pyramids are built from when the DEM does not fit in memory. Access is edge-clamped
// to the whole DEM (width x height), and must fall inside the window held.
struct DemRows {
  const float* heights = nullptr;
  int64_t y0 = 0, rows = 0;
  int64_t x0 = 0, cols = 0;       // cols 0: every column (cols = width)
  int64_t width = 0, height = 0;  // the whole DEM
  std::array<double, 2> spacing{1.0, 1.0};
};
// The rows a chart row needs (its own, and a chart's worth each side for the coarse levels'
// normals): [max(0, gridY * m - m), min(height, gridY * m + 2m + 1)), m = chartSize - 1. The
// columns a chart column needs are the same span of gridX and the width.
std::array<int64_t, 2> chartRowSpan(int64_t gridY, uint32_t chartSize, int64_t height);
ChartPyramid buildChartPyramid(const DemRows& dem, int32_t gridX, int32_t gridY, uint32_t chartSize,
                               bool keepRing = false);

// Builds the pyramid (subsampling) and normal maps of one chart. The normal at a sample comes from
// central differences of the global DEM at that level's spacing (heightFieldNormals), so shared
// borders match. keepRing: also the ring heights and frame a compressed file derives normals from.
ChartPyramid buildChartPyramid(const DemRaster& dem, int32_t gridX, int32_t gridY,
                               uint32_t chartSize, bool keepRing = false);

// Fills the manifest's chart fields for `dem` (chart grid, files, root neighbours, spacing,
// samples, height range, georeference, voids) without writing anything.
void fillTerrainManifest(const DemRaster& dem, const TerrainAtlasOptions& options,
                         AtlasManifest& manifest);

// Writes all chart files into `dir` (which must exist) and fills the manifest's chart fields
// (kind, chartSize, blockIntervals, chartsX/Y, charts, neighbours, spacing, samples, heightRange,
// georef, voids; maxNodeResLog2 is capped at log2(blockIntervals)). zScale, source and the
// hierarchy depth are left to the caller. Charts are written in parallel.
TerrainAtlasStats writeTerrainCharts(const DemRaster& dem, const TerrainAtlasOptions& options,
                                     const std::filesystem::path& dir, AtlasManifest& manifest);

}  // namespace gimlod

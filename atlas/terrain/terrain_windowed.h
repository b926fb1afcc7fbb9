// The terrain atlas of a DEM larger than memory, built window by window within a memory budget:
// the DEM is read through GDAL in bands of rows into a compressed scratch raster beside the atlas
// (atlas/terrain/scratch_raster.h), its voids are filled window by window (atlas/terrain/
// void_fill.h, bit-identical to the whole-raster fill), and the charts are built a chart row at a
// time, in groups of chart columns, from the window of samples each group needs (quantized as a
// compressed atlas stores them). Memory does not grow with the DEM's width or height. A DEM that
// fits in memory gives byte-identical chart files either way.
#pragma once

#include <cstdint>
#include <filesystem>

#include <memory>
#include <vector>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/scratch_raster.h"
#include "atlas/terrain/terrain_atlas.h"

namespace gimlod {

struct WindowedTerrainOptions {
  TerrainAtlasOptions atlas;  // chart size, block size, coding (its height precision: see below)
  // Compressed atlases: heights that are not whole are quantized to this step, in metres; 0: 1 for
  // a DEM of whole metres, else kDefaultHeightPrecision (what the in-memory build chooses).
  double heightPrecision = 0.0;
  double defaultHeightPrecision = 0.01;
  uint64_t memoryBytes = uint64_t{1} << 30;  // what the rows, windows and charts in flight may use
  // The side of the tiles charts are built in (ChartTiling::tile; the chart's intervals: whole), which
  // the chart files' block order follows; 0: the largest that memoryBytes allows (windowTiling).
  uint32_t chartTile = 0;
};
// The tile side charts of chartSize with blocks of blockIntervals are built in window by window
// within `budget` bytes: the chart whole (chartSize - 1) where it fits.
uint32_t windowChartTile(uint32_t chartSize, uint32_t blockIntervals, uint64_t budget);

struct WindowedTerrainResult {
  DemRaster dem;  // the DEM's metadata, heights empty; voids, range, integerHeights
  TerrainAtlasStats charts;
  double heightPrecision = 0;  // the step used (compressed atlases)
  uint64_t scratchBytes = 0;   // the most the scratch raster took on disk (removed at the end)
  uint32_t scratchTile = 0;    // its tiles' side
  uint64_t bandRows = 0;       // the most DEM rows a window of charts held
  uint64_t bandColumns = 0;    // and the most columns
};

// Builds the chart files of `source` into dir (which must exist; the scratch raster lives there
// while the build runs) and fills the manifest's chart fields, like writeTerrainCharts. Throws
// InputError naming the DEM when one chart's window exceeds the memory budget, or when every
// sample is a void.
WindowedTerrainResult writeTerrainChartsWindowed(const DemSource& source, const std::filesystem::path& dir,
                                                 const WindowedTerrainOptions& options, AtlasManifest& manifest);

// The two halves of writeTerrainChartsWindowed, for builds that write the charts in several
// processes (pipeline/sharded_build.h).
// - prepareTerrainWindows: the DEM read into a scratch raster at scratchFile, its voids filled, the
//   height step chosen (result.heightPrecision) and the manifest's chart fields filled; the result's
//   chart figures stay 0.
// - writeTerrainChartWindows: the chart files of `charts` (chart indices; empty: every chart) from
//   the scratch raster into dir, with r.heightPrecision; their figures go into r.charts. The files
//   are those the whole build writes, whichever charts are asked for.
struct PreparedTerrainWindows {
  std::unique_ptr<ScratchRaster> scratch;
  WindowedTerrainResult result;
};
PreparedTerrainWindows prepareTerrainWindows(const DemSource& source, const std::filesystem::path& scratchFile,
                                             const WindowedTerrainOptions& options, AtlasManifest& manifest);
void writeTerrainChartWindows(const ScratchRaster& scratch, const std::filesystem::path& dir,
                              const WindowedTerrainOptions& options, const AtlasManifest& manifest,
                              const std::vector<uint32_t>& charts, WindowedTerrainResult& r);

}  // namespace gimlod

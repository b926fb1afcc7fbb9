// The terrain atlas of a DEM larger than memory, built window by window within a memory budget:
// the DEM is read through GDAL in bands of rows into a scratch raster beside the atlas, its voids
// are filled window by window (atlas/terrain/void_fill.h, bit-identical to the whole-raster fill),
// its heights quantized for a compressed atlas, and the charts built a chart row at a time from
// the rows that row needs. A DEM that fits in memory gives byte-identical chart files either way.
#pragma once

#include <cstdint>
#include <filesystem>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"

namespace gimlod {

struct WindowedTerrainOptions {
  TerrainAtlasOptions atlas;   // chart size, block size, coding (its height precision: see below)
  // Compressed atlases: heights that are not whole are quantized to this step, in metres; 0: 1 for
  // a DEM of whole metres, else kDefaultHeightPrecision (what the in-memory build chooses).
  double heightPrecision = 0.0;
  double defaultHeightPrecision = 0.01;
  uint64_t memoryBytes = uint64_t{1} << 30;  // what the rows, windows and charts in flight may use
};

struct WindowedTerrainResult {
  DemRaster dem;               // the DEM's metadata, heights empty; voids, range, integerHeights
  TerrainAtlasStats charts;
  double heightPrecision = 0;  // the step used (compressed atlases)
  uint64_t scratchBytes = 0;   // the scratch raster's size on disk (removed at the end)
  uint64_t bandRows = 0;       // the most DEM rows held at once
};

// Builds the chart files of `source` into dir (which must exist; the scratch raster lives there
// while the build runs) and fills the manifest's chart fields, like writeTerrainCharts. Throws
// InputError naming the DEM when a chart row's rows exceed the memory budget, or when every
// sample is a void.
WindowedTerrainResult writeTerrainChartsWindowed(const DemSource& source, const std::filesystem::path& dir,
                                                 const WindowedTerrainOptions& options, AtlasManifest& manifest);

}  // namespace gimlod

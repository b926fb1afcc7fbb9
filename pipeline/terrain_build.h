// The stages of a terrain build: DEM -> read and fill -> charts and pyramids (atlas/) ->
// hierarchy (hierarchy/) -> manifest.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, sections 4 and 6 (height-field case).
#pragma once

#include <filesystem>

#include "atlas/terrain/dem.h"
#include "pipeline/build_options.h"
#include "pipeline/build_stats.h"

namespace gimlod {

// Throws InputError naming the parameter (optionRef) for impossible options, before any work. An
// automatic chart size (kAutoChartSize) passes; planTerrain chooses it.
void validateTerrainBuildOptions(const TerrainBuildOptions& options);

// The chart grid of a terrain atlas. Each chart is a quadtree root, so a cut never has fewer nodes
// than the charts in view: when the size is not given, a DEM gets the smallest chart from 513
// samples up that keeps its charts at most kTargetTerrainCharts (tens of trees, as the paper's
// terrains have, from 1M to 21.6G samples), up to kMaxTerrainChartSize. The depth, when not
// given, leaves the finest nodes 32 intervals wide (kDefaultDepth at least), one level less while
// the hierarchy, which the build holds whole, would take over a quarter of the memory cap
// (terrainHierarchyBytes; --max-memory, or three quarters of the machine's).
struct TerrainPlan {
  uint32_t chartSize = 0;
  uint32_t depth = 0;
  uint32_t chartsX = 0, chartsY = 0;
  bool autoChartSize = false, autoDepth = false;
};
inline constexpr uint32_t kTargetTerrainCharts = 64;
// The bytes a terrain hierarchy of `charts` trees of `depth` levels holds in memory (bounds, flags
// and an error for each of resCount resolutions, per node).
uint64_t terrainHierarchyBytes(uint64_t charts, uint32_t depth, uint32_t resCount);
// Throws InputError naming `input` for a DEM under 2 x 2 samples.
TerrainPlan planTerrain(const std::filesystem::path& input, uint64_t width, uint64_t height,
                        const TerrainBuildOptions& options);
// The options with the plan's chart size and depth in place of the automatic ones.
TerrainBuildOptions plannedOptions(const TerrainBuildOptions& options, const TerrainPlan& plan);

// Read and fill: loads options.input (voids filled by pull-push, atlas/terrain/dem.h) and logs its
// figures. Throws InputError naming the file.
DemRaster readTerrain(const TerrainBuildOptions& options, TerrainReadStats* stats);

// Chart and write: writes the chart files of `dem` (freed once they are written), the hierarchy
// and the manifest into dir (the staging directory). Throws InputError when a file cannot be
// written.
TerrainWriteStats writeTerrainAtlas(DemRaster&& dem, const TerrainBuildOptions& options,
                                    const std::filesystem::path& dir);

}  // namespace gimlod

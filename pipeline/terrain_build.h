// The stages of a terrain build: DEM -> read and fill -> charts and pyramids (atlas/) ->
// hierarchy (hierarchy/) -> manifest.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, sections 4 and 6 (height-field case).
#pragma once

#include <filesystem>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/imagery.h"
#include "atlas/terrain/terrain_windowed.h"
#include "hierarchy/hierarchy.h"
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
  uint64_t samplesX = 0, samplesY = 0;  // the DEM's own size
  bool autoChartSize = false, autoDepth = false;
};
inline constexpr uint32_t kTargetTerrainCharts = 64;
inline constexpr uint32_t kMinPlannedChartSize = 513;  // the smallest chart the plan chooses
// The bytes a terrain hierarchy of `charts` trees of `depth` levels holds in memory (bounds, flags
// and an error for each of resCount resolutions, per node).
uint64_t terrainHierarchyBytes(uint64_t charts, uint32_t depth, uint32_t resCount);
// Throws InputError naming `input` for a DEM under 2 x 2 samples.
TerrainPlan planTerrain(const std::filesystem::path& input, uint64_t width, uint64_t height,
                        const TerrainBuildOptions& options);
// The options with the plan's chart size and depth in place of the automatic ones.
TerrainBuildOptions plannedOptions(const TerrainBuildOptions& options, const TerrainPlan& plan);

// Checks the options and the input (throws InputError naming the file or the parameter), plans the
// chart size and depth from the DEM's size and logs them: the options every stage of the build
// takes.
TerrainBuildOptions plannedTerrainBuild(const TerrainBuildOptions& options, TerrainPlan* plan = nullptr);

// How the stages open the DEM (GDAL's block cache capped from the memory cap; a planet's lattice).
// The chart size must be planned.
DemOptions terrainDemOptions(const TerrainBuildOptions& options);
// Logs what opening or reading the DEM found: its warnings (options spelled as o spells them) and
// the planet lattice it was laid on.
void logTerrainSource(const TerrainBuildOptions& o, const DemRaster& dem);
// How the build opens its imagery (options.imagery and the imagery options).
ImageryOptions imageryOptions(const TerrainBuildOptions& options);
// The manifest fields a build sets before its charts are written.
AtlasManifest terrainManifest(const TerrainBuildOptions& options);
TerrainAtlasOptions terrainAtlasOptions(const TerrainBuildOptions& options);
// The window-by-window build's options: its windows take 4/5 of the memory cap above what the
// process holds.
WindowedTerrainOptions windowedTerrainOptions(const TerrainBuildOptions& options);
// The hierarchy of the charts m lists, read from their files in dir (level 0 of each, window by
// window, as a restarted stage would read it); a planet's on the sphere.
Hierarchy measureTerrainHierarchy(const AtlasManifest& m, const std::filesystem::path& dir, HierarchyStats* stats);

// Read and fill: loads options.input (voids filled by pull-push, atlas/terrain/dem.h) and logs its
// figures. Throws InputError naming the file.
DemRaster readTerrain(const TerrainBuildOptions& options, TerrainReadStats* stats);

// Chart and write: writes the chart files of `dem` (freed once they are written), the hierarchy
// and the manifest into dir (the staging directory). Throws InputError when a file cannot be
// written.
TerrainWriteStats writeTerrainAtlas(DemRaster&& dem, const TerrainBuildOptions& options,
                                    const std::filesystem::path& dir);

}  // namespace gimlod

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

// Throws InputError naming the parameter (optionRef) for impossible options, before any work.
void validateTerrainBuildOptions(const TerrainBuildOptions& options);

// Read and fill: loads options.input (voids filled by pull-push, atlas/terrain/dem.h) and logs its
// figures. Throws InputError naming the file.
DemRaster readTerrain(const TerrainBuildOptions& options, TerrainReadStats* stats);

// Chart and write: writes the chart files of `dem` (freed once they are written), the hierarchy
// and the manifest into dir (the staging directory). Throws InputError when a file cannot be
// written.
TerrainWriteStats writeTerrainAtlas(DemRaster&& dem, const TerrainBuildOptions& options,
                                    const std::filesystem::path& dir);

}  // namespace gimlod

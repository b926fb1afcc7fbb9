// `gimlod build`: a DEM -> charts and pyramids (atlas/) -> hierarchy (hierarchy/) -> manifest;
// or a mesh -> (cell files ->) charting -> quads, parameterization and resampling -> geometry
// chart pyramids -> geometry hierarchy -> manifest. Staged in a temporary directory and renamed
// into place, so an interrupted or failed build never leaves a half-valid atlas. The stages are
// in pipeline/terrain_build.h and pipeline/mesh_build.h; pipeline/input_kind.h tells which an
// input needs.
#pragma once

#include <nlohmann/json.hpp>

#include "pipeline/build_options.h"
#include "pipeline/build_stats.h"

namespace gimlod {

// Builds the atlas of a DEM; returns the statistics also written to output/stats.json.
// Throws InputError naming the file or the parameter (optionRef) and the problem; output is
// untouched on failure.
TerrainBuildStats buildTerrainAtlas(const TerrainBuildOptions& options);

// Builds the atlas of a mesh; returns the statistics also written to output/stats.json.
// Throws InputError naming the file or the parameter (optionRef) and the problem; output is
// untouched on failure.
MeshBuildStats buildMeshAtlas(const MeshBuildOptions& options);

// buildTerrainAtlas, returning the content of stats.json.
nlohmann::json buildAtlas(const TerrainBuildOptions& options);

// buildMeshAtlas, returning the content of stats.json.
nlohmann::json buildAtlas(const MeshBuildOptions& options);

}  // namespace gimlod

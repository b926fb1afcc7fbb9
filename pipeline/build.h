// `gimlod build`: a DEM -> charts and pyramids (atlas/) -> hierarchy (hierarchy/) -> manifest;
// or a mesh -> (cell files ->) charting -> quads, parameterization and resampling -> geometry
// chart pyramids -> geometry hierarchy -> manifest. Staged in a temporary directory and renamed
// into place, so an interrupted or failed build never leaves a half-valid atlas. The stages are
// in pipeline/terrain_build.h and pipeline/mesh_build.h; pipeline/input_kind.h tells which an
// input needs.
#pragma once

#include <cstdint>
#include <filesystem>

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

// What exportAtlasSurface wrote.
struct SurfaceExport {
  uint64_t vertices = 0, triangles = 0;
  uint64_t samples = 0;        // chart samples read (before welding)
  uint64_t boundaryEdges = 0;  // edges used by one triangle only (0 where the input was closed)
};

// `gimlod export`: the surface of a mesh or planet atlas at pyramid level `level`, every chart's
// grid triangulated as the renderer draws it and welded along the seams, written to `ply` (binary
// PLY, atomically). Throws InputError naming the atlas, the chart file or the output.
SurfaceExport exportAtlasSurface(const std::filesystem::path& atlasDir, uint32_t level,
                                 const std::filesystem::path& ply);

}  // namespace gimlod

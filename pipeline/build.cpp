#include "pipeline/build.h"

#include "pipeline/build_report.h"

#include "atlas/mesh/mesh_atlas.h"

namespace gimlod {

nlohmann::json buildAtlas(const TerrainBuildOptions& options) { return statsJson(buildTerrainAtlas(options)); }

nlohmann::json buildAtlas(const MeshBuildOptions& options) { return statsJson(buildMeshAtlas(options)); }

SurfaceExport exportAtlasSurface(const std::filesystem::path& atlasDir, uint32_t level,
                                 const std::filesystem::path& ply) {
  const AtlasSurface s = readAtlasSurface(atlasDir, level);
  writePly(ply, s.positions, s.triangles);
  return {s.positions.size(), s.triangles.size(), s.samples, s.boundaryEdges};
}

}  // namespace gimlod

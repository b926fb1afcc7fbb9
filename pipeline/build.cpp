#include "pipeline/build.h"

#include "pipeline/build_report.h"

namespace gimlod {

nlohmann::json buildAtlas(const TerrainBuildOptions& options) { return statsJson(buildTerrainAtlas(options)); }

nlohmann::json buildAtlas(const MeshBuildOptions& options) { return statsJson(buildMeshAtlas(options)); }

}  // namespace gimlod

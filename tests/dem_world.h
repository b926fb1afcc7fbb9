// A real DEM's quadtree hierarchy built in memory, for the tests of the adapters on real terrain.
#pragma once

#include <filesystem>

#include <glm/vec3.hpp>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "hierarchy/hierarchy.h"

namespace gimlod::test {

// A real DEM's hierarchy built in memory (no files), as `gimlod build` would with this chart size
// and depth (R = 64, minimum node resolution 4), with the world bounds of its valid data.
struct DemWorld {
  DemRaster dem;
  AtlasManifest m;
  Hierarchy h;
  glm::dvec3 lo, hi;
};

inline DemWorld loadDemWorld(const std::filesystem::path& file, uint32_t chartSize, uint32_t depth = 5) {
  DemWorld w;
  w.dem = loadDem(file);
  w.m.depth = depth;
  w.m.maxNodeResLog2 = 6;
  w.m.minNodeResLog2 = 2;
  TerrainAtlasOptions topt;
  topt.chartSize = chartSize;
  fillTerrainManifest(w.dem, topt, w.m);
  w.h = buildTerrainHierarchy(
      w.m, [&](uint32_t c) { return extractChart(w.dem, w.m.charts[c].gridX, w.m.charts[c].gridY, chartSize); });
  w.lo = {0, 0, w.dem.minHeight};
  w.hi = {(w.dem.width - 1) * w.dem.spacing[0], (w.dem.height - 1) * w.dem.spacing[1], w.dem.maxHeight};
  return w;
}

}  // namespace gimlod::test

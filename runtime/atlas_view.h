// An opened atlas: manifest plus hierarchy, checked against each other. Pure C++.
#pragma once

#include <filesystem>

#include <glm/glm.hpp>

#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"

namespace gimlod {

struct AtlasView {
  std::filesystem::path dir;
  AtlasManifest manifest;
  Hierarchy hierarchy;
  glm::dvec3 lo{0.0}, hi{0.0};  // world bounds of the valid data (mesh and planet atlases: of the charts)
};

// Reads dir/atlas.json and the hierarchy, and gathers the chart roots into groups of at most
// maxRoots top groups (buildRootGroups; 0: none, every chart root a root of the forest). Throws
// InputError naming the file on any problem.
AtlasView openAtlas(const std::filesystem::path& dir, uint32_t maxRoots = kDefaultMaxRoots);

}  // namespace gimlod

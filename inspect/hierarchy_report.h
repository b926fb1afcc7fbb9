// The hierarchy and streaming parts of the inspection report (inspect/report.h): per level, the
// nodes' errors at every resolution (the error-against-resolution curve) and a heat map of the
// errors over the chart layout at each resolution; bytes per level and per node page; and what the six axis views
// (runtime/camera.h) need at a 1-pixel tolerance: nodes, pages, triangles and the resolutions the
// stitching constraint raised.
#pragma once

#include <cstdint>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "runtime/atlas_view.h"

namespace gimlod {

// Figures of the hierarchy: "levels" (per level: nodes, and per resolution the largest and mean
// error in world units) and "heat_maps" (file names written into dir: one PNG per level and
// resolution, each node a cell coloured by its error there, log scale against the
// largest error, charts tiled in a grid, a DEM's at their place). Levels whose map would exceed
// maxImageSide pixels a side are listed without one.
nlohmann::json hierarchyFigures(const AtlasView& atlas, const std::filesystem::path& dir, uint32_t maxImageSide = 2048);

// Bytes per pyramid level and per node page, and the reference views' needs (width x height,
// 1-pixel tolerance, no node budget): per view nodes, triangles, page bytes, constraint raises;
// their means and maxima.
nlohmann::json streamingFigures(const AtlasView& atlas, uint32_t width = 640, uint32_t height = 480);

}  // namespace gimlod

// The source comparison of the inspection report (inspect/report.h, with --source): the atlas
// against the mesh it was built from, two-sided, sample by sample (atlas/fidelity): the Hausdorff
// figures, where the largest distances lie (atlas samples by chart and (u, v), input vertices and
// triangle centroids by position) and, for the charts farthest from the input, maps of every
// sample's distance.
#pragma once

#include <cstdint>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "core/atlas_format.h"

namespace gimlod {

// Compares the geometry atlas in atlasDir (level 0, every chart's grid as the renderer draws it)
// with the mesh `source`; writes the distance maps of the `mapCharts` farthest charts into dir.
// Throws InputError naming the source when it cannot be read or is not a mesh, or when the atlas
// is a height field.
nlohmann::json sourceComparison(const AtlasManifest& m, const std::filesystem::path& atlasDir,
                                const std::filesystem::path& source, const std::filesystem::path& dir,
                                uint32_t mapCharts = 6, uint32_t worstSamples = 16);

}  // namespace gimlod

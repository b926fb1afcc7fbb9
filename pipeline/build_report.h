// The build's report: stats.json and the summary `gimlod build` prints, both made from the
// stages' stats (pipeline/build_stats.h).
#pragma once

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "pipeline/build_stats.h"

namespace gimlod {

// The content of stats.json for a terrain build.
nlohmann::json statsJson(const TerrainBuildStats& stats);

// The content of stats.json for a mesh build.
nlohmann::json statsJson(const MeshBuildStats& stats);

// The summary printed after a terrain build into `output` (lines ending in '\n').
std::string buildSummary(const std::filesystem::path& output, const TerrainBuildStats& stats);

// The summary printed after a mesh build into `output`: the terrain lines, then what the input
// held and what was repaired.
std::string buildSummary(const std::filesystem::path& output, const MeshBuildStats& stats);

// Bytes of all files under dir (the atlas's size on disk).
uint64_t directoryBytes(const std::filesystem::path& dir);

// Writes json (indented by 2, with a final newline) to dir/stats.json, atomically. Throws
// InputError when it cannot be written.
void writeStatsFile(const std::filesystem::path& dir, const nlohmann::json& json);

}  // namespace gimlod

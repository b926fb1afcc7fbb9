// The build pipeline behind `gimlod build`: DEM -> charts and pyramids (atlas/) -> hierarchy
// (hierarchy/) -> manifest, staged in a temporary directory and renamed into place, so an
// interrupted or failed build never leaves a half-valid atlas.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

namespace gimlod {

struct BuildOptions {
  std::filesystem::path input;
  std::filesystem::path output;
  std::string subdataset;     // netCDF variable; empty: the first 2D one
  uint32_t chartSize = 513;   // samples per chart side, 2^m + 1
  uint32_t depth = 5;         // quadtree levels per chart
  uint32_t nodeRes = 64;      // maximum node resolution R (intervals, power of two)
  uint32_t minNodeRes = 4;    // minimum node resolution (intervals, power of two)
  double zScale = 1.0;
  uint32_t threads = 0;       // 0: all cores
};

// Throws InputError for impossible options (before any work is done).
void validateBuildOptions(const BuildOptions& o);

// Builds the atlas; returns the statistics also written to output/stats.json.
// Throws InputError naming the file and the problem; output is untouched on failure.
nlohmann::json buildAtlas(const BuildOptions& o);

}  // namespace gimlod

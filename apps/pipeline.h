// The build pipeline behind `gimlod build`: DEM -> charts and pyramids (atlas/) -> hierarchy
// (hierarchy/) -> manifest; or mesh -> (gridify ->) charting -> quads, parameterization and
// resampling -> geometry chart pyramids -> geometry hierarchy -> manifest. Staged in a temporary
// directory and renamed into place, so an interrupted or failed build never leaves a half-valid
// atlas.
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
  // Meshes (PLY, OBJ, OFF, STL).
  uint32_t meshChartSize = 65;          // quad chart side in samples, 2^m + 1 (--chart-size for meshes)
  uint32_t charts = 128;                // target patches before quadrangulation; 0: maxChartError
  double maxChartError = 0.01;          // with charts = 0: RMS plane distance / bbox diagonal
  uint32_t straightenRounds = 2;        // rounds of straightening shared sides (atlas/layout_refine.h)
  uint32_t flipRepairRounds = 2;        // rounds of splitting patches whose charts have flipped
                                        // texels (atlas/layout_refine.h); 0 keeps the charting's
  double flipRepairBudget = 1.5;        // the flip repair's work cap: layout triangles parameterized
                                        // again, as a multiple of the layout's triangles
  uint64_t maxMemory = 4ull << 30;      // bytes; above a quarter of it the cells (out-of-core) path runs
  bool measureFidelity = true;          // two-sided Hausdorff distance input <-> atlas (out of core on that path)
};

// Throws InputError for impossible options (before any work is done).
void validateBuildOptions(const BuildOptions& o);

// Builds the atlas; returns the statistics also written to output/stats.json.
// Throws InputError naming the file and the problem; output is untouched on failure.
nlohmann::json buildAtlas(const BuildOptions& o);

}  // namespace gimlod

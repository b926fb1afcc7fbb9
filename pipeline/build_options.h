// Options of `gimlod build`: one struct per input kind, over the fields they share.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>

namespace gimlod {

// The smallest l with 2^l >= v (log2 of a power of two; 0 for v <= 1).
inline uint32_t log2u(uint32_t v) {
  uint32_t l = 0;
  while ((1u << l) < v) ++l;
  return l;
}

// What every build takes.
struct CommonBuildOptions {
  std::filesystem::path input;   // the DEM or mesh to read
  std::filesystem::path output;  // the atlas directory; an earlier atlas there is replaced
  uint32_t depth = 5;            // quadtree levels per chart
  uint32_t nodeRes = 64;         // maximum node resolution R (intervals, power of two)
  uint32_t minNodeRes = 4;       // minimum node resolution (intervals, power of two)
  uint32_t threads = 0;          // worker threads; 0: all cores
  // Spells an option's parameter name ("maxMemory") in logged warnings, e.g. as the front end's
  // flag; empty: the parameter name itself.
  std::function<std::string(std::string_view)> spellOption;
};

// A terrain atlas from a DEM (any single-band raster GDAL reads).
struct TerrainBuildOptions : CommonBuildOptions {
  std::string subdataset;    // netCDF variable; empty: the first 2D one
  uint32_t chartSize = 513;  // samples per chart side, 2^m + 1 in [9, 8193]
  double zScale = 1.0;       // height multiplier; finite and non-zero
};

// A geometry atlas from a mesh (PLY, OBJ, OFF, STL).
struct MeshBuildOptions : CommonBuildOptions {
  uint32_t chartSize = 65;          // quad chart side in samples, 2^m + 1 in [9, 8193]
  uint32_t charts = 128;            // target patches before quadrangulation; 0: maxChartError
  double maxChartError = 0.01;      // with charts = 0: RMS plane distance / bbox diagonal
  uint32_t straightenRounds = 2;    // rounds of straightening shared sides (atlas/layout_refine.h)
  uint32_t flipRepairRounds = 2;    // rounds of splitting patches whose charts have flipped texels
                                    // (atlas/layout_refine.h), in [0, 16]; 0 keeps the charting's
  double flipRepairBudget = 1.5;    // the flip repair's work cap: layout triangles parameterized
                                    // again, as a multiple of the layout's triangles, in [0, 100]
  uint64_t maxMemory = 4ull << 30;  // bytes, at least 64 MiB; above a quarter of it the cells
                                    // (out-of-core) path runs
  bool measureFidelity = true;      // two-sided Hausdorff distance input <-> atlas (out of core on
                                    // that path)
};

// The option's name as opts spell it in messages (CommonBuildOptions::spellOption).
inline std::string spelledOption(const CommonBuildOptions& opts, std::string_view name) {
  return opts.spellOption ? opts.spellOption(name) : std::string(name);
}

}  // namespace gimlod

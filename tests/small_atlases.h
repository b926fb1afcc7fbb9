// Small atlases of the shipped scan and DEM, quick to build, for the tests of what reads atlases
// (seam validation, the inspection report).
#pragma once

#include <cstdint>
#include <filesystem>

#include "pipeline/build.h"
#include "tests/test_util.h"

namespace gimlod::test {

// The shipped bunny in 24 target patches of 17^2-sample charts, 3 levels of 2..8 intervals.
inline void buildSmallScanAtlas(const std::filesystem::path& output, bool fidelity = true) {
  MeshBuildOptions o;
  o.input = repoData() / "meshes/bun_zipper.ply";
  o.output = output;
  o.patches = 24;
  o.chartSize = 17;
  o.depth = 3;
  o.nodeRes = 8;
  o.minNodeRes = 2;
  o.measureFidelity = fidelity;
  buildAtlas(o);
}

// The shipped Rainier tile (1201^2 samples) in chartSize^2-sample charts, `depth` levels of
// minNodeRes..nodeRes intervals.
inline void buildRainierAtlas(const std::filesystem::path& output, uint32_t chartSize, uint32_t depth, uint32_t nodeRes,
                              uint32_t minNodeRes) {
  TerrainBuildOptions o;
  o.input = repoData() / "terrain/mt_rainier_90m.tif";
  o.output = output;
  o.chartSize = chartSize;
  o.depth = depth;
  o.nodeRes = nodeRes;
  o.minNodeRes = minNodeRes;
  buildAtlas(o);
}

// The shipped Rainier tile in 129^2-sample charts, 3 levels of 4..32 intervals.
inline void buildSmallDemAtlas(const std::filesystem::path& output) { buildRainierAtlas(output, 129, 3, 32, 4); }

}  // namespace gimlod::test

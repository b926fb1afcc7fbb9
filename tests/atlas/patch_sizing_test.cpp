// Per-patch chart sizes (atlas/mesh/quad_charts.h MeshSizing::kPatch): a spill of images of every
// size, charts of different sizes written at their own levels, and the shipped bunny's atlas with
// its patches at different sizes, seamless at every level.
#include <gtest/gtest.h>

#include <bit>
#include <fstream>
#include <set>

#include <nlohmann/json.hpp>

#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/quad_charts.h"
#include "atlas/mesh/resample.h"
#include "core/atlas_format.h"
#include "inspect/seams.h"
#include "pipeline/build.h"
#include "tests/atlas_invariants.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

GeometryImage rampImage(uint32_t side, float offset, bool colours) {
  GeometryImage g;
  for (uint32_t v = 0; v < side; ++v)
    for (uint32_t u = 0; u < side; ++u) {
      g.positions.push_back({float(u) + offset, float(v), offset});
      g.normals.push_back(packNormal(0.f, 0.f, 1.f));
      if (colours) g.colours.push_back({uint8_t(u), uint8_t(v), 7, 255});
    }
  return g;
}

// Images of 33^2, 65^2 and 9^2 samples share one spill, each read back whole; an image that is not
// (2^k + 1)^2 is refused.
TEST(PatchSizing, OneSpillHoldsImagesOfEverySize) {
  test::TempDir dir("gimlod-spill-sizes");
  for (const bool colours : {false, true}) {
    ChartSpill spill(dir.path() / "samples.tmp", colours);
    std::vector<GeometryImage> images, originals;
    for (const uint32_t side : {33u, 65u, 9u}) {
      originals.push_back(rampImage(side, float(side), colours));
      images.push_back(originals.back());
    }
    for (GeometryImage& g : images) {
      spill.put(g);
      EXPECT_GE(g.spilled, 0);
      EXPECT_TRUE(g.positions.empty());
    }
    for (size_t i = images.size(); i-- > 0;) {
      spill.get(images[i]);
      EXPECT_EQ(images[i].spilled, -1);
      EXPECT_EQ(images[i].positions, originals[i].positions);
      EXPECT_EQ(images[i].colours, originals[i].colours);
      ASSERT_EQ(images[i].normals.size(), originals[i].normals.size());
    }
    GeometryImage odd = rampImage(33, 0.f, colours);
    odd.positions.pop_back();
    EXPECT_THROW(spill.put(odd), std::invalid_argument);
  }
}

// A set of 65^2 charts where one holds its samples at level 1 (33^2): the writer keeps it at its own
// size and level, never finer, and the coarsening goes on from there.
TEST(PatchSizing, ACoarserImageIsWrittenAtItsOwnLevel) {
  test::TempDir dir("gimlod-image-levels");
  GeometryImageSet set;
  set.chartSize = 65;
  set.charts.push_back(rampImage(65, 0.f, false));
  set.charts.push_back(rampImage(33, 100.f, false));
  set.charts.back().level = 1;
  EXPECT_EQ(set.charts[1].side(set.chartSize), 33u);
  EXPECT_TRUE(set.charts[1].hasSamples(set.chartSize));
  // A flat ramp is within any bound at every level: each chart coarsens as far as allowed, the
  // coarser image no less far than its own level.
  ChartCoarsening c;
  c.bound = 1.0;
  c.maxFinestLevel = 3;
  const std::vector<uint32_t> finest = chartFinestLevels(set, nullptr, c);
  EXPECT_EQ(finest, (std::vector<uint32_t>{3, 3}));
  c.maxFinestLevel = 0;
  EXPECT_EQ(chartFinestLevels(set, nullptr, c), (std::vector<uint32_t>{0, 1}));
  AtlasManifest m;
  m.depth = 2;
  m.maxNodeResLog2 = 5;
  m.minNodeResLog2 = 2;
  writeGeometryCharts(set, dir.path(), 32, m);
  ASSERT_EQ(m.charts.size(), 2u);
  EXPECT_EQ(m.charts[0].finestLevel, 0u);
  EXPECT_EQ(m.charts[1].finestLevel, 1u);
  EXPECT_EQ(m.chartFileSize(1), 33u);
  EXPECT_THROW(writeGeometryCharts(set, dir.path(), 32, m, nullptr, {}, {0, 0}), std::invalid_argument);
}

// A chart is not coarsened past a level that folds more than its own samples do: the flipped
// texels a build reports are those of the levels it keeps.
TEST(PatchSizing, AChartKeepsNoLevelThatFoldsMoreThanItsSamples) {
  GeometryImageSet set;
  set.chartSize = 65;
  set.charts.push_back(rampImage(65, 0.f, false));
  set.charts.push_back(rampImage(33, 100.f, false));
  set.charts.back().level = 1;
  ChartCoarsening c;
  c.bound = 1.0;
  c.maxFinestLevel = 3;
  // Without flipped texels anywhere the flat ramps coarsen as far as allowed.
  set.charts[0].flippedAtLevel = {0, 0, 0, 0, 0};
  set.charts[1].flippedAtLevel = {0, 0, 0, 0};
  EXPECT_EQ(chartFinestLevels(set, nullptr, c), (std::vector<uint32_t>{3, 3}));
  // Level 2 of the first folds (level 1 of the second, its level 2 of the set): each stops above.
  set.charts[0].flippedAtLevel = {0, 2, 0, 0, 0};
  set.charts[1].flippedAtLevel = {1, 0, 0, 0};
  EXPECT_EQ(chartFinestLevels(set, nullptr, c), (std::vector<uint32_t>{1, 1}));
  // No more than the samples themselves fold: allowed.
  set.charts[0].quality.flippedTexels = 2;
  set.charts[1].quality.flippedTexels = 1;
  EXPECT_EQ(chartFinestLevels(set, nullptr, c), (std::vector<uint32_t>{3, 3}));
}

// The shipped bunny at the defaults: one quad layout (sides), its patches at more than one size,
// each chart's file at its own size or coarser; seamless (bit-identical shared edges and corners)
// at every level, charts of different sizes included; every chart within the sampling bound; the
// stats' patch sizes add up.
TEST(PatchSizing, TheShippedBunnysPatchesTakeTheirOwnSizesAndStaySeamless) {
  test::TempDir dir("gimlod-patch-sizing");
  MeshBuildOptions o;
  o.input = test::repoData() / "meshes/bun_zipper.ply";
  o.output = dir.path() / "bunny.atlas";
  o.measureFidelity = false;
  buildAtlas(o);
  const nlohmann::json stats = nlohmann::json::parse(std::ifstream(o.output / "stats.json"));
  const nlohmann::json& r = stats.at("resample");
  EXPECT_EQ(r.at("sizing").get<std::string>(), "patch");
  EXPECT_EQ(r.at("quads").get<std::string>(), "sides");
  EXPECT_EQ(r.at("repair_stopped_for_work").get<bool>(), false);
  std::set<uint32_t> sides;
  for (const nlohmann::json& c : r.at("per_chart")) {
    sides.insert(c.at("side").get<uint32_t>());
    EXPECT_LE(c.at("sample_error").get<double>(), r.at("max_sample_error").get<double>());
  }
  EXPECT_GE(sides.size(), 2u) << "every patch took one size";
  uint32_t patches = r.at("patches_below_density_size").get<uint32_t>();
  for (const uint32_t n : r.at("patches_by_size").get<std::vector<uint32_t>>()) patches += n;
  EXPECT_EQ(patches, r.at("patches").get<uint32_t>());
  const AtlasManifest m = readManifest(o.output);
  EXPECT_EQ(m.chartSize, *sides.rbegin());
  const nlohmann::json& perChart = r.at("per_chart");
  ASSERT_EQ(perChart.size(), m.charts.size());
  std::set<uint32_t> levels;
  for (size_t i = 0; i < m.charts.size(); ++i) {
    const uint32_t own =
        uint32_t(std::countr_zero(m.chartSize - 1) - std::countr_zero(perChart[i].at("side").get<uint32_t>() - 1));
    EXPECT_GE(m.charts[i].finestLevel, own) << "chart " << i << " is stored finer than it was sampled";
    levels.insert(m.charts[i].finestLevel);
  }
  EXPECT_GE(levels.size(), 2u);
  const SeamReport seams = validateSeams(o.output);
  EXPECT_TRUE(seams.seamless()) << seams.mismatches() << " seam mismatches";
  test::checkSeams(o.output);
}

// The repair's work cap follows the surface up to a million triangles and stays there: on the
// 18.7M-triangle sphere every cut parameterizes a patch of hundreds of thousands of triangles
// again, and eight times the surface would be about eight first resamplings.
TEST(PatchSizing, TheRepairsWorkStopsGrowingPastAMillionTriangles) {
  EXPECT_EQ(meshRepairWorkBudget(8.0, 40000), 320000u);
  EXPECT_EQ(meshRepairWorkBudget(8.0, kRepairTrianglesCounted), 8 * kRepairTrianglesCounted);
  EXPECT_EQ(meshRepairWorkBudget(8.0, 18690048), 8 * kRepairTrianglesCounted);
  EXPECT_EQ(meshRepairWorkBudget(0.5, 100017228), kRepairTrianglesCounted / 2);
  EXPECT_EQ(meshRepairWorkBudget(0.0, 18690048), 0u);
}

}  // namespace
}  // namespace gimlod

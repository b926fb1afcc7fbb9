// Seam validation (inspect/seams.h) on the shipped scan's and DEM's atlases: every shared edge and
// corner agrees at every level, and one altered shared sample in a copy is found and named.
#include <gtest/gtest.h>

#include <filesystem>

#include "core/atlas_format.h"
#include "inspect/seams.h"
#include "pipeline/build.h"
#include "tests/small_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

class SeamsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("gimlod-seams");
    test::buildSmallScanAtlas(dir_->path() / "bunny.atlas", false);
    test::buildSmallDemAtlas(dir_->path() / "rainier.atlas");
  }
  static void TearDownTestSuite() { delete dir_; }
  static fs::path atlas(const char* name) { return dir_->path() / name; }

  // A copy of atlas `name` in which sample k of edge `edge` of the first chart with a neighbour
  // there differs at level 0 (by +1 in z / height); returns the chart.
  static uint32_t alteredCopy(const char* name, const fs::path& to, uint32_t edge, uint32_t k) {
    fs::copy(atlas(name), to, fs::copy_options::recursive);
    const AtlasManifest m = readManifest(to);
    uint32_t c = 0;
    while (c < m.charts.size() && m.charts[c].neighbours[edge].chart < 0) ++c;
    EXPECT_LT(c, m.charts.size()) << "no chart with a neighbour across edge " << edge;
    const fs::path file = to / m.charts[c].file;
    ChartPyramid p;
    {
      const ChartFileReader r(file);
      for (uint32_t level = 0; level < r.levels(); ++level) {
        p.normals.push_back(r.readLevelNormals(level));
        if (m.kind == AtlasKind::Geometry) {
          p.positions.push_back(r.readLevelPositions(level));
          if (r.hasChannel(kChannelColours)) p.colours.push_back(r.readLevelColours(level));
        } else {
          p.heights.push_back(r.readLevelHeights(level));
        }
      }
    }
    const uint32_t at = edgeSampleIndex(m.chartSize, edge, k);
    if (m.kind == AtlasKind::Geometry)
      p.positions[0][at].z += 1.0f;
    else
      p.heights[0][at] += 1.0f;
    writeChartFile(file, p, m.chartSize, m.blockIntervals);
    return c;
  }
  static test::TempDir* dir_;
};
test::TempDir* SeamsTest::dir_ = nullptr;

TEST_F(SeamsTest, ShippedScanAndDemAreSeamlessAtEveryLevel) {
  for (const char* name : {"bunny.atlas", "rainier.atlas"}) {
    SCOPED_TRACE(name);
    const AtlasManifest m = readManifest(atlas(name));
    const SeamReport r = validateSeams(atlas(name));
    EXPECT_EQ(r.charts, m.charts.size());
    EXPECT_EQ(r.levels.size(), m.pyramidLevels());
    EXPECT_GT(r.sharedEdges, 0u);
    uint64_t compared = 0;
    for (const SeamLevel& l : r.levels) {
      EXPECT_EQ(l.edgeMismatches, 0u) << "level " << l.level;
      EXPECT_EQ(l.cornerMismatches, 0u) << "level " << l.level;
      compared += l.edgeSamples;
    }
    // Every shared edge pair is compared once per level, sample by sample.
    uint64_t expected = 0;
    for (uint32_t level = 0; level < m.pyramidLevels(); ++level)
      expected += r.sharedEdges * (((m.chartSize - 1) >> level) + 1);
    EXPECT_EQ(compared, expected);
    EXPECT_TRUE(r.seamless());
    EXPECT_TRUE(r.offenders.empty());
  }
  // The scan is closed but for its holes: open edges exist, and corners join 3 or more charts.
  const SeamReport b = validateSeams(atlas("bunny.atlas"));
  EXPECT_GT(b.openEdges, 0u);
  EXPECT_GT(b.cornerValence.rbegin()->first, 2u);
}

TEST_F(SeamsTest, OneAlteredSharedSampleIsFoundAndNamed) {
  for (const char* name : {"bunny.atlas", "rainier.atlas"}) {
    SCOPED_TRACE(name);
    const fs::path copy = dir_->path() / (std::string("altered_") + name);
    const AtlasManifest m = readManifest(atlas(name));
    const uint32_t k = (m.chartSize - 1) / 2;  // inside the edge: not a corner
    uint32_t edge = 0;
    while (edge < 4) {
      bool any = false;
      for (const ChartInfo& c : m.charts) any = any || c.neighbours[edge].chart >= 0;
      if (any) break;
      ++edge;
    }
    ASSERT_LT(edge, 4u);
    const uint32_t chart = alteredCopy(name, copy, edge, k);
    const SeamReport r = validateSeams(copy);
    EXPECT_FALSE(r.seamless());
    ASSERT_FALSE(r.levels.empty());
    EXPECT_EQ(r.levels[0].edgeMismatches, 1u);
    EXPECT_EQ(r.levels[0].cornerMismatches, 0u);
    for (size_t l = 1; l < r.levels.size(); ++l) EXPECT_EQ(r.levels[l].edgeMismatches, 0u) << "level " << l;
    EXPECT_NEAR(r.levels[0].maxEdgeDifference, 1.0, 1e-3);
    ASSERT_EQ(r.offenders.size(), 1u);
    const SeamOffender& o = r.offenders[0];
    const RootNeighbour& nb = m.charts[chart].neighbours[edge];
    // Named from either side of the edge.
    const bool fromChart = o.chart == chart && o.edge == edge && o.sample == k;
    const bool fromOther = o.chart == uint32_t(nb.chart) && o.edge == nb.edge && o.otherChart == chart &&
                           o.otherEdge == edge && o.otherSample == k;
    EXPECT_TRUE(fromChart || fromOther) << "offender chart " << o.chart << " edge " << o.edge << " sample " << o.sample;
    EXPECT_EQ(o.level, 0u);
    EXPECT_FALSE(o.corner);
  }
}

TEST_F(SeamsTest, AnAlteredCornerIsFound) {
  const fs::path copy = dir_->path() / "corner_bunny.atlas";
  const AtlasManifest m = readManifest(atlas("bunny.atlas"));
  alteredCopy("bunny.atlas", copy, kEdgeBottom, 0);  // corner 0 of the chart: its edge 0, sample 0
  const SeamReport r = validateSeams(copy);
  EXPECT_GE(r.levels[0].cornerMismatches, 1u);
  EXPECT_GE(r.levels[0].edgeMismatches, 1u);  // the corner ends edges too
  EXPECT_EQ(r.mismatches(), r.levels[0].edgeMismatches + r.levels[0].cornerMismatches);
}

TEST_F(SeamsTest, NotAnAtlasOrATruncatedChartIsAnErrorNamingTheFile) {
  const fs::path empty = dir_->path() / "empty";
  fs::create_directories(empty);
  EXPECT_THROW(validateSeams(empty), InputError);
  const fs::path copy = dir_->path() / "truncated.atlas";
  fs::copy(atlas("bunny.atlas"), copy, fs::copy_options::recursive);
  const fs::path chart = copy / readManifest(copy).charts[3].file;
  fs::resize_file(chart, fs::file_size(chart) / 2);
  try {
    validateSeams(copy);
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(chart.filename().string()), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace gimlod

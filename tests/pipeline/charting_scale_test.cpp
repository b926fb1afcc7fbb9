// Tests for the large-mesh paths of charting and the build's stage report: a UV sphere big
// enough for the clusterer's heap purge, the cells path's weld counts through gridify, and the
// per-stage time and peak-memory figures of `gimlod build MESH`.
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <string>

#include "pipeline/build.h"
#include "atlas/mesh/charting.h"
#include "atlas/mesh/gridify.h"
#include "atlas/mesh/mesh_atlas.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// Closed UV sphere: `rings` rings of `columns` vertices plus one vertex per pole, counter-
// clockwise seen from outside; 2 * columns * rings triangles, 2 + columns * rings vertices.
IndexedMesh uvSphere(uint32_t columns, uint32_t rings) {
  IndexedMesh m;
  const double pi = 3.14159265358979323846;
  m.positions.push_back({0.f, 0.f, -1.f});
  for (uint32_t k = 0; k < rings; ++k) {
    const double lat = -pi / 2 + pi * (k + 1) / (rings + 1);
    for (uint32_t c = 0; c < columns; ++c) {
      const double lon = 2 * pi * c / columns;
      const double r = 1.0 + 0.05 * std::sin(5 * lon) * std::cos(3 * lat);  // not a perfect sphere
      m.positions.push_back({float(r * std::cos(lat) * std::cos(lon)), float(r * std::cos(lat) * std::sin(lon)),
                             float(r * std::sin(lat))});
    }
  }
  m.positions.push_back({0.f, 0.f, 1.f});
  const uint32_t south = 0, north = uint32_t(m.positions.size() - 1);
  auto id = [&](uint32_t k, uint32_t c) { return 1 + k * columns + c % columns; };
  for (uint32_t c = 0; c < columns; ++c) m.triangles.push_back({south, id(0, c + 1), id(0, c)});
  for (uint32_t k = 0; k + 1 < rings; ++k)
    for (uint32_t c = 0; c < columns; ++c) {
      m.triangles.push_back({id(k, c), id(k, c + 1), id(k + 1, c + 1)});
      m.triangles.push_back({id(k, c), id(k + 1, c + 1), id(k + 1, c)});
    }
  for (uint32_t c = 0; c < columns; ++c) m.triangles.push_back({id(rings - 1, c), id(rings - 1, c + 1), north});
  return m;
}

// Below the blocked-clustering threshold (32768 triangles), so one clusterer merges every
// triangle: its heap passes the purge threshold (65536 candidates) many times over.
TEST(ChartingScale, OneLargeHeapGivesAValidClosedLayout) {
  const IndexedMesh m = uvSphere(128, 126);
  ASSERT_LE(m.triangles.size(), 32768u);
  ChartingOptions o;
  o.targetPatches = 12;
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(m, o, &st);
  EXPECT_TRUE(validatePatchLayout(l).empty());
  EXPECT_EQ(st.cells, 0u);  // not blocked
  EXPECT_EQ(l.triangles.size(), m.triangles.size());
  EXPECT_EQ(st.boundaryEdges, 0u);
  EXPECT_GE(st.charts, 12u);
  EXPECT_LE(st.charts, 24u);
  std::set<uint32_t> seen;
  for (const Patch& p : l.patches) seen.insert(p.triangles.begin(), p.triangles.end());
  EXPECT_EQ(seen.size(), m.triangles.size());
}

// The cells path welds twice (in each cell, then across cells); the counts still describe the
// whole: every corner of the cell files in, the sphere's distinct vertices out.
TEST(ChartingScale, CellsPathCountsEveryWeld) {
  test::TempDir dir("charting_scale");
  const IndexedMesh m = uvSphere(96, 60);
  writePly(dir.path() / "sphere.ply", m.positions, m.triangles);
  GridifyOptions g;
  g.targetTrianglesPerCell = 1500;
  const GridifyResult gr = gridify(dir.path() / "sphere.ply", dir.path() / "grid", g);
  ASSERT_GT(gr.cells, 4u);
  ChartingOptions o;
  o.targetPatches = 20;
  ChartingStats st;
  const PatchLayout l = buildPatchLayoutFromCells(dir.path() / "grid", o, &st);
  EXPECT_TRUE(validatePatchLayout(l).empty());
  EXPECT_EQ(l.triangles.size(), m.triangles.size());
  EXPECT_EQ(l.positions.size(), m.positions.size());
  EXPECT_EQ(st.inputVertices, 3 * m.triangles.size());
  EXPECT_EQ(st.verticesWelded, 3 * m.triangles.size() - m.positions.size());
  EXPECT_EQ(st.boundaryEdges, 0u);
  EXPECT_EQ(st.nonManifoldEdges, 0u);
  EXPECT_GT(st.cellClusters, st.charts / 2);
}

// Every stage of a mesh build reports its time and peak memory in stats.json.
TEST(ChartingScale, MeshBuildReportsEveryStage) {
  test::TempDir dir("charting_scale");
  const IndexedMesh m = uvSphere(48, 30);
  writePly(dir.path() / "sphere.ply", m.positions, m.triangles);
  MeshBuildOptions b;
  b.input = dir.path() / "sphere.ply";
  b.output = dir.path() / "sphere.atlas";
  b.patches = 12;
  b.chartSize = 17;
  b.measureFidelity = false;
  const nlohmann::json stats = buildAtlas(b);
  ASSERT_TRUE(stats.contains("stages"));
  std::set<std::string> names;
  uint64_t largest = 0;
  double stageSeconds = 0.0;
  for (const auto& s : stats["stages"]) {
    names.insert(s.at("stage").get<std::string>());
    // Every stage does work (so its clocks moved), and the stages run one after another within
    // the build's own wall time.
    EXPECT_GT(s.at("seconds").get<double>(), 0.0) << s.at("stage");
    EXPECT_GT(s.at("cpu_seconds").get<double>(), 0.0) << s.at("stage");
    stageSeconds += s.at("seconds").get<double>();
    EXPECT_GT(s.at("peak_rss_bytes").get<uint64_t>(), 0u);
    largest = std::max(largest, s.at("peak_rss_bytes").get<uint64_t>());
  }
  EXPECT_LE(stageSeconds, stats.at("total_seconds").get<double>());
  for (const char* want : {"read", "charting", "validate", "resample", "write"}) EXPECT_TRUE(names.count(want)) << want;
  EXPECT_GE(stats.at("peak_rss_bytes").get<uint64_t>(), largest);  // VmHWM: the process peak
}

}  // namespace
}  // namespace gimlod

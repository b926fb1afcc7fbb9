// The mesh atlas on disk: geometry chart files with their pyramids, the manifest, the geometry
// hierarchy over them, and the exported surface, which is watertight at every level for a closed
// input (the seams are bit-identical) and is a valid PLY.
#include <gtest/gtest.h>

#include <map>

#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/mesh_io.h"
#include "hierarchy/hierarchy.h"
#include "tests/chart_layout_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

TEST(MeshAtlas, ClosedSurfaceStaysWatertightAtEveryLevel) {
  test::TempDir tmp("gimlod-mesh-atlas");
  const ChartLayout layout = test::cubeLayout(6, true);  // a sphere from six curved patches
  ResampleOptions ro;
  ro.chartSize = 33;
  const GeometryImageSet set = resampleLayout(layout, ro);
  ASSERT_EQ(set.charts.size(), 24u);  // 6 four-sided patches, 4 quads each
  AtlasManifest m;
  m.depth = 3;
  m.maxNodeResLog2 = 3;
  m.minNodeResLog2 = 1;
  const fs::path dir = tmp.path() / "sphere.atlas";
  const GeometryChartsWritten w = writeGeometryCharts(set, dir, 8, m);
  EXPECT_GT(w.bytes, 0u);
  EXPECT_NEAR(w.bounds[5], 1.f, 2e-3f);  // the triangulated sphere lies just inside radius 1
  writeManifest(dir, m);
  const AtlasManifest back = readManifest(dir);  // checks that the neighbours are symmetric
  EXPECT_EQ(back.kind, AtlasKind::Geometry);
  ASSERT_EQ(back.charts.size(), 24u);
  for (uint32_t level = 0; level < back.pyramidLevels(); ++level) {
    const AtlasSurface s = readAtlasSurface(dir, level);
    const uint32_t side = (32u >> level) + 1;
    EXPECT_EQ(s.samples, 24ull * side * side);
    EXPECT_EQ(s.boundaryEdges, 0u) << "level " << level << ": seams are not bit-identical";
    // Closed genus-0 surface: V - E + F = 2, E = 3F/2.
    EXPECT_EQ(int64_t(s.positions.size()) - int64_t(s.triangles.size()) * 3 / 2 + int64_t(s.triangles.size()), 2)
        << "level " << level;
  }
  // The hierarchy over the written charts: bounds hold every sample, finest errors are 0.
  std::vector<std::array<RootNeighbour, 4>> roots;
  for (const ChartInfo& c : back.charts) roots.push_back(c.neighbours);
  const Hierarchy h = buildGeometryHierarchy(hierarchyParams(back), roots, [&](uint32_t c) {
    return ChartFileReader(dir / back.charts[c].file).readLevelPositions(0);
  });
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const auto& b = h.bounds({c, 0, 0, 0});
    for (const glm::vec3& q : set.charts[c].positions) {
      ASSERT_GE(q.x, b[0]);
      ASSERT_LE(q.z, b[5]);
    }
    EXPECT_EQ(h.error({c, 2, 3, 1}, 3), 0.f);  // a leaf at full resolution
    EXPECT_GT(h.error({c, 0, 0, 0}, 1), 0.f);  // a curved root drawn coarsely
  }
  // Export: a PLY that the mesh reader reads back unchanged.
  const AtlasSurface s = readAtlasSurface(dir, 1);
  const fs::path ply = tmp.path() / "surface.ply";
  writePly(ply, s.positions, s.triangles);
  const IndexedMesh mesh = readMesh(ply);
  EXPECT_EQ(mesh.positions.size(), s.positions.size());
  EXPECT_EQ(mesh.triangles.size(), s.triangles.size());
  EXPECT_EQ(mesh.stats.droppedDegenerate + mesh.stats.droppedDuplicate, 0u);
}

TEST(MeshAtlas, BadInputsAreReported) {
  test::TempDir tmp("gimlod-mesh-atlas");
  const GeometryImageSet set = resampleLayout(test::cubeLayout(2), ResampleOptions{9, 0, {}});
  AtlasManifest m;
  m.depth = 2;
  m.maxNodeResLog2 = 2;
  m.minNodeResLog2 = 1;
  EXPECT_THROW(writeGeometryCharts(set, tmp.path() / "a", 16, m), std::invalid_argument);  // block > chart
  EXPECT_THROW(writeGeometryCharts(GeometryImageSet{}, tmp.path() / "b", 4, m), std::invalid_argument);
  const fs::path dir = tmp.path() / "cube.atlas";
  writeGeometryCharts(set, dir, 4, m);
  writeManifest(dir, m);
  EXPECT_THROW(readAtlasSurface(dir, 9), InputError);  // no such level
  EXPECT_THROW(readAtlasSurface(tmp.path() / "missing", 0), InputError);
  fs::remove(dir / m.charts[3].file);
  EXPECT_THROW(readAtlasSurface(dir, 0), InputError);  // a chart file is missing
}

}  // namespace
}  // namespace gimlod

// The mesh atlas on disk: geometry chart files with their pyramids, the manifest, the geometry
// hierarchy over them, and the exported surface, which is watertight at every level for a closed
// input (the seams are bit-identical) and is a valid PLY.
#include <gtest/gtest.h>

#include <functional>
#include <map>

#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/mesh_io.h"
#include "hierarchy/hierarchy.h"
#include "inspect/seams.h"
#include "runtime/atlas_view.h"
#include "runtime/page_reader.h"
#include "tests/chart_layout_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// The atlas's export at every level is one closed genus-0 surface (a sphere's atlas): no edge is
// open, so every seam is bit-identical or stitched.
void expectClosedSphereAtEveryLevel(const fs::path& dir, uint32_t levels) {
  for (uint32_t level = 0; level < levels; ++level) {
    const AtlasSurface s = readAtlasSurface(dir, level);
    EXPECT_EQ(s.boundaryEdges, 0u) << "level " << level << ": a seam is neither bit-identical nor stitched";
    // V - E + F = 2, E = 3F/2.
    EXPECT_EQ(int64_t(s.positions.size()) - int64_t(s.triangles.size()) * 3 / 2 + int64_t(s.triangles.size()), 2)
        << "level " << level;
  }
}

// The hierarchy over an atlas's written charts, each from its finest level.
Hierarchy hierarchyOfCharts(const fs::path& dir, const AtlasManifest& m) {
  std::vector<std::array<RootNeighbour, 4>> roots;
  for (const ChartInfo& c : m.charts) roots.push_back(c.neighbours);
  return buildGeometryHierarchy(
      hierarchyParams(m), roots,
      [&](uint32_t c) { return ChartFileReader(dir / m.charts[c].file).readLevelPositions(0); }, nullptr,
      finestLevels(m, hierarchyParams(m)));
}

TEST(MeshAtlas, ClosedSurfaceStaysWatertightAtEveryLevel) {
  test::TempDir tmp("gimlod-mesh-atlas");
  const PatchLayout layout = test::cubeLayout(6, true);  // a sphere from six curved patches
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
  expectClosedSphereAtEveryLevel(dir, back.pyramidLevels());
  for (uint32_t level = 0; level < back.pyramidLevels(); ++level) {
    const uint32_t side = (32u >> level) + 1;
    EXPECT_EQ(readAtlasSurface(dir, level).samples, 24ull * side * side) << "level " << level;
  }
  // The hierarchy over the written charts: bounds hold every sample, finest errors are 0.
  const Hierarchy h = hierarchyOfCharts(dir, back);
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

// The farthest a level-0 sample lies from the surface of level k at its (u, v), over k' <= k,
// found the plain way: every sample against the two triangles of its level-k' cell.
double levelErrorUpTo(const std::vector<glm::vec3>& P, uint32_t n, uint32_t k) {
  double e = 0.0;
  for (uint32_t j = 1; j <= k; ++j) {
    const uint32_t s = 1u << j;
    for (uint32_t v = 0; v < n; ++v)
      for (uint32_t u = 0; u < n; ++u) {
        const uint32_t cu = std::min(u / s, (n - 1) / s - 1), cv = std::min(v / s, (n - 1) / s - 1);
        const double a = double(u - cu * s) / s, b = double(v - cv * s) / s;
        const glm::dvec3 p00 = P[size_t(cv * s) * n + cu * s], p10 = P[size_t(cv * s) * n + cu * s + s];
        const glm::dvec3 p01 = P[size_t(cv * s + s) * n + cu * s], p11 = P[size_t(cv * s + s) * n + cu * s + s];
        const glm::dvec3 q = a >= b ? p00 + a * (p10 - p00) + b * (p11 - p10) : p00 + b * (p01 - p00) + a * (p11 - p01);
        e = std::max(e, glm::length(q - glm::dvec3(P[size_t(v) * n + u])));
      }
  }
  return e;
}

TEST(ChartCoarsening, KeepsTheCoarsestLevelWithinTheBound) {
  const uint32_t n = 33;
  // A plane keeps its coarsest allowed level; a paraboloid the coarsest within the bound.
  std::vector<glm::vec3> plane(size_t(n) * n), bowl(plane.size());
  for (uint32_t v = 0; v < n; ++v)
    for (uint32_t u = 0; u < n; ++u) {
      const float x = float(u) / (n - 1), y = float(v) / (n - 1);
      plane[size_t(v) * n + u] = {x, y, 0.5f * x - 0.25f * y};
      bowl[size_t(v) * n + u] = {x, y, 2.0f * (x * x + y * y)};
    }
  EXPECT_EQ(chartFinestLevel(plane, n, 0.0, {1e-6, 3}), 3u);
  EXPECT_EQ(chartFinestLevel(plane, n, 0.0, {0.0, 3}), 0u);    // no bound: nothing dropped
  EXPECT_EQ(chartFinestLevel(plane, n, 2e-6, {1e-6, 3}), 0u);  // the sampling alone is over it
  for (const double sampleError : {0.0, 1e-3}) {
    for (const double bound : {2e-3, 5e-3, 1e-2, 3e-2, 1e-1}) {
      const uint32_t k = chartFinestLevel(bowl, n, sampleError, {bound, 4});
      SCOPED_TRACE(::testing::Message() << "bound " << bound << ", sampling error " << sampleError << ", level " << k);
      EXPECT_LE(sampleError + levelErrorUpTo(bowl, n, k), bound * (1 + 1e-5));
      if (k < 4) {
        EXPECT_GT(sampleError + levelErrorUpTo(bowl, n, k + 1), bound * (1 - 1e-5));
      }
    }
  }
  EXPECT_GT(chartFinestLevel(bowl, n, 0.0, {3e-2, 4}), chartFinestLevel(bowl, n, 0.0, {2e-3, 4}));
}

// Planar squares (geometryPyramid's PlanarPlacement) on a wavy chart: the surface drawn from the
// stored finest level stays within the budget of every level-0 sample (or no farther than without
// them), the chart's border never moves, the moved samples are counted, and the chart file is
// smaller; no budget moves nothing.
TEST(PlanarSquares, MoveWithinTheBudgetNeverTheBorderAndStoreFewerBytes) {
  test::TempDir tmp("gimlod-planar");
  const uint32_t n = 65;
  GeometryImage img;
  for (uint32_t v = 0; v < n; ++v)
    for (uint32_t u = 0; u < n; ++u) {
      const float x = float(u) / (n - 1), y = float(v) / (n - 1);
      const float bump = std::exp(-60.0f * ((x - 0.7f) * (x - 0.7f) + (y - 0.3f) * (y - 0.3f)));
      img.positions.push_back({x, y, 0.05f * std::sin(3.0f * x) * std::cos(2.0f * y) + 0.08f * bump});
      img.normals.push_back(packNormal(0.0f, 0.0f, 1.0f));
    }
  ChartCoding coding;
  coding.compressed = true;
  coding.positionStep = std::exp2(-18.0);
  coding.deriveGeometryNormals = true;
  for (const uint32_t finest : {0u, 1u})
    for (const double budget : {0.0, 2e-4, 2e-3}) {
      SCOPED_TRACE(::testing::Message() << "finest level " << finest << ", budget " << budget);
      const ChartPyramid base = geometryPyramid(img, n, coding, finest);
      uint64_t moved = 1;
      const ChartPyramid planar = geometryPyramid(img, n, coding, finest, {budget, 16}, &moved);
      const uint32_t side = ((n - 1) >> finest) + 1, M = side - 1;
      uint64_t differ = 0;
      for (uint32_t y = 0; y <= M; ++y)
        for (uint32_t x = 0; x <= M; ++x) {
          const size_t i = size_t(y) * side + x;
          differ += planar.positions[0][i] != base.positions[0][i];
          if (x == 0 || y == 0 || x == M || y == M) {
            EXPECT_EQ(planar.positions[0][i], base.positions[0][i]) << x << ", " << y;
          }
        }
      EXPECT_EQ(moved, differ);
      // The drawn surfaces at every level-0 sample, each level subsampling the stored finest one.
      auto drawn = [&](const std::vector<glm::vec3>& stored) {
        std::vector<glm::vec3> h(img.positions.size());
        for (uint32_t v = 0; v < side; ++v)
          for (uint32_t u = 0; u < side; ++u) h[size_t(v << finest) * n + (u << finest)] = stored[size_t(v) * side + u];
        return finest == 0 ? h : geometryLevelSurface(h, n, finest);
      };
      const std::vector<glm::vec3> before = drawn(base.positions[0]), after = drawn(planar.positions[0]);
      for (size_t i = 0; i < img.positions.size(); ++i)
        EXPECT_LE(glm::length(after[i] - img.positions[i]),
                  std::max(budget, double(glm::length(before[i] - img.positions[i]))) + 1e-6)
            << i;
      for (size_t k = 1; k < planar.positions.size(); ++k)
        for (uint32_t y = 0; y < (M >> k) + 1; ++y)
          for (uint32_t x = 0; x < (M >> k) + 1; ++x)
            EXPECT_EQ(planar.positions[k][size_t(y) * ((M >> k) + 1) + x],
                      planar.positions[0][size_t(y << k) * side + (x << k)]);
      if (budget == 0.0) {
        EXPECT_EQ(moved, 0u);
        continue;
      }
      EXPECT_GT(moved, uint64_t(side) * side / (budget > 1e-3 ? 2 : 8));
      const uint64_t baseBytes = writeChartFile(tmp.path() / "base.bin", base, side, std::min(16u, M), coding);
      const uint64_t planarBytes = writeChartFile(tmp.path() / "planar.bin", planar, side, std::min(16u, M), coding);
      EXPECT_LE(planarBytes, budget > 1e-3 ? baseBytes * 3 / 4 : baseBytes) << "moved " << moved;
      // The file decodes to the samples placed.
      EXPECT_EQ(ChartFileReader(tmp.path() / "planar.bin").readLevelPositions(0), planar.positions[0]);
    }
}

// Charts of different finest levels side by side: the files hold their own sizes, the seams stay
// bit-identical where both charts hold a level, the export is stitched watertight at every level
// as the renderer stitches, the hierarchy gives no coarse chart a resolution it does not hold, and
// a coarse chart's pages are its own samples.
TEST(MeshAtlas, ChartsOfDifferentFinestLevelsStayWatertight) {
  test::TempDir tmp("gimlod-mesh-atlas");
  GeometryImageSet set = resampleLayout(test::cubeLayout(6, true), ResampleOptions{33, 0, {}});
  ASSERT_EQ(set.charts.size(), 24u);
  // Every other chart is given a sampling error at the bound, so it keeps its finest samples.
  const double bound = 0.02;
  for (size_t i = 0; i < set.charts.size(); ++i) set.charts[i].quality.sampleError = i % 2 ? 0.0 : bound;
  AtlasManifest m;
  m.depth = 2;
  m.maxNodeResLog2 = 3;
  m.minNodeResLog2 = 1;
  const HierarchyParams p{5, 2, 3, 1};
  const fs::path dir = tmp.path() / "sphere.atlas";
  const std::vector<uint32_t> levels = chartFinestLevels(set, nullptr, {bound, p.maxFinestLevel()});
  const GeometryChartsWritten w = writeGeometryCharts(set, dir, 8, m, nullptr, {}, levels);
  writeManifest(dir, m);
  const AtlasManifest back = readManifest(dir);
  uint64_t finest = 0;
  for (const ChartInfo& c : back.charts) {
    SCOPED_TRACE(c.file);
    if (c.id % 2 == 0) {
      EXPECT_EQ(c.finestLevel, 0u);
    } else {
      EXPECT_GT(c.finestLevel, 0u);
    }
    EXPECT_LE(c.finestLevel, p.maxFinestLevel());
    const ChartFileReader r(dir / c.file);
    EXPECT_EQ(r.chartSize(), (32u >> c.finestLevel) + 1);
    EXPECT_EQ(r.levels(), back.pyramidLevels() - c.finestLevel);
    finest += uint64_t(r.chartSize()) * r.chartSize();
  }
  EXPECT_EQ(w.finestSamples, finest);
  ASSERT_GE(w.chartsByFinestLevel.size(), 2u);
  EXPECT_EQ(w.chartsByFinestLevel[0], 12u);
  const SeamReport seams = validateSeams(dir);
  EXPECT_EQ(seams.mismatches(), 0u);
  expectClosedSphereAtEveryLevel(dir, back.pyramidLevels());
  // The hierarchy, as the runtime opens it.
  const Hierarchy h = hierarchyOfCharts(dir, back);
  writeHierarchy(dir / back.hierarchyFile, h);
  const AtlasView view = openAtlas(dir);
  const PageReader pages(dir, back, view.hierarchy.params);
  for (const ChartInfo& c : back.charts) {
    const NodeId leaf{c.id, 1, 1, 0};
    EXPECT_EQ(view.hierarchy.maxResLog2(leaf), std::min(4 - c.finestLevel, 3u));
    EXPECT_EQ(view.hierarchy.maxResLog2(leaf), h.maxResLog2(leaf));
    // Finer than the chart holds: no error; its own finest samples: error 0.
    const uint32_t r = h.maxResLog2(leaf);
    if (r < p.maxNodeResLog2) {
      EXPECT_TRUE(std::isnan(view.hierarchy.error(leaf, r + 1)));
    }
    if (c.finestLevel > 0) {
      EXPECT_EQ(view.hierarchy.error(leaf, r), 0.f);
    } else {
      EXPECT_GT(view.hierarchy.error(leaf, r), 0.f);  // the page's level 1 on a sphere
    }
    std::vector<float> samples;
    std::vector<PackedNormal> normals;
    pages.read(leaf, samples, normals);
    // The page: the leaf's window of the file's level intervals - level - res, in the file's units.
    const uint32_t side = pages.pageSamples(leaf), fileSide = (32u >> c.finestLevel) + 1;
    const uint32_t step = (fileSide - 1) / 2 / (side - 1);
    ASSERT_EQ(samples.size(), size_t(side) * side * 3);
    const std::vector<glm::vec3> level0 = ChartFileReader(dir / c.file).readLevelPositions(0);
    const uint32_t x0 = (fileSide - 1) / 2;  // the leaf (1, 0) starts halfway along u
    for (uint32_t j = 0; j < side; ++j)
      for (uint32_t i = 0; i < side; ++i) {
        const glm::vec3& q = level0[size_t(j * step) * fileSide + x0 + i * step];
        ASSERT_EQ(samples[(size_t(j) * side + i) * 3 + 0], q.x) << c.file << " (" << i << ", " << j << ")";
        ASSERT_EQ(samples[(size_t(j) * side + i) * 3 + 2], q.z) << c.file << " (" << i << ", " << j << ")";
      }
  }
  // A manifest that disagrees with the files: a finest level past what the hierarchy allows, and
  // one that is not the chart file's.
  const fs::path manifest = dir / kManifestName;
  auto expectError = [&](const std::function<void()>& open, const std::string& file, const std::string& what) {
    try {
      open();
      ADD_FAILURE() << "expected an InputError naming " << file;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  AtlasManifest bad = back;
  bad.charts[1].finestLevel = p.maxFinestLevel() + 1;
  writeManifest(dir, bad);
  expectError([&] { openAtlas(dir); }, manifest.string(), "finest level");
  bad.charts[1].finestLevel = back.charts[1].finestLevel == 1 ? 2 : 1;
  writeManifest(dir, bad);
  expectError([&] { PageReader(dir, bad, hierarchyParams(bad)); }, (dir / bad.charts[1].file).string(),
              "the manifest says");
  expectError([&] { readAtlasSurface(dir, 0); }, (dir / bad.charts[1].file).string(), "chart size differs");
  expectError([&] { validateSeams(dir); }, (dir / bad.charts[1].file).string(), "chart size or levels differ");
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

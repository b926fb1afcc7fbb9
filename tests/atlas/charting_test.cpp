// Tests for charting: hand-made meshes for the exact logic (cube faces, corner insertion, holes,
// non-manifold repair) and the shared scanned meshes for the layout invariants (validatePatchLayout
// empty, triangles preserved, chart count near the target).
#include <gtest/gtest.h>

#include <glm/glm.hpp>

#include <chrono>
#include <cmath>
#include <utility>
#include <cstdio>
#include <set>

#include "atlas/mesh/charting.h"
#include "atlas/mesh/charting_internal.h"
#include "atlas/mesh/gridify.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

// Cube [0,1]^3 with n x n quads per face; each face has its own vertices (welding joins them).
IndexedMesh gridCube(int n) {
  IndexedMesh m;
  // Face frames: origin, u, v with u x v = outward normal.
  const glm::vec3 frames[6][3] = {
      {{0, 0, 0}, {0, 1, 0}, {1, 0, 0}},  // z = 0, normal -z
      {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}},  // z = 1, normal +z
      {{0, 0, 0}, {1, 0, 0}, {0, 0, 1}},  // y = 0, normal -y
      {{0, 1, 0}, {0, 0, 1}, {1, 0, 0}},  // y = 1, normal +y
      {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}},  // x = 0, normal -x
      {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}},  // x = 1, normal +x
  };
  for (const auto& fr : frames) {
    const uint32_t base = static_cast<uint32_t>(m.positions.size());
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) m.positions.push_back(fr[0] + fr[1] * (float(i) / n) + fr[2] * (float(j) / n));
    auto id = [&](int i, int j) { return base + uint32_t(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
        m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
      }
  }
  return m;
}

// Planar n x n grid in z = 0 with the quads in [h0, h1)^2 removed (a hole).
IndexedMesh gridWithHole(int n, int h0, int h1) {
  IndexedMesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.positions.push_back({float(i), float(j), 0.0f});
  auto id = [&](int i, int j) { return uint32_t(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      if (i >= h0 && i < h1 && j >= h0 && j < h1) continue;
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

void expectValid(const PatchLayout& l, const std::string& what) {
  const std::vector<std::string> errs = validatePatchLayout(l);
  EXPECT_TRUE(errs.empty()) << what << ": " << errs.size() << " violations, first: " << errs[0];
}

TEST(Charting, CubeBecomesSixQuads) {
  const IndexedMesh cube = gridCube(4);
  ChartingOptions o;
  o.targetPatches = 6;
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(cube, o, &st);
  expectValid(l, "cube");
  EXPECT_EQ(st.verticesWelded, 6u * 25u - 98u);  // 6 faces of 25 vertices, 98 distinct
  EXPECT_EQ(l.positions.size(), 98u);
  EXPECT_EQ(l.triangles.size(), cube.triangles.size());
  ASSERT_EQ(l.patches.size(), 6u);
  for (const Patch& p : l.patches) {
    EXPECT_EQ(p.sides.size(), 4u);
    EXPECT_EQ(p.triangles.size(), 32u);
    for (const PatchSide& s : p.sides) {
      EXPECT_EQ(s.vertices.size(), 5u);  // a whole cube edge
      EXPECT_GE(s.neighbourPatch, 0);
    }
  }
  EXPECT_EQ(st.boundaryEdges, 0u);
  EXPECT_EQ(st.nonManifoldEdges, 0u);
  EXPECT_LT(st.maxPlanarityError, 1e-6);
}

TEST(Charting, CubeSingleFaceDecomposedAtSmallTargetsStaysValid) {
  const IndexedMesh cube = gridCube(3);
  for (uint32_t target : {1u, 2u, 3u, 12u, 40u}) {
    ChartingOptions o;
    o.targetPatches = target;
    ChartingStats st;
    const PatchLayout l = buildPatchLayout(cube, o, &st);
    expectValid(l, "cube target " + std::to_string(target));
    // A closed surface needs at least two disks.
    EXPECT_GE(l.patches.size(), std::max(2u, target));
  }
}

TEST(Charting, TetrahedronNeedsCornerInsertion) {
  IndexedMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  ChartingOptions o;
  o.targetPatches = 2;
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(m, o, &st);
  expectValid(l, "tetrahedron");
  ASSERT_EQ(l.patches.size(), 2u);
  EXPECT_EQ(st.cornersInserted, 3u);
  for (const Patch& p : l.patches) EXPECT_EQ(p.sides.size(), 3u);
  // With 4 charts every vertex joins 3 patches: natural corners only.
  o.targetPatches = 4;
  const PatchLayout l4 = buildPatchLayout(m, o, &st);
  expectValid(l4, "tetrahedron 4");
  EXPECT_EQ(l4.patches.size(), 4u);
  EXPECT_EQ(st.cornersInserted, 0u);
}

TEST(Charting, OpenGridWithHole) {
  const IndexedMesh m = gridWithHole(12, 4, 8);
  for (uint32_t target : {1u, 4u, 10u}) {
    ChartingOptions o;
    o.targetPatches = target;
    ChartingStats st;
    const PatchLayout l = buildPatchLayout(m, o, &st);
    expectValid(l, "grid with hole, target " + std::to_string(target));
    // An annulus is not a disk: at least two charts.
    EXPECT_GE(l.patches.size(), std::max(2u, target));
    EXPECT_EQ(st.boundaryEdges, 4u * 12u + 4u * 4u);
    size_t open = 0;
    for (const Patch& p : l.patches)
      for (const PatchSide& s : p.sides)
        if (s.neighbourPatch < 0) open += s.vertices.size() - 1;
    EXPECT_EQ(open, st.boundaryEdges);
  }
}

TEST(Charting, BowTieVertexIsSplit) {
  IndexedMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
  m.triangles = {{0, 1, 2}, {0, 3, 4}};
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(m, {}, &st);
  expectValid(l, "bow-tie");
  EXPECT_EQ(st.nonManifoldVertices, 1u);
  EXPECT_EQ(st.verticesSplit, 1u);
  EXPECT_EQ(l.positions.size(), 6u);
  EXPECT_EQ(l.patches.size(), 2u);
  EXPECT_EQ(st.cornersInserted, 6u);
}

TEST(Charting, FinEdgeIsRepaired) {
  IndexedMesh m;
  // Three triangles on edge 0-1, plus a duplicate (after welding) that is dropped.
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0.5f, 1, 0}, {0.5f, -1, 0}, {0.5f, 0, 1}, {0.5f, 0, 1}};
  m.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}, {0, 1, 5}, {2, 2, 1}};
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(m, {}, &st);
  expectValid(l, "fin");
  EXPECT_EQ(st.droppedDegenerate, 1u);
  EXPECT_EQ(st.droppedDuplicate, 1u);
  EXPECT_EQ(st.verticesWelded, 1u);
  EXPECT_EQ(st.nonManifoldEdges, 1u);
  EXPECT_EQ(st.verticesSplit, 2u);  // the fin's copy of edge 0-1
  EXPECT_EQ(l.triangles.size(), 3u);
  EXPECT_EQ(st.outputTriangles + st.droppedDegenerate + st.droppedDuplicate, st.inputTriangles);
}

TEST(Charting, TwoCubesWithColoursKeepTheirColours) {
  IndexedMesh m = gridCube(2);
  const IndexedMesh b = gridCube(2);
  const uint32_t base = static_cast<uint32_t>(m.positions.size());
  for (const glm::vec3& p : b.positions) m.positions.push_back(p + glm::vec3(3, 0, 0));
  for (const auto& t : b.triangles) m.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  for (const glm::vec3& p : m.positions)
    m.colours.push_back(glm::u8vec4(uint8_t(p.x * 50), uint8_t(p.y * 200), uint8_t(p.z * 200), 255));
  ChartingOptions o;
  o.targetPatches = 12;
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(m, o, &st);
  expectValid(l, "two cubes");
  ASSERT_EQ(l.patches.size(), 12u);
  for (const Patch& p : l.patches) EXPECT_EQ(p.sides.size(), 4u);
  ASSERT_EQ(l.colours.size(), l.positions.size());
  for (size_t v = 0; v < l.positions.size(); ++v) {
    const glm::vec3& p = l.positions[v];
    EXPECT_EQ(l.colours[v], glm::u8vec4(uint8_t(p.x * 50), uint8_t(p.y * 200), uint8_t(p.z * 200), 255));
  }
}

TEST(Charting, FlippedTriangleIsCutOut) {
  IndexedMesh m = gridWithHole(6, 0, 0);
  std::swap(m.triangles[20][1], m.triangles[20][2]);  // inconsistent orientation
  ChartingOptions o;
  o.targetPatches = 3;
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(m, o, &st);
  expectValid(l, "flipped triangle");
  EXPECT_EQ(st.nonManifoldEdges, 3u);  // its three edges are left open
  EXPECT_EQ(st.verticesSplit, 3u);
  EXPECT_EQ(l.triangles.size(), m.triangles.size());
}

TEST(Charting, BadInputThrows) {
  IndexedMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}};
  m.triangles = {{0, 1, 2}};
  EXPECT_THROW(buildPatchLayout(m), InputError);
  m.positions.push_back({0, 1, 0});
  ChartingOptions o;
  o.minSides = 2;
  EXPECT_THROW(buildPatchLayout(m, o), InputError);
  o = {};
  o.maxSides = 3;
  EXPECT_THROW(buildPatchLayout(m, o), InputError);
  o = {};
  o.maxError = 0;
  EXPECT_THROW(buildPatchLayout(m, o), InputError);
  m.triangles = {{0, 0, 1}};
  EXPECT_THROW(buildPatchLayout(m), InputError);
}

TEST(Charting, ValidatorCatchesBrokenLayouts) {
  ChartingOptions o;
  o.targetPatches = 6;
  PatchLayout l = buildPatchLayout(gridCube(2), o);
  ASSERT_TRUE(validatePatchLayout(l).empty());
  PatchLayout a = l;
  a.patches[0].sides[0].neighbourSide = (a.patches[0].sides[0].neighbourSide + 1) % 4;
  EXPECT_FALSE(validatePatchLayout(a).empty());
  PatchLayout b = l;
  b.patches[1].triangles.push_back(b.patches[0].triangles[0]);
  EXPECT_FALSE(validatePatchLayout(b).empty());
  PatchLayout c = l;
  std::swap(c.patches[2].sides[0], c.patches[2].sides[1]);
  EXPECT_FALSE(validatePatchLayout(c).empty());
  EXPECT_FALSE(validatePatchLayout(l, 3, 3).empty());  // 4 sides > 3
}

// Within one patch: a hole (an inner triangle taken out) and a triangle listed twice.
TEST(Charting, ValidatorCatchesBrokenPatches) {
  ChartingOptions o;
  o.targetPatches = 6;
  const PatchLayout l = buildPatchLayout(gridCube(4), o);
  ASSERT_TRUE(validatePatchLayout(l).empty());
  auto says = [](const std::vector<std::string>& errs, const std::string& what) {
    for (const std::string& e : errs) {
      if (e.find(what) != std::string::npos) return true;
    }
    return false;
  };
  // The first triangle of patch 0 with no vertex on its sides.
  const Patch& p0 = l.patches[0];
  std::vector<uint32_t> onSides;
  for (const PatchSide& s : p0.sides) onSides.insert(onSides.end(), s.vertices.begin(), s.vertices.end());
  auto inner = std::find_if(p0.triangles.begin(), p0.triangles.end(), [&](uint32_t t) {
    for (uint32_t v : l.triangles[t]) {
      if (std::find(onSides.begin(), onSides.end(), v) != onSides.end()) return false;
    }
    return true;
  });
  ASSERT_NE(inner, p0.triangles.end());
  PatchLayout holed = l;
  holed.patches[0].triangles.erase(holed.patches[0].triangles.begin() + (inner - p0.triangles.begin()));
  const std::vector<std::string> h = validatePatchLayout(holed);
  EXPECT_TRUE(says(h, "patch 0: Euler characteristic 0, not 1")) << (h.empty() ? "" : h.front());
  EXPECT_TRUE(says(h, "patch 0: boundary is not a single loop"));
  PatchLayout twice = l;
  twice.patches[0].triangles.push_back(twice.patches[0].triangles.front());
  EXPECT_TRUE(says(validatePatchLayout(twice), "patch 0: repeated directed edge"));
}

struct MeshCase {
  const char* file;
  uint64_t boundaryEdges;  // known open edges (bunny: 5 holes)
};

class ChartingShared : public ::testing::TestWithParam<MeshCase> {};

TEST_P(ChartingShared, LayoutValidNearTarget) {
  const fs::path path = test::realData(std::string("meshes/") + GetParam().file);
  GIMLOD_NEED_SHARED_DATA(fs::exists(path));
  const IndexedMesh mesh = readMesh(path);
  for (uint32_t target : {50u, 200u}) {
    ChartingOptions o;
    o.targetPatches = target;
    ChartingStats st;
    const auto t0 = std::chrono::steady_clock::now();
    const PatchLayout l = buildPatchLayout(mesh, o, &st);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf(
        "[charting] %s target %u: %u charts (%u clustered, %u splits, %u corners inserted), "
        "%zu tris, weld %.2fs cluster %.2fs sides %.2fs total %.2fs; planarity max %.4f mean "
        "%.4f; nm edges %llu vertices split %llu; peak ~%.0f MB\n",
        GetParam().file, target, st.charts, st.chartsBeforeFixing, st.patchesSplit, st.cornersInserted,
        l.triangles.size(), st.weldSeconds, st.clusterSeconds, st.sidesSeconds, secs, st.maxPlanarityError,
        st.meanPlanarityError, (unsigned long long)st.nonManifoldEdges, (unsigned long long)st.verticesSplit,
        st.peakBytesEstimate / 1e6);
    std::printf("[charting]   sides histogram:");
    for (size_t n = 0; n < st.sidesHistogram.size(); ++n)
      if (st.sidesHistogram[n]) std::printf(" %zu:%u", n, st.sidesHistogram[n]);
    std::printf("\n");
    EXPECT_EQ(st.patchesUnfixed, 0u);
    const std::vector<std::string> errs = validatePatchLayout(l);
    EXPECT_TRUE(errs.empty()) << errs.size() << " violations, first: " << errs[0];
    EXPECT_EQ(st.inputTriangles, mesh.triangles.size());
    EXPECT_EQ(l.triangles.size(), st.outputTriangles);
    EXPECT_EQ(st.outputTriangles + st.droppedDegenerate + st.droppedDuplicate, st.inputTriangles);
    if (GetParam().boundaryEdges != ~0ull) {
      EXPECT_EQ(st.boundaryEdges, GetParam().boundaryEdges);
    }
    // Merging stops exactly at the target here (non-disk refusals only bind at a few charts);
    // splitting patches with more than 8 sides adds charts: observed at most 6% at these
    // targets on these meshes, allow 25%.
    EXPECT_EQ(st.chartsBeforeFixing, target);
    EXPECT_GE(st.charts, target);
    EXPECT_LE(st.charts, target + target / 4);
    EXPECT_EQ(st.charts, st.chartsBeforeFixing + st.patchesSplit);
  }
}

INSTANTIATE_TEST_SUITE_P(Charting, ChartingShared,
                         ::testing::Values(MeshCase{"bun_zipper.ply", 223}, MeshCase{"igea.ply", ~0ull},
                                           MeshCase{"turbineblade.ply", ~0ull}, MeshCase{"horse.ply", ~0ull},
                                           MeshCase{"armadillo.obj", ~0ull}),
                         [](const auto& info) {
                           std::string n = info.param.file;
                           return n.substr(0, n.find('.'));
                         });

TEST(Charting, ErrorTargetOnBunny) {
  const fs::path path = test::realData("meshes/bun_zipper.ply");
  const IndexedMesh mesh = readMesh(path);
  ChartingOptions o;
  o.maxError = 0.01;
  ChartingStats st;
  const PatchLayout l = buildPatchLayout(mesh, o, &st);
  std::printf("[charting] bunny maxError %.3f: %u charts, planarity max %.4f mean %.4f, %.2fs\n", o.maxError, st.charts,
              st.maxPlanarityError, st.meanPlanarityError, st.seconds);
  expectValid(l, "bunny error mode");
  EXPECT_GT(st.charts, 10u);
  // Splits only cut charts that met the bound; a half's RMS can exceed its parent's a little.
  EXPECT_LE(st.maxPlanarityError, 2 * o.maxError);
}

TEST(Charting, BlockedClusteringIsDeterministic) {
  const fs::path path = test::realData("meshes/bun_zipper.ply");
  const IndexedMesh mesh = readMesh(path);
  ChartingOptions o;
  o.targetPatches = 80;
  o.threads = 1;
  ChartingStats st1, st2;
  const PatchLayout a = buildPatchLayout(mesh, o, &st1);
  o.threads = 2;
  const PatchLayout b = buildPatchLayout(mesh, o, &st2);
  EXPECT_GT(st1.cells, 1u);  // the blocked path ran
  ASSERT_EQ(a.patches.size(), b.patches.size());
  for (size_t p = 0; p < a.patches.size(); ++p) {
    EXPECT_EQ(a.patches[p].triangles, b.patches[p].triangles);
    ASSERT_EQ(a.patches[p].sides.size(), b.patches[p].sides.size());
    for (size_t i = 0; i < a.patches[p].sides.size(); ++i)
      EXPECT_EQ(a.patches[p].sides[i].vertices, b.patches[p].sides[i].vertices);
  }
}

TEST(Charting, CellsPathOnBunny) {
  const fs::path path = test::realData("meshes/bun_zipper.ply");
  test::TempDir dir("charting");
  GridifyOptions g;
  g.targetTrianglesPerCell = 4000;
  const GridifyResult gr = gridify(path, dir.path() / "grid", g);
  ChartingOptions o;
  o.targetPatches = 100;
  o.threads = 2;
  ChartingStats st;
  const PatchLayout l = buildPatchLayoutFromCells(dir.path() / "grid", o, &st);
  std::printf(
      "[charting] bunny cells: %u cells, %u cell clusters (%u dissolved), %u charts, "
      "cluster %.2fs total %.2fs\n",
      st.cells, st.cellClusters, st.cellClustersDissolved, st.charts, st.clusterSeconds, st.seconds);
  expectValid(l, "bunny cells");
  EXPECT_GT(st.cells, 4u);
  EXPECT_EQ(l.triangles.size() + st.droppedDegenerate + st.droppedDuplicate, gr.triangles);
  EXPECT_EQ(st.boundaryEdges, 223u);
  EXPECT_GE(st.charts, o.targetPatches);
  EXPECT_LE(st.charts, o.targetPatches * 5 / 4);
}

// The cone fit of the developable metric, on faceted surfaces: 0 where every face normal makes
// one angle with an axis (a plane, a half cylinder, a cone), and about theta^4 / 48 on a spherical
// cap of half-angle theta (the variance of cos t, t the polar angle, over the cap; across the axis
// the normals vary by theta^2 / 4).
TEST(Charting, ConeFitVarianceIsZeroOnDevelopableSurfacesOnly) {
  constexpr double kPi = 3.14159265358979323846;
  // A grid of n x n quads (two triangles each) of surface(u, v), u, v in [0, 1].
  auto moments = [](auto surface) {
    charting::Moments m;
    const int n = 24;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const glm::dvec3 a = surface(i / double(n), j / double(n)), b = surface((i + 1) / double(n), j / double(n)),
                         c = surface((i + 1) / double(n), (j + 1) / double(n)),
                         d = surface(i / double(n), (j + 1) / double(n));
        m.add(charting::triangleMoments(a, b, c));
        m.add(charting::triangleMoments(a, c, d));
      }
    return charting::coneFitVariance(m);
  };
  const double plane = moments([](double u, double v) { return glm::dvec3(u, 0.3 * v, 0.0); });
  const double cylinder = moments([&](double u, double v) {
    return glm::dvec3(std::cos(kPi * u), std::sin(kPi * u), 2.0 * v);  // half a turn
  });
  const double cone = moments([&](double u, double v) {
    const double r = 0.2 + v;  // apex angle 45 degrees
    return glm::dvec3(r * std::cos(1.5 * kPi * u), r * std::sin(1.5 * kPi * u), r);
  });
  const double theta = kPi / 6;
  const double cap = moments([&](double u, double v) {
    const double t = theta * v, p = 2 * kPi * u;  // polar angle t, azimuth p (a degenerate row at the pole)
    return glm::dvec3(std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t));
  });
  EXPECT_LT(plane, 1e-12);
  EXPECT_LT(cylinder, 1e-12);
  EXPECT_LT(cone, 1e-12);
  const double theta4 = theta * theta * theta * theta;
  EXPECT_GT(cap, 0.8 * theta4 / 48);
  EXPECT_LT(cap, 1.2 * theta4 / 48);
}

// The developable metric clusters the shipped bunny into patches that fit cones better, which is
// what it ranks merges by; the planar metric's patches fit planes better.
TEST(Charting, DevelopableMetricMakesPatchesThatFitCones) {
  const IndexedMesh mesh = readMesh(test::realData("meshes/bun_zipper.ply"));
  // Area-weighted means over the patches of the cone-fit variance and of the plane fit (mean
  // squared distance, in the bounding-box diagonal's units).
  auto fits = [](const PatchLayout& l) {
    glm::dvec3 lo(1e300), hi(-1e300);
    for (const glm::vec3& p : l.positions) lo = glm::min(lo, glm::dvec3(p)), hi = glm::max(hi, glm::dvec3(p));
    const double diag = glm::length(hi - lo);
    double cone = 0, plane = 0, area = 0;
    for (const Patch& p : l.patches) {
      charting::Moments m;
      for (uint32_t t : p.triangles) {
        const auto& tri = l.triangles[t];
        m.add(charting::triangleMoments(glm::dvec3(l.positions[tri[0]]) / diag, glm::dvec3(l.positions[tri[1]]) / diag,
                                        glm::dvec3(l.positions[tri[2]]) / diag));
      }
      cone += m.area * charting::coneFitVariance(m);
      plane += m.area * charting::planeMsd(m);
      area += m.area;
    }
    return std::pair{cone / area, plane / area};
  };
  ChartingOptions o;
  o.targetPatches = 24;
  const PatchLayout planar = buildPatchLayout(mesh, o);
  o.metric = ChartMetric::kDevelopable;
  const PatchLayout developable = buildPatchLayout(mesh, o);
  expectValid(developable, "bunny, developable metric");
  const auto [planarCone, planarPlane] = fits(planar);
  const auto [devCone, devPlane] = fits(developable);
  std::printf("[charting] bunny, 24 patches: cone-fit variance %.4f planar, %.4f developable; plane msd %.3g, %.3g\n",
              planarCone, devCone, planarPlane, devPlane);
  EXPECT_LT(devCone, 0.8 * planarCone);
  EXPECT_LT(planarPlane, devPlane);
}

}  // namespace
}  // namespace gimlod

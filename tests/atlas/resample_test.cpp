// Tests for quadrangulation and resampling: a flat square reproduces the plane exactly; two
// patches sharing a side, a cube and a sphere-like cube are seamless (shared edge samples
// bit-identical at every pyramid level, corners identical in every chart that meets there);
// n-gon disks and hemisphere caps have no flipped texels and bounded stretch; neighbour tables
// are reciprocal; results do not depend on the thread count; a disk region of the real bunny
// resamples without flips.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <queue>
#include <stdexcept>
#include <unordered_map>

#include "atlas/mesh/mesh_io.h"
#include "atlas/mesh/resample.h"
#include "tests/chart_layout_fixture.h"
#include "tests/seam_check.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

using test::expectSeamless;
using test::sameBytes;

// Chart corner (0,0) of quad i is corner i of its patch: the layout vertex exactly, and the
// same bytes (position, normal, colour) in every chart that meets there.
void expectCornersShared(const PatchLayout& layout, const GeometryImageSet& set, uint32_t expectMeeting = 0) {
  std::map<uint32_t, std::vector<uint32_t>> byVertex;
  for (uint32_t c = 0; c < set.charts.size(); ++c) {
    const GeometryImage& g = set.charts[c];
    const uint32_t v = layout.patches[g.patch].sides[g.quad].vertices.front();
    EXPECT_TRUE(sameBytes(&g.positions[0], &layout.positions[v], sizeof(glm::vec3)));
    byVertex[v].push_back(c);
  }
  for (const auto& [v, charts] : byVertex) {
    if (expectMeeting) {
      EXPECT_EQ(charts.size(), expectMeeting) << "vertex " << v;
    }
    const GeometryImage& first = set.charts[charts[0]];
    for (uint32_t c : charts) {
      const GeometryImage& g = set.charts[c];
      EXPECT_TRUE(sameBytes(&g.normals[0], &first.normals[0], sizeof(PackedNormal)));
      if (!g.colours.empty()) {
        EXPECT_TRUE(sameBytes(&g.colours[0], &first.colours[0], sizeof(glm::u8vec4)));
      }
    }
  }
}

void expectNoFlips(const GeometryImageSet& set) {
  EXPECT_EQ(set.image.flippedTexels, 0u);
  EXPECT_EQ(set.param.flippedTriangles, 0u);
  for (const GeometryImage& g : set.charts) {
    EXPECT_EQ(g.quality.flippedTexels, 0u) << "patch " << g.patch << " quad " << g.quad;
    EXPECT_TRUE(std::isfinite(g.quality.stretchL2));
    EXPECT_TRUE(std::isfinite(g.quality.stretchLinf));
  }
}

void print(const char* what, const GeometryImageSet& set) {
  std::printf(
      "  %s: %zu charts of %u^2, param L2 %.4f -> %.4f (Linf %.3f -> %.3f), image L2 "
      "%.4f Linf %.3f, flipped %u, degenerate %u, %.3f s\n",
      what, set.charts.size(), set.chartSize, set.paramInitial.stretchL2, set.param.stretchL2,
      set.paramInitial.stretchLinf, set.param.stretchLinf, set.image.stretchL2, set.image.stretchLinf,
      set.image.flippedTexels, set.image.degenerateTexels, set.seconds);
}

TEST(Resample, EdgeSampleIndexRunsCounterClockwise) {
  // 3x3 chart: bottom 0,1,2; right 2,5,8; top 8,7,6; left 6,3,0.
  const uint32_t expect[4][3] = {{0, 1, 2}, {2, 5, 8}, {8, 7, 6}, {6, 3, 0}};
  for (uint32_t e = 0; e < 4; ++e) {
    for (uint32_t k = 0; k < 3; ++k) EXPECT_EQ(edgeSampleIndex(3, e, k), expect[e][k]);
  }
}

TEST(Resample, FlatSquareMatchesPlane) {
  const PatchLayout layout = test::gridLayout(12, 12, 3.f, 3.f);
  ResampleOptions opt;
  opt.chartSize = 17;
  const GeometryImageSet set = resampleLayout(layout, opt);
  ASSERT_EQ(set.charts.size(), 4u);
  const uint32_t m = 16;
  // Quad i: corner i, midpoint of side i, centre, midpoint of side i-1 of the square.
  const glm::dvec3 corners[4] = {{0, 0, 0}, {3, 0, 0}, {3, 3, 0}, {0, 3, 0}};
  const glm::dvec3 centre(1.5, 1.5, 0);
  for (uint32_t i = 0; i < 4; ++i) {
    const GeometryImage& g = set.charts[i];
    EXPECT_EQ(g.patch, 0u);
    EXPECT_EQ(g.quad, i);
    EXPECT_TRUE(g.colours.empty());
    const glm::dvec3 c = corners[i], mi = 0.5 * (corners[i] + corners[(i + 1) % 4]),
                     mp = 0.5 * (corners[i] + corners[(i + 3) % 4]);
    for (uint32_t v = 0; v <= m; ++v) {
      for (uint32_t u = 0; u <= m; ++u) {
        const double s = double(u) / m, t = double(v) / m;
        const glm::dvec3 e = (1 - s) * (1 - t) * c + s * (1 - t) * mi + s * t * centre + (1 - s) * t * mp;
        const glm::vec3 p = g.positions[v * 17 + u];
        ASSERT_NEAR(p.x, e.x, 1e-5) << i << " " << u << " " << v;
        ASSERT_NEAR(p.y, e.y, 1e-5);
        ASSERT_EQ(p.z, 0.f);
        EXPECT_EQ(g.normals[v * 17 + u], packNormal(0.f, 0.f, 1.f));
      }
    }
    EXPECT_NEAR(g.quality.stretchL2, 1.0, 1e-4);
    EXPECT_NEAR(g.quality.stretchLinf, 1.0, 1e-4);
    EXPECT_EQ(g.quality.degenerateTexels, 0u);
    EXPECT_NEAR(g.quality.area3D, 2.25, 1e-4);
  }
  expectNoFlips(set);
  EXPECT_GT(expectSeamless(set), 0u);
  // Inside the patch: right edge of quad i meets the top edge of quad i+1; outer edges are open.
  for (uint32_t i = 0; i < 4; ++i) {
    const auto& nb = set.charts[i].neighbours;
    EXPECT_EQ(nb[kEdgeRight].chart, int32_t((i + 1) % 4));
    EXPECT_EQ(nb[kEdgeRight].edge, kEdgeTop);
    EXPECT_EQ(nb[kEdgeTop].chart, int32_t((i + 3) % 4));
    EXPECT_EQ(nb[kEdgeBottom].chart, -1);
    EXPECT_EQ(nb[kEdgeLeft].chart, -1);
  }
}

TEST(Resample, TwoPatchesShareABitIdenticalSide) {
  // A warped planar grid cut at column 7 of 16: the two patches have different shapes, so the
  // shared side is sampled from two different parameterizations.
  const PatchLayout layout = test::gridLayout(16, 9, 4.f, 2.f, {7}, true);
  ASSERT_EQ(layout.patches[0].sides[1].neighbourPatch, 1);
  ASSERT_EQ(layout.patches[1].sides[3].neighbourPatch, 0);
  for (const uint32_t size : {9u, 33u}) {
    ResampleOptions opt;
    opt.chartSize = size;
    const GeometryImageSet set = resampleLayout(layout, opt);
    ASSERT_EQ(set.charts.size(), 8u);
    // Patch 0 side 1 (first half: quad 1 bottom) meets patch 1 side 3 (second half: quad 0 left).
    EXPECT_EQ(set.charts[1].neighbours[kEdgeBottom].chart, 4 + 0);
    EXPECT_EQ(set.charts[1].neighbours[kEdgeBottom].edge, kEdgeLeft);
    EXPECT_TRUE(set.charts[1].neighbours[kEdgeBottom].reversed);
    EXPECT_GT(expectSeamless(set), 0u);
    expectCornersShared(layout, set);
    expectNoFlips(set);
    for (const GeometryImage& g : set.charts) {
      for (const glm::vec3& p : g.positions) EXPECT_EQ(p.z, 0.f);
    }
    if (size == 33) print("two warped patches", set);
  }
}

TEST(Resample, CubeAndSphereAreSeamless) {
  for (const bool sphere : {false, true}) {
    SCOPED_TRACE(sphere ? "sphere" : "cube");
    const PatchLayout layout = test::cubeLayout(7, sphere);
    ResampleOptions opt;
    opt.chartSize = 33;
    const GeometryImageSet set = resampleLayout(layout, opt);
    ASSERT_EQ(set.charts.size(), 24u);
    for (const GeometryImage& g : set.charts) {
      for (const RootNeighbour& nb : g.neighbours) EXPECT_GE(nb.chart, 0);  // closed surface
    }
    EXPECT_EQ(expectSeamless(set), 24u * 4 * (33 + 17 + 9 + 5 + 3 + 2));
    expectCornersShared(layout, set, 3);  // three faces meet at every cube corner
    expectNoFlips(set);
    test::expectCubeImage(set, sphere);
    if (sphere) {
      for (const GeometryImage& g : set.charts) {
        for (const glm::vec3& p : g.positions) {
          EXPECT_LE(glm::length(p), 1.0f + 1e-5f);
          EXPECT_GT(glm::length(p), 0.95f);  // chord error of 7 cells per face
        }
      }
    }
    print(sphere ? "sphere (cube)" : "cube", set);
  }
}

TEST(Resample, NonReversedJoinIsSeamless) {
  // Patch 1 of a two-patch grid re-oriented (triangles and sides reversed): both patches list the
  // shared side in the same order (a non-orientable join, reversed = false).
  PatchLayout layout = test::gridLayout(8, 4, 2.f, 1.f, {4});
  Patch& b = layout.patches[1];
  for (uint32_t t : b.triangles) std::swap(layout.triangles[t][1], layout.triangles[t][2]);
  std::reverse(b.sides.begin(), b.sides.end());
  for (PatchSide& side : b.sides) std::reverse(side.vertices.begin(), side.vertices.end());
  ASSERT_EQ(b.sides[0].vertices, layout.patches[0].sides[1].vertices);
  b.sides[0].neighbourSide = 1;
  b.sides[0].reversed = false;
  layout.patches[0].sides[1].neighbourSide = 0;
  layout.patches[0].sides[1].reversed = false;
  ResampleOptions opt;
  opt.chartSize = 17;
  const GeometryImageSet set = resampleLayout(layout, opt);
  const RootNeighbour nb = set.charts[1].neighbours[kEdgeBottom];
  EXPECT_EQ(nb.chart, 4);
  EXPECT_EQ(nb.edge, kEdgeBottom);
  EXPECT_FALSE(nb.reversed);
  EXPECT_GT(expectSeamless(set), 0u);
  expectCornersShared(layout, set);
}

TEST(Resample, NGonPatchesHaveNoFlippedTexels) {
  for (const bool hemisphere : {false, true}) {
    for (const uint32_t n : {3u, 5u, 8u}) {
      SCOPED_TRACE(testing::Message() << "n=" << n << " hemisphere=" << hemisphere);
      const PatchLayout layout = test::diskLayout(n, 12, 48, hemisphere, true);
      ResampleOptions opt;
      opt.chartSize = 33;
      const GeometryImageSet set = resampleLayout(layout, opt);
      ASSERT_EQ(set.charts.size(), n);
      expectNoFlips(set);
      EXPECT_EQ(set.image.degenerateTexels, 0u);
      EXPECT_GT(expectSeamless(set), 0u);  // the centre-to-midpoint edges inside the patch
      EXPECT_LT(set.image.stretchL2, 2.0);
      EXPECT_LT(set.image.stretchLinf, 6.0);
      // The patch centre is one sample shared by all n quads.
      for (const GeometryImage& g : set.charts) {
        EXPECT_EQ(g.colours.size(), 33u * 33u);
        EXPECT_TRUE(sameBytes(&g.positions.back(), &set.charts[0].positions.back(), sizeof(glm::vec3)));
        for (const glm::vec3& p : g.positions) {
          if (hemisphere) {
            EXPECT_LE(glm::length(p), 1.0f + 1e-5f);
            EXPECT_GT(glm::length(p), 0.98f);
            EXPECT_GE(p.z, -1e-6f);
          } else {
            EXPECT_EQ(p.z, 0.f);
            EXPECT_LE(glm::length(p), 1.0f + 1e-5f);
          }
        }
      }
      char what[64];
      std::snprintf(what, sizeof(what), "%u-gon %s", n, hemisphere ? "hemisphere" : "disk");
      print(what, set);
    }
  }
}

TEST(Resample, NeighbourTablesAreReciprocal) {
  for (const PatchLayout& layout :
       {test::cubeLayout(3), test::gridLayout(9, 3, 3.f, 1.f, {3, 6}), test::diskLayout(5, 3, 20, false)}) {
    const auto nb = quadNeighbours(layout);
    ASSERT_EQ(nb.size(), quadChartOffsets(layout).back() + layout.patches.back().sides.size());
    for (uint32_t c = 0; c < nb.size(); ++c) {
      for (uint32_t e = 0; e < 4; ++e) {
        if (nb[c][e].chart < 0) continue;
        const RootNeighbour back = nb[uint32_t(nb[c][e].chart)][nb[c][e].edge];
        EXPECT_EQ(back.chart, int32_t(c));
        EXPECT_EQ(back.edge, e);
        EXPECT_TRUE(back.reversed);
      }
    }
  }
}

TEST(Resample, RejectsBadInput) {
  PatchLayout layout = test::gridLayout(6, 3, 2.f, 1.f, {3});
  ResampleOptions opt;
  opt.chartSize = 16;
  EXPECT_THROW(resampleLayout(layout, opt), std::invalid_argument);
  opt.chartSize = 9;
  EXPECT_NO_THROW(resampleLayout(layout, opt));
  PatchLayout oneWay = layout;
  oneWay.patches[1].sides[3].neighbourPatch = -1;
  EXPECT_THROW(resampleLayout(oneWay, opt), std::invalid_argument);
  EXPECT_THROW(quadNeighbours(oneWay), std::invalid_argument);
  PatchLayout notReversed = layout;
  notReversed.patches[0].sides[1].reversed = false;
  notReversed.patches[1].sides[3].reversed = false;
  EXPECT_THROW(resampleLayout(notReversed, opt), std::invalid_argument);
}

TEST(Resample, ThreadCountDoesNotChangeTheResult) {
  const PatchLayout layout = test::cubeLayout(5, true);
  ResampleOptions one, many;
  one.chartSize = many.chartSize = 17;
  one.threads = 1;
  many.threads = 2;
  const GeometryImageSet a = resampleLayout(layout, one), b = resampleLayout(layout, many);
  ASSERT_EQ(a.charts.size(), b.charts.size());
  for (size_t c = 0; c < a.charts.size(); ++c) {
    EXPECT_TRUE(sameBytes(a.charts[c].positions.data(), b.charts[c].positions.data(),
                          a.charts[c].positions.size() * sizeof(glm::vec3)));
    EXPECT_TRUE(sameBytes(a.charts[c].normals.data(), b.charts[c].normals.data(),
                          a.charts[c].normals.size() * sizeof(PackedNormal)));
  }
}

// A BFS-grown region of about `target` triangles from `seed`, closed over notches (triangles
// with two region neighbours are added); empty unless it is a disk. Fills `loop` with its
// boundary loop (in the triangles' orientation).
std::vector<uint32_t> diskRegion(const IndexedMesh& mesh, uint32_t seed, size_t target, std::vector<uint32_t>& loop) {
  const size_t nt = mesh.triangles.size();
  std::unordered_map<uint64_t, std::vector<uint32_t>> edgeTris;
  auto key = [](uint32_t a, uint32_t b) { return (uint64_t{std::min(a, b)} << 32) | std::max(a, b); };
  for (uint32_t t = 0; t < nt; ++t) {
    for (int c = 0; c < 3; ++c) edgeTris[key(mesh.triangles[t][c], mesh.triangles[t][(c + 1) % 3])].push_back(t);
  }
  auto neighbours = [&](uint32_t t) {
    std::vector<uint32_t> out;
    for (int c = 0; c < 3; ++c) {
      const auto& l = edgeTris[key(mesh.triangles[t][c], mesh.triangles[t][(c + 1) % 3])];
      if (l.size() == 2) out.push_back(l[0] == t ? l[1] : l[0]);
    }
    return out;
  };
  std::vector<uint8_t> in(nt, 0);
  std::vector<uint32_t> region;
  std::queue<uint32_t> queue;
  queue.push(seed);
  in[seed] = 1;
  while (!queue.empty() && region.size() < target) {
    const uint32_t t = queue.front();
    queue.pop();
    region.push_back(t);
    for (uint32_t o : neighbours(t)) {
      if (!in[o]) in[o] = 1, queue.push(o);
    }
  }
  while (!queue.empty()) in[queue.front()] = 0, queue.pop();
  for (bool grew = true; grew;) {
    grew = false;
    for (uint32_t t : std::vector<uint32_t>(region)) {
      for (uint32_t o : neighbours(t)) {
        if (in[o]) continue;
        int inside = 0;
        for (uint32_t x : neighbours(o)) inside += in[x];
        if (inside >= 2) in[o] = 1, region.push_back(o), grew = true;
      }
    }
  }
  // Boundary: directed edges whose reverse is not in the region; one loop, no repeated vertex.
  std::unordered_map<uint64_t, int> directed;
  for (uint32_t t : region) {
    for (int c = 0; c < 3; ++c) {
      directed[(uint64_t{mesh.triangles[t][c]} << 32) | mesh.triangles[t][(c + 1) % 3]]++;
    }
  }
  std::unordered_map<uint32_t, uint32_t> next;
  size_t boundaryEdges = 0;
  for (const auto& [k, count] : directed) {
    if (count != 1) return {};
    const uint32_t a = uint32_t(k >> 32), b = uint32_t(k);
    if (directed.contains((uint64_t{b} << 32) | a)) continue;
    if (!next.emplace(a, b).second) return {};  // pinched boundary vertex
    ++boundaryEdges;
  }
  loop.clear();
  if (next.empty()) return {};
  const uint32_t start = next.begin()->first;
  for (uint32_t v = start; loop.size() <= boundaryEdges;) {
    loop.push_back(v);
    v = next[v];
    if (v == start) break;
  }
  if (loop.size() != boundaryEdges) return {};
  std::unordered_map<uint32_t, int> verts;
  for (uint32_t t : region) {
    for (uint32_t v : mesh.triangles[t]) verts[v] = 1;
  }
  const int64_t euler = int64_t(verts.size()) - int64_t((directed.size() + boundaryEdges) / 2) + int64_t(region.size());
  if (euler != 1) return {};
  return region;
}

TEST(Resample, BunnyDiskRegion) {
  const auto path = test::realData("meshes/bun_zipper.ply");
  const IndexedMesh mesh = readMesh(path);
  std::vector<uint32_t> region, loop;
  for (uint32_t seed = 0; seed < mesh.triangles.size() && region.empty(); seed += 1777) {
    region = diskRegion(mesh, seed, 2000, loop);
  }
  ASSERT_FALSE(region.empty()) << "no disk-shaped region found";
  PatchLayout layout;
  layout.positions = mesh.positions;
  layout.triangles = mesh.triangles;
  Patch patch;
  patch.triangles = region;
  const size_t nb = loop.size();
  for (uint32_t i = 0; i < 4; ++i) {
    PatchSide side;
    for (size_t k = i * nb / 4; k <= (i + 1) * nb / 4; ++k) side.vertices.push_back(loop[k % nb]);
    patch.sides.push_back(side);
  }
  layout.patches.push_back(patch);

  const PatchParameterization pp = parameterizePatch(layout, 0);
  EXPECT_EQ(pp.quality.flippedTriangles, 0u);
  EXPECT_TRUE(std::isfinite(pp.quality.stretchL2));
  EXPECT_TRUE(std::isfinite(pp.quality.stretchLinf));
  std::printf(
      "  bunny region: %zu triangles, %zu boundary vertices, param L2 %.4f -> %.4f, Linf "
      "%.3f -> %.3f (%u reweightings, %u sweeps), degenerate %u\n",
      region.size(), nb, pp.initial.stretchL2, pp.quality.stretchL2, pp.initial.stretchLinf, pp.quality.stretchLinf,
      pp.iterationsUsed, pp.sweepsUsed, pp.quality.degenerateTriangles);

  ResampleOptions opt;
  opt.chartSize = 65;
  const GeometryImageSet set = resampleLayout(layout, opt);
  ASSERT_EQ(set.charts.size(), 4u);
  expectNoFlips(set);
  EXPECT_GT(expectSeamless(set), 0u);
  print("bunny region", set);
}

}  // namespace
}  // namespace gimlod

namespace gimlod {
namespace {

// A flat 5 x 5 image in the z = 0 plane, u along x and v along y (normal +z).
std::vector<glm::vec3> flatImage(bool mirrored) {
  std::vector<glm::vec3> p;
  for (int v = 0; v < 5; ++v) {
    for (int u = 0; u < 5; ++u) p.emplace_back(float(mirrored ? 4 - u : u), float(v), 0.f);
  }
  return p;
}

TEST(ResampleQuality, FlippedTexelsAreJudgedAgainstTheInputFaces) {
  const std::vector<glm::vec3> up(25, glm::vec3(0, 0, 1)), down(25, glm::vec3(0, 0, -1));
  // Faithful to the faces: no flips, whatever the vertex normals say.
  ImageQuality q = measureImage(flatImage(false), down, 5, nullptr, &up);
  EXPECT_EQ(q.flippedTexels, 0u);
  EXPECT_EQ(q.texelsAgainstNormals, 16u);  // a folded input: every texel against its vertex normals
  q = measureImage(flatImage(false), up, 5, nullptr, &up);
  EXPECT_EQ(q.flippedTexels, 0u);
  EXPECT_EQ(q.texelsAgainstNormals, 0u);
  // A mirrored image faces away from the faces it samples: all flipped, and all reported.
  std::vector<uint32_t> at;
  q = measureImage(flatImage(true), up, 5, &at, &up);
  EXPECT_EQ(q.flippedTexels, 16u);
  EXPECT_EQ(at.size(), 16u);
  // Without faces (zero face normals count as none), the vertex normals decide.
  const std::vector<glm::vec3> none(25, glm::vec3(0.f));
  EXPECT_EQ(measureImage(flatImage(true), up, 5, nullptr, &none).flippedTexels, 16u);
  EXPECT_EQ(measureImage(flatImage(true), up, 5).flippedTexels, 16u);
}

TEST(ResampleQuality, ATexelOverAnInputFinIsNotFlippedButOneOverACreaseIs) {
  const std::vector<glm::vec3> up(25, glm::vec3(0, 0, 1));
  // A fin: the input faces under the last column of samples (u = 4) face the other way. The
  // texels that reach it agree with the faces on their left and follow the input; the others
  // agree with every face. None is flipped.
  std::vector<glm::vec3> fin(25, glm::vec3(0, 0, 1));
  for (int v = 0; v < 5; ++v) fin[size_t(v) * 5 + 4] = glm::vec3(0, 0, -1);
  EXPECT_EQ(measureImage(flatImage(false), up, 5, nullptr, &fin).flippedTexels, 0u);
  // Mirrored, the texels of columns 0..2 face away from all their faces (flipped); those of
  // column 3 agree with the fin's faces at u = 4.
  EXPECT_EQ(measureImage(flatImage(true), up, 5, nullptr, &fin).flippedTexels, 12u);
  // A crease of 100 degrees (faces tilted 50 degrees either way): a mirrored image faces away
  // from both sides of it, so every texel is flipped.
  const float s = float(std::sin(50.0 * 3.14159265358979 / 180.0)),
              c = float(std::cos(50.0 * 3.14159265358979 / 180.0));
  std::vector<glm::vec3> crease(25);
  for (int v = 0; v < 5; ++v) {
    for (int u = 0; u < 5; ++u) crease[size_t(v) * 5 + u] = u < 2 ? glm::vec3(s, 0, c) : glm::vec3(-s, 0, c);
  }
  EXPECT_EQ(measureImage(flatImage(true), up, 5, nullptr, &crease).flippedTexels, 16u);
  EXPECT_EQ(measureImage(flatImage(false), up, 5, nullptr, &crease).flippedTexels, 0u);
}

}  // namespace
}  // namespace gimlod

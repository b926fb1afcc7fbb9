// Tests for refining a chart layout: straightened sides are never longer and keep the layout
// valid, and splitting patches: corner-to-corner cuts partition the triangles
// into two linked disks, inserted corners split both sides of a seam, a long strip is cut near
// its middle, refused splits leave the layout as it was, and the flip repair on a real scan never
// raises the flipped-texel count and leaves a valid layout that matches the charts it returns.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <fstream>
#include <limits>
#include <mutex>
#include <set>
#include <thread>

#include <tbb/global_control.h>

#include <glm/geometric.hpp>

#include "atlas/mesh/charting.h"
#include "atlas/mesh/layout_refine.h"
#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/mesh_io.h"
#include "atlas/mesh/patch_param.h"
#include "atlas/mesh/patch_topology.h"
#include "tests/chart_layout_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

void expectValid(const PatchLayout& layout) {
  const std::vector<std::string> bad = validatePatchLayout(layout);
  EXPECT_TRUE(bad.empty()) << bad.front();
}

// Bit-identical charts: samples, normals, neighbours and figures.
void expectSameCharts(const GeometryImageSet& a, const GeometryImageSet& b) {
  ASSERT_EQ(a.charts.size(), b.charts.size());
  for (size_t c = 0; c < a.charts.size(); ++c) {
    const GeometryImage &x = a.charts[c], &y = b.charts[c];
    ASSERT_EQ(x.positions.size(), y.positions.size()) << "chart " << c;
    EXPECT_EQ(std::memcmp(x.positions.data(), y.positions.data(), x.positions.size() * sizeof(glm::vec3)), 0)
        << "chart " << c;
    ASSERT_EQ(x.normals.size(), y.normals.size());
    EXPECT_EQ(std::memcmp(x.normals.data(), y.normals.data(), x.normals.size() * sizeof(PackedNormal)), 0)
        << "chart " << c;
    EXPECT_EQ(x.patch, y.patch);
    EXPECT_EQ(x.quad, y.quad);
    for (int e = 0; e < 4; ++e) {
      EXPECT_EQ(x.neighbours[e].chart, y.neighbours[e].chart);
      EXPECT_EQ(x.neighbours[e].edge, y.neighbours[e].edge);
      EXPECT_EQ(x.neighbours[e].reversed, y.neighbours[e].reversed);
    }
    EXPECT_EQ(x.quality.flippedTexels, y.quality.flippedTexels);
    EXPECT_EQ(x.quality.stretchL2, y.quality.stretchL2);
    EXPECT_EQ(x.foldTriangles, y.foldTriangles);
  }
  EXPECT_EQ(a.image.flippedTexels, b.image.flippedTexels);
  EXPECT_EQ(a.image.stretchL2, b.image.stretchL2);
  EXPECT_EQ(a.param.stretchL2, b.param.stretchL2);
}

// The shipped bunny charted to 128 patches: a real scan whose charts fold at 33^2 samples.
PatchLayout chartedBunny() {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = 128;
  return buildPatchLayout(mesh, copt);
}

bool sameLayout(const PatchLayout& a, const PatchLayout& b) {
  if (a.patches.size() != b.patches.size()) return false;
  for (size_t p = 0; p < a.patches.size(); ++p) {
    const Patch &x = a.patches[p], &y = b.patches[p];
    if (x.triangles != y.triangles || x.sides.size() != y.sides.size()) return false;
    for (size_t s = 0; s < x.sides.size(); ++s) {
      if (x.sides[s].vertices != y.sides[s].vertices || x.sides[s].neighbourPatch != y.sides[s].neighbourPatch ||
          x.sides[s].neighbourSide != y.sides[s].neighbourSide) {
        return false;
      }
    }
  }
  return true;
}

TEST(PatchSplit, CornerToCornerCutMakesTwoLinkedDisks) {
  PatchLayout layout = test::gridLayout(8, 8, 1.f, 1.f);
  ASSERT_EQ(layout.patches.size(), 1u);
  ASSERT_TRUE(splitPatchAtCorners(layout, 0, 0, 2));
  ASSERT_EQ(layout.patches.size(), 2u);
  expectValid(layout);
  const Patch &a = layout.patches[0], &b = layout.patches[1];
  EXPECT_EQ(a.sides.size(), 3u);
  EXPECT_EQ(b.sides.size(), 3u);
  // Every triangle in exactly one part, and each part a real share of the square.
  std::set<uint32_t> all(a.triangles.begin(), a.triangles.end());
  all.insert(b.triangles.begin(), b.triangles.end());
  EXPECT_EQ(all.size(), layout.triangles.size());
  EXPECT_EQ(a.triangles.size() + b.triangles.size(), layout.triangles.size());
  EXPECT_GE(std::min(a.triangles.size(), b.triangles.size()), layout.triangles.size() / 4);
  // The cut: last side of each, linked to the other, vertex runs reversed, from corner 0 to 2.
  const PatchSide &ca = a.sides.back(), &cb = b.sides.back();
  EXPECT_EQ(ca.neighbourPatch, 1);
  EXPECT_EQ(cb.neighbourPatch, 0);
  EXPECT_EQ(ca.neighbourSide, uint32_t(b.sides.size() - 1));
  EXPECT_EQ(cb.neighbourSide, uint32_t(a.sides.size() - 1));
  EXPECT_EQ(std::vector<uint32_t>(ca.vertices.rbegin(), ca.vertices.rend()), cb.vertices);
  EXPECT_EQ(cb.vertices.front(), 0u);           // grid corner (0, 0)
  EXPECT_EQ(cb.vertices.back(), 8u * 9u + 8u);  // grid corner (8, 8)
  for (uint32_t p = 0; p < 2; ++p) {
    const PatchParameterization pp = parameterizePatch(layout, p);
    EXPECT_EQ(pp.quality.flippedTriangles, 0u);
  }
}

TEST(PatchSplit, RefusedSplitsLeaveTheLayoutAlone) {
  PatchLayout layout = test::gridLayout(6, 6, 1.f, 1.f);
  const PatchLayout before = layout;
  EXPECT_FALSE(splitPatchAtCorners(layout, 0, 0, 1));  // adjacent corners: a 2-sided part
  EXPECT_FALSE(splitPatchAtCorners(layout, 0, 1, 1));
  EXPECT_FALSE(splitPatchAtCorners(layout, 3, 0, 2));  // no such patch
  EXPECT_FALSE(insertCorner(layout, 0, 0, 0));         // a corner already
  EXPECT_FALSE(insertCorner(layout, 0, 0, 6));         // past the side's inner vertices
  EXPECT_FALSE(insertCorner(layout, 0, 0, 3, 4));      // would give 5 sides, 4 allowed
  EXPECT_TRUE(sameLayout(layout, before));
}

TEST(PatchSplit, InsertedCornerSplitsBothSidesOfASeam) {
  // Two 4 x 4 patches side by side; the seam is patch 0's right side (x = 4).
  PatchLayout layout = test::gridLayout(8, 4, 2.f, 1.f, {4});
  ASSERT_EQ(layout.patches.size(), 2u);
  ASSERT_EQ(layout.patches[0].sides[1].neighbourPatch, 1);
  ASSERT_TRUE(insertCorner(layout, 0, 1, 2));
  expectValid(layout);
  EXPECT_EQ(layout.patches[0].sides.size(), 5u);
  EXPECT_EQ(layout.patches[1].sides.size(), 5u);
  // The new corner is grid vertex (4, 2) on both sides of the seam.
  const uint32_t corner = 2u * 9u + 4u;
  EXPECT_EQ(layout.patches[0].sides[2].vertices.front(), corner);
  bool found = false;
  for (const PatchSide& s : layout.patches[1].sides) found = found || s.vertices.front() == corner;
  EXPECT_TRUE(found);
  // And the layout can still be cut, through the new corner.
  ASSERT_TRUE(splitPatchAtCorners(layout, 0, 0, 2));
  expectValid(layout);
}

TEST(PatchSplit, NeckCutCrossesALongStripNearItsMiddle) {
  PatchLayout layout = test::gridLayout(24, 3, 8.f, 1.f);
  const size_t total = layout.triangles.size();
  ASSERT_TRUE(splitPatchAtNeck(layout, 0));
  expectValid(layout);
  ASSERT_EQ(layout.patches.size(), 2u);
  const size_t smaller = std::min(layout.patches[0].triangles.size(), layout.patches[1].triangles.size());
  EXPECT_GE(smaller, total / 4);
  // A cut across the strip: about its width (1), not along it.
  const PatchSide& cut = layout.patches[0].sides.back();
  double length = 0.0;
  for (size_t k = 0; k + 1 < cut.vertices.size(); ++k) {
    length += glm::length(layout.positions[cut.vertices[k + 1]] - layout.positions[cut.vertices[k]]);
  }
  EXPECT_LT(length, 2.0);
}

double runLength(const PatchLayout& layout, const std::vector<uint32_t>& run) {
  double l = 0.0;
  for (size_t k = 0; k + 1 < run.size(); ++k) {
    l += glm::length(layout.positions[run[k + 1]] - layout.positions[run[k]]);
  }
  return l;
}

// The smallest ratio, over the shared sides, of a side's length to the smaller mean side of its
// two patches.
double shortestSideRatio(const PatchLayout& layout) {
  double ratio = std::numeric_limits<double>::infinity();
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (const PatchSide& s : layout.patches[p].sides) {
      if (s.neighbourPatch < 0) continue;
      ratio = std::min(ratio, sideLength(layout, s) / std::min(meanSideLength(layout, p),
                                                               meanSideLength(layout, uint32_t(s.neighbourPatch))));
    }
  }
  return ratio;
}

TEST(ShortSides, LengthenedSideMovesItsCornerAndKeepsEverySideCount) {
  // Every shared side of a cube of 8 x 8 cells a face: its end corner moves 3 cells along the next
  // side; the third patch there gives the triangles between to the neighbour.
  const PatchLayout cube = test::cubeLayout(8);
  uint32_t tried = 0;
  for (uint32_t p = 0; p < cube.patches.size(); ++p) {
    for (uint32_t s = 0; s < 4; ++s) {
      PatchLayout layout = cube;
      const PatchSide side = layout.patches[p].sides[s];
      const uint32_t q = uint32_t(side.neighbourPatch);
      const double before = sideLength(layout, side);
      ASSERT_TRUE(lengthenSide(layout, p, s, 3.0 / 8.0)) << "patch " << p << " side " << s;
      ++tried;
      expectValid(layout);
      EXPECT_NEAR(sideLength(layout, layout.patches[p].sides[s]), before + 3.0 / 8.0, 1e-5);
      EXPECT_EQ(layout.patches[p].triangles, cube.patches[p].triangles);  // A keeps its triangles
      EXPECT_GT(layout.patches[q].triangles.size(), cube.patches[q].triangles.size());
      size_t total = 0;
      for (uint32_t x = 0; x < layout.patches.size(); ++x) {
        EXPECT_EQ(layout.patches[x].sides.size(), 4u);
        total += layout.patches[x].triangles.size();
      }
      EXPECT_EQ(total, cube.triangles.size());
    }
  }
  EXPECT_EQ(tried, 24u);
}

TEST(ShortSides, ShortSidesAreLengthenedAndLongOnesLeftAlone) {
  PatchLayout layout = test::cubeLayout(16);
  // Nothing is short on the cube.
  PatchLayout same = layout;
  EXPECT_EQ(lengthenShortSides(same), 0u);
  EXPECT_EQ(same.patches[0].triangles, layout.patches[0].triangles);
  // Moving one corner four times along the same side leaves that side 1 cell long of 16.
  const uint32_t sn = 1;
  for (int k = 0; k < 4; ++k) ASSERT_TRUE(lengthenSide(layout, 0, 0, 1.0));
  expectValid(layout);
  EXPECT_NEAR(sideLength(layout, layout.patches[0].sides[sn]), 1.0 / 16.0, 1e-5);
  EXPECT_LT(shortestSideRatio(layout), 0.125);
  EXPECT_EQ(lengthenShortSides(layout), 1u);
  expectValid(layout);
  EXPECT_GE(shortestSideRatio(layout), 0.125);
}

TEST(LayoutRefine, StraightSidesStayAsTheyAre) {
  PatchLayout layout = test::gridLayout(8, 4, 2.f, 1.f, {4});
  const PatchLayout before = layout;
  EXPECT_EQ(straightenSides(layout), 0u);
  EXPECT_FALSE(straightenSide(layout, 0, 0));  // open side
  EXPECT_TRUE(sameLayout(layout, before));
}

TEST(LayoutRefine, StraightenedScanSidesAreShorterAndTheLayoutStaysValid) {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = 64;
  PatchLayout layout = buildPatchLayout(mesh, copt);
  const PatchLayout before = layout;
  const uint32_t changed = straightenSides(layout);
  EXPECT_GT(changed, 0u);
  expectValid(layout);
  ASSERT_EQ(layout.patches.size(), before.patches.size());
  size_t triangles = 0, shorter = 0;
  for (size_t p = 0; p < layout.patches.size(); ++p) {
    triangles += layout.patches[p].triangles.size();
    ASSERT_EQ(layout.patches[p].sides.size(), before.patches[p].sides.size());
    for (size_t s = 0; s < layout.patches[p].sides.size(); ++s) {
      const PatchSide &now = layout.patches[p].sides[s], &old = before.patches[p].sides[s];
      // Same corners and links; never longer.
      EXPECT_EQ(now.vertices.front(), old.vertices.front());
      EXPECT_EQ(now.vertices.back(), old.vertices.back());
      EXPECT_EQ(now.neighbourPatch, old.neighbourPatch);
      const double ln = runLength(layout, now.vertices), lo = runLength(layout, old.vertices);
      EXPECT_LE(ln, lo * (1 + 1e-12));
      shorter += ln < lo;
    }
  }
  EXPECT_EQ(triangles, layout.triangles.size());
  // Both copies of every changed side (a side may change in both rounds).
  EXPECT_GE(shorter, changed);
  EXPECT_EQ(shorter % 2, 0u);
  // Straighter sides parameterize better: the mean image stretch does not rise.
  ResampleOptions ro;
  ro.chartSize = 17;
  PatchLayout raw = before;
  EXPECT_LE(resampleLayout(layout, ro).image.stretchL2, resampleLayout(raw, ro).image.stretchL2);
}

// The straightening's search (shortestCutWithin on the triangles of the ellipse where a path
// shorter than the bound can run) finds the path of the search through the whole of both
// patches wherever that one is shorter than the bound, and nothing shorter where it is not.
TEST(LayoutRefine, BoundedSearchInTheEllipseFindsTheWholeSearchsPath) {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = 64;
  const PatchLayout layout = buildPatchLayout(mesh, copt);
  auto pathTo = [](const Paths& paths, uint32_t a, uint32_t b) {
    std::vector<uint32_t> path{b};
    while (path.back() != a) path.push_back(paths.prev.at(path.back()));
    return path;
  };
  uint32_t shorter = 0, straight = 0, smaller = 0;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (uint32_t s = 0; s < layout.patches[p].sides.size(); ++s) {
      const PatchSide& side = layout.patches[p].sides[s];
      if (side.neighbourPatch < 0 || uint32_t(side.neighbourPatch) < p) continue;
      const Patch& q = layout.patches[uint32_t(side.neighbourPatch)];
      Patch u;
      u.triangles = layout.patches[p].triangles;
      u.triangles.insert(u.triangles.end(), q.triangles.begin(), q.triangles.end());
      for (uint32_t k = 0; k < layout.patches[p].sides.size(); ++k) {
        if (k != s) u.sides.push_back(layout.patches[p].sides[k]);
      }
      for (uint32_t k = 0; k < q.sides.size(); ++k) {
        if (k != side.neighbourSide) u.sides.push_back(q.sides[k]);
      }
      const uint32_t a = side.vertices.front(), b = side.vertices.back();
      const Paths whole = shortestCuts(layout, patchGraph(layout, u), a, b);
      ASSERT_TRUE(whole.dist.contains(b));
      const double shortest = whole.dist.at(b), length = runLength(layout, side.vertices);
      // Bounds above the side's length (the straightening's), and just below the shortest path.
      for (const double bound : {length * (1.0 + 1e-5), shortest * 0.999}) {
        Patch near;
        near.sides = u.sides;
        near.triangles = trianglesWithin(layout, u.triangles, a, b, bound);
        const Paths within = shortestCutWithin(layout, patchGraph(layout, near), a, b, bound);
        if (shortest < bound) {
          ASSERT_TRUE(within.dist.contains(b)) << "patch " << p << " side " << s;
          EXPECT_EQ(within.dist.at(b), shortest);
          EXPECT_EQ(pathTo(within, a, b), pathTo(whole, a, b)) << "patch " << p << " side " << s;
          shorter += shortest < length * (1.0 - 1e-9);
          straight += !(shortest < length * (1.0 - 1e-9));
        } else {
          EXPECT_FALSE(within.dist.contains(b) && within.dist.at(b) < bound);
          ++smaller;
        }
        EXPECT_LE(near.triangles.size(), u.triangles.size());
      }
    }
  }
  std::printf("  bunny, 64 patches: %u sides with a shorter path, %u straight, %u bounds below the path\n", shorter,
              straight, smaller);
  EXPECT_GT(shorter, 0u);
  EXPECT_GT(smaller, 0u);
}

// With keepHalves, a straightening never leaves either patch less than half its triangles; on the
// bunny some straightenings without it do (a side straightened across a patch's bulge).
TEST(LayoutRefine, KeepHalvesStraightensNoPatchToASliver) {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = 48;
  const PatchLayout layout = buildPatchLayout(mesh, copt);
  uint32_t shrunk = 0, kept = 0, refused = 0;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (uint32_t s = 0; s < layout.patches[p].sides.size(); ++s) {
      const int32_t q = layout.patches[p].sides[s].neighbourPatch;
      if (q < 0 || uint32_t(q) < p) continue;  // each shared side once
      const size_t np = layout.patches[p].triangles.size(), nq = layout.patches[uint32_t(q)].triangles.size();
      PatchLayout free = layout, halves = layout;
      const bool freeDone = straightenSide(free, p, s);
      const bool shrinks = freeDone && (2 * free.patches[p].triangles.size() < np ||
                                        2 * free.patches[uint32_t(q)].triangles.size() < nq);
      shrunk += shrinks;
      if (straightenSide(halves, p, s, true)) {
        ++kept;
        EXPECT_GE(2 * halves.patches[p].triangles.size(), np) << "patch " << p << " side " << s;
        EXPECT_GE(2 * halves.patches[uint32_t(q)].triangles.size(), nq) << "patch " << q;
        EXPECT_FALSE(shrinks);
        expectValid(halves);
      } else {
        refused += freeDone;
      }
    }
  }
  std::printf(
      "  bunny, 48 patches: %u sides straightened with keepHalves, %u refused, %u would shrink a patch below half\n",
      kept, refused, shrunk);
  EXPECT_GT(kept, 0u);
  EXPECT_GT(shrunk, 0u);
  EXPECT_EQ(refused, shrunk);
}

TEST(PatchSplit, FlipRepairOnARealScanNeverMakesThingsWorse) {
  PatchLayout layout = chartedBunny();
  const size_t patchesBefore = layout.patches.size();
  ResampleOptions ro;
  ro.chartSize = 33;
  ChartRepairStats st;
  const GeometryImageSet set = resampleAndRepair(layout, ro, {3}, &st);
  std::printf("  bunny at 33^2: %u flipped texels before repair, %u after (%u patches split, %u rounds)\n",
              st.flippedTexelsFirst, set.image.flippedTexels, st.patchesSplit, st.rounds);
  EXPECT_LE(set.image.flippedTexels, st.flippedTexelsFirst);
  expectValid(layout);
  EXPECT_EQ(layout.patches.size(), patchesBefore + st.patchesSplit);
  // The returned charts are those of the returned layout.
  EXPECT_EQ(set.charts.size(), quadChartOffsets(layout).back() + layout.patches.back().sides.size());
  // Only changed patches were parameterized again, yet the charts are bit for bit those of a
  // full resampling of the final layout.
  expectSameCharts(set, resampleLayout(layout, ro));
  // Where flipped texels remain, the charts say where (layout triangles), and only there.
  for (const GeometryImage& g : set.charts) {
    EXPECT_EQ(g.foldTriangles.empty(), g.quality.flippedTexels == 0);
    for (uint32_t t : g.foldTriangles) {
      const auto& tris = layout.patches[g.patch].triangles;
      EXPECT_NE(std::find(tris.begin(), tris.end(), t), tris.end());
    }
  }
}

TEST(PatchSplit, FlipRepairStopsWhenToldMemoryIsShort) {
  PatchLayout layout = chartedBunny();
  ResampleOptions ro;
  ro.chartSize = 33;
  const PatchLayout before = layout;
  GeometryImageSet first = resampleLayout(layout, ro);
  ASSERT_GT(first.image.flippedTexels, 0u);
  const GeometryImageSet reference = resampleLayout(layout, ro);
  // Refused from the start: nothing is cut, the charts are those it was given.
  ChartRepairStats st;
  const GeometryImageSet set = repairCharts(layout, std::move(first), ro, {2}, &st, [] { return false; });
  EXPECT_TRUE(st.stoppedForMemory);
  EXPECT_EQ(st.patchesSplit, 0u);
  EXPECT_TRUE(sameLayout(layout, before));
  expectSameCharts(set, reference);
  // Allowed a few batches: it stops part way with a valid layout whose charts match it.
  PatchLayout partial = before;
  ChartRepairStats st2;
  uint32_t left = 1;
  const GeometryImageSet some =
      repairCharts(partial, resampleLayout(partial, ro), ro, {2}, &st2, [&] { return left-- > 0; });
  EXPECT_TRUE(st2.stoppedForMemory);
  expectValid(partial);
  expectSameCharts(some, resampleLayout(partial, ro));
}

// Charts whose samples go to a spill file as they are measured: the repair (which moves charts and
// reuses unchanged patches' charts) and the writer (which reads them back) give the same charts
// and the same chart files, byte for byte, as with every sample held in memory.
TEST(PatchSplit, FlipRepairWithSpilledChartsGivesTheSameAtlas) {
  const PatchLayout charted = chartedBunny();
  test::TempDir tmp("gimlod-spill");
  ResampleOptions ro;
  ro.chartSize = 33;
  PatchLayout held = charted, spilled = charted;
  ChartRepairStats stHeld, stSpilled;
  const GeometryImageSet setHeld = resampleAndRepair(held, ro, {2}, &stHeld);
  ChartSpill spill(tmp.path() / "samples.tmp", false);
  ro.spill = &spill;
  GeometryImageSet setSpilled = resampleAndRepair(spilled, ro, {2}, &stSpilled);
  EXPECT_GT(stHeld.patchesSplit, 0u) << "the bunny at 33^2 should need splits";
  EXPECT_EQ(stHeld.patchesSplit, stSpilled.patchesSplit);
  EXPECT_TRUE(sameLayout(held, spilled));
  for (const GeometryImage& g : setSpilled.charts) {
    EXPECT_GE(g.spilled, 0);
    EXPECT_TRUE(g.positions.empty());
  }
  EXPECT_GE(spill.bytes(), setSpilled.charts.size() * 33 * 33 * 16);
  // Written, each chart from its finest level (within a bound some charts meet coarser and some do
  // not): the same levels and the same files.
  double largest = 0.0;
  for (const GeometryImage& g : setHeld.charts) largest = std::max(largest, g.quality.sampleError);
  const ChartCoarsening coarsen{2.0 * largest, 2};
  const std::vector<uint32_t> finestHeld = chartFinestLevels(setHeld, nullptr, coarsen);
  EXPECT_EQ(chartFinestLevels(setSpilled, &spill, coarsen), finestHeld);
  EXPECT_THROW(chartFinestLevels(setSpilled, nullptr, coarsen), std::invalid_argument);
  EXPECT_TRUE(std::any_of(finestHeld.begin(), finestHeld.end(), [](uint32_t f) { return f > 0; }));
  AtlasManifest mHeld, mSpilled;
  writeGeometryCharts(setHeld, tmp.path() / "held", 8, mHeld, nullptr, {}, finestHeld);
  writeGeometryCharts(setSpilled, tmp.path() / "spilled", 8, mSpilled, &spill, {}, finestHeld);
  EXPECT_THROW(writeGeometryCharts(setSpilled, tmp.path() / "nospill", 8, mSpilled), std::invalid_argument);
  ASSERT_EQ(mHeld.charts.size(), mSpilled.charts.size());
  auto bytes = [](const std::filesystem::path& f) {
    std::ifstream in(f, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
  };
  for (size_t c = 0; c < mHeld.charts.size(); ++c)
    EXPECT_EQ(bytes(tmp.path() / "held" / mHeld.charts[c].file),
              bytes(tmp.path() / "spilled" / mSpilled.charts[c].file))
        << "chart " << c;
  // Read back: the same samples.
  for (GeometryImage& g : setSpilled.charts) spill.get(g);
  expectSameCharts(setHeld, setSpilled);
}

// The work budget: counted in layout triangles parameterized again, checked before every round
// and batch, so the repair stops after the batch that reaches it, with a valid layout and its
// charts; a budget of 0 repairs nothing.
TEST(PatchSplit, FlipRepairStopsAtItsWorkBudget) {
  const PatchLayout charted = chartedBunny();
  ResampleOptions ro;
  ro.chartSize = 33;
  ro.unfold = false;  // the folds as mapped: enough of them for several rounds of cuts
  PatchLayout full = charted;
  ChartRepairStats stFull;
  resampleAndRepair(full, ro, {2}, &stFull);
  const uint64_t work = stFull.trianglesWholeRounds + stFull.trianglesTrials;
  ASSERT_GT(stFull.trianglesWholeRounds, 0u);
  EXPECT_FALSE(stFull.stoppedForWork);
  // Nothing allowed: the charts it was given.
  PatchLayout none = charted;
  ChartRepairStats stNone;
  const GeometryImageSet untouched = repairCharts(none, resampleLayout(none, ro), ro, {2, 0.0, 0}, &stNone);
  EXPECT_TRUE(stNone.stoppedForWork);
  EXPECT_EQ(stNone.patchesSplit, 0u);
  EXPECT_TRUE(sameLayout(none, charted));
  EXPECT_EQ(untouched.image.flippedTexels, stNone.flippedTexelsFirst);
  // A third of what the whole repair takes: it stops part way, past the budget by at most the
  // batch that crossed it, and what it returns is the resampling of what it leaves.
  PatchLayout part = charted;
  ChartRepairStats stPart;
  const GeometryImageSet some = repairCharts(part, resampleLayout(part, ro), ro, {2, 0.0, work / 3}, &stPart);
  EXPECT_TRUE(stPart.stoppedForWork);
  const uint64_t used = stPart.trianglesWholeRounds + stPart.trianglesTrials;
  EXPECT_GE(used, work / 3);
  EXPECT_LT(used, work);
  expectValid(part);
  expectSameCharts(some, resampleLayout(part, ro));
}

TEST(PatchSplit, FlipRepairDoesNotDependOnTheThreadCount) {
  // Batches of folds are searched and judged in parallel; the result must be that of one thread.
  const PatchLayout charted = chartedBunny();
  ResampleOptions ro;
  ro.chartSize = 33;
  PatchLayout one = charted, many = charted;
  ChartRepairStats stOne, stMany;
  GeometryImageSet setOne;
  {
    tbb::global_control single(tbb::global_control::max_allowed_parallelism, 1);
    straightenSides(one, 2);
    setOne = resampleAndRepair(one, ro, {2}, &stOne);
  }
  straightenSides(many, 2);
  const GeometryImageSet setMany = resampleAndRepair(many, ro, {2}, &stMany);
  EXPECT_GT(stOne.patchesSplit, 0u) << "the bunny at 33^2 should need splits";
  EXPECT_TRUE(sameLayout(one, many));
  EXPECT_EQ(stOne.patchesSplit, stMany.patchesSplit);
  expectSameCharts(setOne, setMany);
}

// A patch's parameterization, kept in a ParamCache, serves its resampling at another size: the
// charts are bit for bit a fresh resampling's, and a patch that changed is parameterized anew.
TEST(ResampleReuse, CachedParameterizationsGiveTheSameChartsAtEverySize) {
  PatchLayout layout = test::cubeLayout(8, true);
  ResampleOptions ro;
  ro.chartSize = 17;
  ParamCache cache(uint64_t(1) << 30);
  ResampleReuse reuse;
  reuse.params = &cache;
  const GeometryImageSet first = resampleLayout(layout, ro, reuse);
  expectSameCharts(first, resampleLayout(layout, ro));
  EXPECT_EQ(cache.hits(), 0u);
  ASSERT_GT(cache.bytes(), 0u);
  ro.chartSize = 33;
  const GeometryImageSet doubled = resampleLayout(layout, ro, reuse);
  EXPECT_EQ(cache.hits(), layout.patches.size());
  expectSameCharts(doubled, resampleLayout(layout, ro));

  // A cut changes some patches: only the unchanged ones are taken from the cache.
  const std::vector<Patch> before = layout.patches;
  ASSERT_TRUE(splitPatchAtCorners(layout, 0, 0, 2));
  uint64_t alike = 0;
  for (uint32_t p = 0; p < before.size(); ++p) alike += patchParamAlike(before[p], layout.patches[p]);
  ASSERT_LT(alike, before.size());
  const uint64_t hitsBefore = cache.hits();
  expectSameCharts(resampleLayout(layout, ro, reuse), resampleLayout(layout, ro));
  EXPECT_EQ(cache.hits() - hitsBefore, alike);

  // A side that opens changes the parameterization (its vertices slide), so the patch is not alike.
  Patch opened = layout.patches[1];
  opened.sides[0].neighbourPatch = -1;
  EXPECT_FALSE(patchParamAlike(opened, layout.patches[1]));
  EXPECT_EQ(cache.find(layout, opened, 1), nullptr);
  const auto kept = cache.find(layout, layout.patches[1], 1);
  ASSERT_NE(kept, nullptr);
  // Made again from the layout, its local mesh is the parameterization's own.
  const PatchParameterization fresh = parameterizePatch(layout, 1);
  EXPECT_EQ(kept->vertices, fresh.vertices);
  EXPECT_EQ(kept->triangles, fresh.triangles);
  EXPECT_EQ(kept->uv, fresh.uv);

  // Past its bytes, the cache keeps nothing more, and the charts are the same.
  ParamCache tiny(1);
  ResampleReuse small;
  small.params = &tiny;
  expectSameCharts(resampleLayout(layout, ro, small), resampleLayout(layout, ro));
  EXPECT_EQ(tiny.bytes(), 0u);
  EXPECT_EQ(tiny.find(layout, layout.patches[1], 1), nullptr);
}

// The cache keeps several versions of a patch (a trial cut gives a neighbour a corner, and the
// trial may be undone), and past its bytes drops the least recently used, not the newest.
TEST(ResampleReuse, TheCacheKeepsVersionsAndDropsTheLeastRecentlyUsed) {
  PatchLayout layout = test::cubeLayout(8, true);
  const Patch plain = layout.patches[0];
  auto pp = [&](uint32_t p) { return std::make_shared<const PatchParameterization>(parameterizePatch(layout, p)); };
  const auto plainMap = pp(0);
  ASSERT_TRUE(insertCorner(layout, 0, 0, 4));
  const Patch cornered = layout.patches[0];
  ASSERT_FALSE(patchParamAlike(plain, cornered));
  const auto corneredMap = pp(0), otherMap = pp(1);
  // Room for two of the three.
  ParamCache measure(uint64_t(1) << 30);
  measure.put(plain, 0, plainMap);
  const uint64_t one = measure.bytes();
  measure.put(layout.patches[1], 1, otherMap);
  const uint64_t bigger = std::max(one, measure.bytes() - one);
  ParamCache cache(one + bigger + bigger / 2);
  cache.put(plain, 0, plainMap);
  cache.put(cornered, 0, corneredMap);
  // What a hit gives: the map put, with the local mesh made again from the layout.
  auto found = [&](const Patch& patch, uint32_t p, const std::shared_ptr<const PatchParameterization>& map) {
    const auto got = cache.find(layout, patch, p);
    return got && got->uv == map->uv && got->triangles == map->triangles && got->vertices == map->vertices;
  };
  EXPECT_TRUE(found(plain, 0, plainMap));
  EXPECT_TRUE(found(cornered, 0, corneredMap));
  EXPECT_TRUE(found(plain, 0, plainMap));  // now the cornered version is the least recent
  cache.put(layout.patches[1], 1, otherMap);
  EXPECT_EQ(cache.find(layout, cornered, 0), nullptr);
  EXPECT_TRUE(found(plain, 0, plainMap));
  EXPECT_TRUE(found(layout.patches[1], 1, otherMap));
  EXPECT_LE(cache.bytes(), one + bigger + bigger / 2);
  // Put again for a patch alike, a version replaces the one it had.
  const uint64_t held = cache.bytes();
  cache.put(plain, 0, plainMap);
  EXPECT_EQ(cache.bytes(), held);
  EXPECT_EQ(cache.hits(), 5u);
}

// An entry knows its patch's triangles by their count and digest, not by a copy of the list: a
// list of the same length in another order, or with one triangle swapped for another, is another
// patch; the entry's bytes are the coordinates, the boundary and the sides.
TEST(ResampleReuse, TheCacheKnowsAPatchByItsTrianglesDigest) {
  const PatchLayout layout = test::cubeLayout(32, true);
  const Patch& patch = layout.patches[0];
  const auto map = std::make_shared<const PatchParameterization>(parameterizePatch(layout, 0));
  ParamCache cache(uint64_t(1) << 30);
  cache.put(patch, 0, map);
  uint64_t sides = 0;
  for (const PatchSide& s : patch.sides) sides += sizeof(PatchSide) + s.vertices.size() * sizeof(uint32_t);
  const uint64_t coordinates = map->uv.size() * sizeof(glm::dvec2) + map->boundary.size() * sizeof(uint32_t);
  ASSERT_GT(patch.triangles.size() * sizeof(uint32_t), 4096u);
  EXPECT_GE(cache.bytes(), coordinates + sides);
  EXPECT_LT(cache.bytes(), coordinates + sides + 1024);

  Patch reordered = patch;
  std::swap(reordered.triangles[3], reordered.triangles[7]);
  Patch replaced = patch;
  replaced.triangles[5] = layout.patches[1].triangles[0];
  for (const Patch* other : {&reordered, &replaced}) {
    EXPECT_EQ(other->triangles.size(), patch.triangles.size());
    EXPECT_NE(patchDigest(*other), patchDigest(patch));
    EXPECT_FALSE(patchParamAlike(*other, patch));
    EXPECT_EQ(cache.find(layout, *other, 0), nullptr);
  }
  const Patch copy = patch;
  EXPECT_EQ(patchDigest(copy), patchDigest(patch));
  const auto hit = cache.find(layout, copy, 0);
  ASSERT_NE(hit, nullptr);
  EXPECT_EQ(hit->uv, map->uv);
  EXPECT_EQ(cache.hits(), 1u);
}

// The repair takes its parameterizations from the cache and puts them there: the patches a kept
// cut changed are not parameterized again by a later resampling, and the charts are bit for bit
// those of the repair without the cache.
TEST(PatchSplit, FlipRepairSharesTheParameterizationCache) {
  const PatchLayout charted = chartedBunny();
  ResampleOptions ro;
  ro.chartSize = 33;
  PatchLayout plain = charted, cached = charted;
  straightenSides(plain, 2);
  straightenSides(cached, 2);
  ChartRepairStats stPlain, stCached;
  const GeometryImageSet setPlain = repairCharts(plain, resampleLayout(plain, ro), ro, {2}, &stPlain);
  ASSERT_GT(stPlain.patchesSplit, 0u) << "the bunny at 33^2 should need splits";
  ParamCache cache(uint64_t(1) << 30);
  ResampleReuse reuse;
  reuse.params = &cache;
  ChartRepairOptions repair{2};
  repair.params = &cache;
  const GeometryImageSet setCached = repairCharts(cached, resampleLayout(cached, ro, reuse), ro, repair, &stCached);
  EXPECT_TRUE(sameLayout(plain, cached));
  EXPECT_EQ(stPlain.patchesSplit, stCached.patchesSplit);
  // The same work is counted, so the repair stops where it did.
  EXPECT_EQ(stPlain.trianglesTrials, stCached.trianglesTrials);
  EXPECT_EQ(stPlain.trianglesWholeRounds, stCached.trianglesWholeRounds);
  expectSameCharts(setPlain, setCached);
  // Every patch of the repaired layout is in the cache: a resampling parameterizes none again.
  const uint64_t hitsBefore = cache.hits();
  ro.chartSize = 65;
  expectSameCharts(resampleLayout(cached, ro, reuse), resampleLayout(cached, ro));
  EXPECT_EQ(cache.hits() - hitsBefore, cached.patches.size());
}

// The gate holds a parameterization back while those running and it would need more than its
// budget, and lets one run alone whatever it needs; the charts are those of an ungated resampling.
TEST(ParamGate, HoldsWithinTheBudgetAndOneAlwaysRuns) {
  for (const uint64_t budget : {uint64_t(0), uint64_t(100), uint64_t(250)}) {
    SCOPED_TRACE(testing::Message() << "budget " << budget);
    ParamGate gate(budget);
    std::mutex m;
    uint64_t held = 0, mostHeld = 0, running = 0, mostRunning = 0;
    bool overBudget = false;
    const std::vector<uint64_t> needs{60, 60, 60, 60, 120, 300, 40, 40, 90, 10, 10, 10};
    std::vector<std::thread> threads;
    for (const uint64_t need : needs) {
      threads.emplace_back([&, need] {
        const ParamGate::Hold hold(gate, need);
        {
          const std::lock_guard<std::mutex> lock(m);
          held += need;
          ++running;
          mostHeld = std::max(mostHeld, held);
          mostRunning = std::max(mostRunning, running);
          overBudget = overBudget || (running > 1 && held > budget);
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        const std::lock_guard<std::mutex> lock(m);
        held -= need;
        --running;
      });
    }
    for (std::thread& t : threads) t.join();
    EXPECT_FALSE(overBudget) << "most held " << mostHeld;
    EXPECT_EQ(held, 0u);
    if (budget == 0) {
      EXPECT_EQ(mostRunning, 1u);
    }
    if (budget == 250) {
      EXPECT_GT(mostRunning, 1u);
    }
    EXPECT_GT(gate.waits(), 0u);
  }

  // What resampleLayout asks before it picks a patch: whether a hold would run now.
  ParamGate hint(100);
  EXPECT_TRUE(hint.fitsNow(500));  // nothing runs: one always may
  {
    const ParamGate::Hold hold(hint, 70);
    EXPECT_TRUE(hint.fitsNow(30));
    EXPECT_FALSE(hint.fitsNow(31));
  }
  EXPECT_TRUE(hint.fitsNow(100));

  // Patches taken largest first, and under a gate the largest that fits: the charts are an
  // ungated resampling's, at any thread count and gate.
  PatchLayout layout = test::cubeLayout(8, true);
  ResampleOptions ro;
  ro.chartSize = 17;
  ro.threads = 4;
  const GeometryImageSet ungated = resampleLayout(layout, ro);
  for (const uint64_t budget : {uint64_t(0), uint64_t(1) << 18}) {
    for (const uint32_t threads : {1u, 4u}) {
      ParamGate gate(budget);
      ro.gate = &gate;
      ro.threads = threads;
      expectSameCharts(resampleLayout(layout, ro), ungated);
    }
  }
}

TEST(ResampleReuse, ReusedPatchesAreBitIdenticalAndOnlyChangedOnesAreRedone) {
  PatchLayout layout = test::cubeLayout(8, true);
  ResampleOptions ro;
  ro.chartSize = 17;
  GeometryImageSet earlier = resampleLayout(layout, ro);
  const std::vector<Patch> before = layout.patches;
  ASSERT_TRUE(splitPatchAtCorners(layout, 0, 0, 2));
  const GeometryImageSet full = resampleLayout(layout, ro);
  std::vector<uint32_t> changed;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    if (p >= before.size() || !patchSamplesAlike(before[p], layout.patches[p], p)) changed.push_back(p);
  }
  // The split patch, its new part, and the neighbours across the sides that moved to the new
  // part (the side's owner, by patch index, changes); not the rest.
  ASSERT_GE(changed.size(), 2u);
  EXPECT_EQ(changed.front(), 0u);
  EXPECT_EQ(changed.back(), uint32_t(before.size()));
  ASSERT_LT(changed.size(), layout.patches.size());
  uint32_t kept = 0;
  while (std::find(changed.begin(), changed.end(), kept) != changed.end()) ++kept;
  ResampleReuse reuse;
  reuse.earlier.push_back({&before, &earlier});
  const GeometryImageSet incremental = resampleLayout(layout, ro, reuse);
  expectSameCharts(incremental, full);
  // The unchanged patches' charts were taken (moved out), the split one's were not.
  EXPECT_FALSE(earlier.charts[earlier.patches[0].firstChart].positions.empty());
  EXPECT_TRUE(earlier.charts[earlier.patches[kept].firstChart].positions.empty());
  // Only the selected patches: their charts and figures as in the full resampling, none else.
  std::vector<uint8_t> only(layout.patches.size(), 0);
  only[0] = 1;
  ResampleReuse selected;
  selected.only = &only;
  const GeometryImageSet part = resampleLayout(layout, ro, selected);
  ASSERT_EQ(part.charts.size(), full.charts.size());
  for (size_t c = 0; c < part.charts.size(); ++c) {
    EXPECT_EQ(part.charts[c].positions.empty(), part.charts[c].patch != 0);
    if (part.charts[c].patch == 0) {
      EXPECT_EQ(part.charts[c].positions, full.charts[c].positions);
    }
  }
  // A selection of the wrong size is refused.
  std::vector<uint8_t> wrong(1, 1);
  selected.only = &wrong;
  EXPECT_THROW(resampleLayout(layout, ro, selected), std::invalid_argument);
}

// A square fanned from its centre whose bottom side 0-5-7-6-1 has an ear (5, 7, 6) hanging
// below the chord 5-6; with `below`, a second patch fills the band under the bottom side and
// shares it, else the bottom side is open.
PatchLayout earLayout(bool below) {
  PatchLayout l;
  l.positions = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}, {1, 1, 0}, {0.7f, 0, 0}, {1.3f, 0, 0}, {1, -0.2f, 0}};
  l.triangles = {{0, 5, 4}, {5, 6, 4}, {6, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}, {5, 7, 6}};
  Patch a;
  a.triangles = {0, 1, 2, 3, 4, 5, 6};
  a.sides = {{{0, 5, 7, 6, 1}}, {{1, 2}}, {{2, 3}}, {{3, 0}}};
  l.patches.push_back(a);
  if (below) {
    l.positions.push_back({0, -1, 0});  // 8
    l.positions.push_back({2, -1, 0});  // 9
    l.triangles.insert(l.triangles.end(), {{8, 9, 7}, {8, 7, 5}, {8, 5, 0}, {9, 6, 7}, {9, 1, 6}});
    Patch b;
    b.triangles = {7, 8, 9, 10, 11};
    b.sides = {{{8, 9}}, {{9, 1}}, {{1, 6, 7, 5, 0}}, {{0, 8}}};
    b.sides[2].neighbourPatch = 0;
    b.sides[2].neighbourSide = 0;
    l.patches[0].sides[0].neighbourPatch = 1;
    l.patches[0].sides[0].neighbourSide = 2;
    l.patches.push_back(b);
  }
  return l;
}

TEST(SideEars, AnEarOnASharedSideMovesToTheNeighbour) {
  PatchLayout layout = earLayout(true);
  expectValid(layout);
  ResampleOptions ro;
  ro.chartSize = 17;
  EXPECT_GT(resampleLayout(layout, ro).param.degenerateTriangles, 0u) << "the ear has no area in the polygon";
  EXPECT_EQ(moveSideEars(layout), 1u);
  expectValid(layout);
  EXPECT_EQ(layout.patches[0].triangles.size(), 6u);
  EXPECT_EQ(layout.patches[1].triangles.size(), 6u);
  EXPECT_NE(std::find(layout.patches[1].triangles.begin(), layout.patches[1].triangles.end(), 6u),
            layout.patches[1].triangles.end());
  EXPECT_EQ(layout.patches[0].sides[0].vertices, (std::vector<uint32_t>{0, 5, 6, 1}));
  EXPECT_EQ(layout.patches[1].sides[2].vertices, (std::vector<uint32_t>{1, 6, 5, 0}));
  EXPECT_EQ(resampleLayout(layout, ro).param.degenerateTriangles, 0u);
  EXPECT_EQ(moveSideEars(layout), 0u) << "nothing left to mend";
}

TEST(SideEars, AnEarOnAnOpenSideGetsACorner) {
  PatchLayout layout = earLayout(false);
  expectValid(layout);
  ResampleOptions ro;
  ro.chartSize = 17;
  EXPECT_GT(resampleLayout(layout, ro).param.degenerateTriangles, 0u);
  EXPECT_EQ(moveSideEars(layout), 1u);
  expectValid(layout);
  ASSERT_EQ(layout.patches.size(), 1u);
  ASSERT_EQ(layout.patches[0].sides.size(), 5u);
  EXPECT_EQ(layout.patches[0].sides[0].vertices, (std::vector<uint32_t>{0, 5, 7}));
  EXPECT_EQ(layout.patches[0].sides[1].vertices, (std::vector<uint32_t>{7, 6, 1}));
  EXPECT_EQ(resampleLayout(layout, ro).param.degenerateTriangles, 0u);
}

// An ear left on an open side (moveSideEars would have made its middle vertex a corner) is split
// at its inner edge: the middle vertex, lifted out of the plane here, then has area round it in the
// polygon, and the chart passes through it instead of a triangle's height away. Undone, the layout
// is as it was.
TEST(SideEars, AnEarLeftOnAnOpenSideIsSplitAtItsInnerEdge) {
  PatchLayout shared = earLayout(true);
  EarSplits none;
  EXPECT_EQ(splitOpenSideEars(shared, &none), 0u) << "an ear on a shared side is moveSideEars' to mend";
  PatchLayout layout = earLayout(false);
  layout.positions[7].z = 0.3f;
  const PatchLayout original = layout;
  auto area = [](const PatchLayout& l) {
    double a = 0.0;
    for (const auto& t : l.triangles)
      a += 0.5 * glm::length(glm::cross(glm::dvec3(l.positions[t[1]] - l.positions[t[0]]),
                                        glm::dvec3(l.positions[t[2]] - l.positions[t[0]])));
    return a;
  };
  const double areaBefore = area(layout);
  ResampleOptions ro;
  ro.chartSize = 17;
  const GeometryImageSet before = resampleLayout(layout, ro);
  EXPECT_GT(before.param.degenerateTriangles, 0u) << "the ear has no area in the polygon";
  EXPECT_GT(before.image.sampleError, 0.1) << "the chart misses the ear's middle vertex";

  EarSplits record;
  EXPECT_EQ(splitOpenSideEars(layout, &record), 1u);
  expectValid(layout);
  ASSERT_EQ(layout.positions.size(), 9u);
  EXPECT_EQ(layout.positions[8], glm::vec3(1.0f, 0.0f, 0.0f)) << "the midpoint of the inner edge 5-6";
  EXPECT_EQ(layout.triangles.size(), 9u);
  EXPECT_EQ(layout.patches[0].triangles.size(), 9u);
  EXPECT_EQ(layout.patches[0].sides[0].vertices, (std::vector<uint32_t>{0, 5, 7, 6, 1})) << "the sides stay";
  uint32_t fan = 0;
  for (const auto& t : layout.triangles) fan += uint32_t(std::count(t.begin(), t.end(), 7u));
  EXPECT_EQ(fan, 2u);
  EXPECT_NEAR(area(layout), areaBefore, 1e-6 * areaBefore) << "the surface is the same";
  const GeometryImageSet after = resampleLayout(layout, ro);
  EXPECT_EQ(after.param.degenerateTriangles, 0u);
  EXPECT_LT(after.image.sampleError, 0.1 * before.image.sampleError);
  EarSplits again;
  EXPECT_EQ(splitOpenSideEars(layout, &again), 0u) << "nothing left to split";

  record.undo(layout);
  layout.patches = original.patches;
  EXPECT_EQ(layout.triangles, original.triangles);
  EXPECT_EQ(layout.positions, original.positions);
  expectValid(layout);
}

// A strip of rim triangles: the triangle across an ear's inner edge has its third vertex on the
// ear's side too, so the midpoint would lie on the side's line in the polygon. It is left.
TEST(SideEars, AnEarWhoseTriangleAcrossLiesOnTheSameSideIsLeft) {
  // One open 4-sided patch: side 0 runs 0 -> 4 -> 5 -> 6 -> 1; the ear 4 -> 5 -> 6 has 4 -> 6 -> 1
  // across its inner edge, every vertex on side 0.
  PatchLayout layout;
  layout.positions = {{0, 0, 0}, {4, 0, 0}, {4, 2, 0}, {0, 2, 0}, {1, 0, 0}, {2, -0.3f, 0}, {3, -0.2f, 0}};
  layout.triangles = {{4, 5, 6}, {4, 6, 1}, {0, 4, 3}, {4, 1, 2}, {4, 2, 3}};
  Patch p;
  p.triangles = {0, 1, 2, 3, 4};
  p.sides = {{{0, 4, 5, 6, 1}}, {{1, 2}}, {{2, 3}}, {{3, 0}}};
  layout.patches = {p};
  expectValid(layout);
  EarSplits record;
  EXPECT_EQ(splitOpenSideEars(layout, &record), 0u);
  EXPECT_EQ(layout.triangles.size(), 5u);
}

// A tube closed at one end by a cone (a sock), open at its rim, as one 3-sided patch: its
// mean-value map squeezes the tip exponentially in the tube's length. The cut from its deepest
// vertex (the tip) runs down both sides, into two halves that each reach the tip and the rim and
// map with a quarter of the whole's stretch or less.
TEST(PatchSplit, ASockIsCutFromItsTipDownBothSides) {
  constexpr double kPi = 3.14159265358979323846;
  const uint32_t segments = 24, rings = 160;
  const float radius = 0.03f, length = 2.0f;  // the antenna of mesh_family's thin_parts
  PatchLayout layout;
  for (uint32_t k = 0; k <= rings; ++k)
    for (uint32_t j = 0; j < segments; ++j) {
      const double a = 2.0 * kPi * j / segments;
      layout.positions.push_back(
          {radius * float(std::cos(a)), radius * float(std::sin(a)), length * float(k) / float(rings)});
    }
  const uint32_t tip = uint32_t(layout.positions.size());
  layout.positions.push_back({0.f, 0.f, length + radius});
  auto at = [&](uint32_t k, uint32_t j) { return k * segments + j % segments; };
  Patch sock;
  for (uint32_t k = 0; k < rings; ++k)
    for (uint32_t j = 0; j < segments; ++j) {  // outward normals, counter-clockwise
      sock.triangles.push_back(uint32_t(layout.triangles.size()));
      layout.triangles.push_back({at(k, j), at(k, j + 1), at(k + 1, j + 1)});
      sock.triangles.push_back(uint32_t(layout.triangles.size()));
      layout.triangles.push_back({at(k, j), at(k + 1, j + 1), at(k + 1, j)});
    }
  for (uint32_t j = 0; j < segments; ++j) {
    sock.triangles.push_back(uint32_t(layout.triangles.size()));
    layout.triangles.push_back({at(rings, j), at(rings, j + 1), tip});
  }
  // The rim, in the order its triangles run round it. Three open sides.
  std::vector<uint32_t> rim;
  for (uint32_t j = 0; j <= segments; ++j) rim.push_back(at(0, j));
  for (uint32_t s = 0; s < 3; ++s) {
    PatchSide side;
    side.vertices.assign(rim.begin() + s * segments / 3, rim.begin() + (s + 1) * segments / 3 + 1);
    sock.sides.push_back(side);
  }
  layout.patches.push_back(sock);
  expectValid(layout);
  EXPECT_EQ(deepestPatchVertex(layout, 0), tip);
  const PatchParameterization whole = parameterizePatch(layout, 0);
  // Past the L2 stretch of 16 the per-patch sizing takes a map for collapsed (quad_charts.cpp).
  EXPECT_TRUE(whole.quality.degenerateTriangles > 0 || whole.quality.stretchL2 > 16.0) << "the whole sock collapses";

  ASSERT_TRUE(splitPatchFromDeepest(layout, 0));
  expectValid(layout);
  ASSERT_EQ(layout.patches.size(), 2u);
  for (uint32_t p = 0; p < 2; ++p) {
    SCOPED_TRACE(p);
    float low = length, high = 0.f;
    for (const uint32_t t : layout.patches[p].triangles)
      for (const uint32_t v : layout.triangles[t])
        low = std::min(low, layout.positions[v].z), high = std::max(high, layout.positions[v].z);
    EXPECT_EQ(low, 0.f) << "reaches the rim";
    EXPECT_EQ(high, length + radius) << "reaches the tip";
    const PatchParameterization half = parameterizePatch(layout, p);
    std::printf("[sock] part %u: %zu triangles, L2 stretch %.3g, mean-value %.3g (the whole sock: %.3g, %.3g)\n", p,
                layout.patches[p].triangles.size(), half.quality.stretchL2, half.initial.stretchL2,
                whole.quality.stretchL2, whole.initial.stretchL2);
    EXPECT_GT(layout.patches[p].triangles.size(), 2 * segments * rings / 5) << "not a sliver";
    EXPECT_EQ(half.quality.degenerateTriangles, 0u);
    EXPECT_LT(half.quality.stretchL2, 0.25 * whole.quality.stretchL2);
  }
}

// An ear on an open side of a patch that has 8 sides already cannot take a corner: the patch is
// cut at its neck first, which appends a patch (and so may move every patch in memory), and the
// part with the ear then gets its corner. Built as a single patch so that the layout's patch
// vector is full when the cut appends (run under AddressSanitizer, a reference held across the
// cut is a use after free).
TEST(SideEars, AnEarOnAnOpenSideOfAnEightSidedPatchIsMendedAfterANeckCut) {
  PatchLayout layout = test::gridLayout(24, 3, 8.f, 1.f);
  ASSERT_EQ(layout.patches.size(), 1u);
  // An ear (a, m, b) hanging below the bottom grid edge a -> b at x = 12.
  const uint32_t a = 12, b = 13, m = uint32_t(layout.positions.size());
  layout.positions.push_back((layout.positions[a] + layout.positions[b]) * 0.5f + glm::vec3(0, -0.05f, 0));
  layout.patches[0].triangles.push_back(uint32_t(layout.triangles.size()));
  layout.triangles.push_back({a, m, b});
  std::vector<uint32_t>& bottom = layout.patches[0].sides[0].vertices;
  bottom.insert(std::find(bottom.begin(), bottom.end(), b), m);
  // Four more corners on the bottom side, away from the ear: 8 sides.
  for (const uint32_t x : {20u, 16u, 6u, 3u}) ASSERT_TRUE(insertCorner(layout, 0, 0, x));
  ASSERT_EQ(layout.patches[0].sides.size(), 8u);
  expectValid(layout);
  ResampleOptions ro;
  ro.chartSize = 17;
  EXPECT_GT(resampleLayout(layout, ro).param.degenerateTriangles, 0u) << "the ear has no area in the polygon";
  layout.patches.shrink_to_fit();

  EXPECT_EQ(moveSideEars(layout), 1u);
  expectValid(layout);
  EXPECT_EQ(layout.patches.size(), 2u) << "cut once at the neck";
  for (const Patch& patch : layout.patches) EXPECT_LE(patch.sides.size(), 8u);
  // The ear's middle vertex is now a corner.
  bool corner = false;
  for (const Patch& patch : layout.patches) {
    for (const PatchSide& side : patch.sides) corner = corner || side.vertices.front() == m;
  }
  EXPECT_TRUE(corner);
  EXPECT_EQ(resampleLayout(layout, ro).param.degenerateTriangles, 0u);
  EXPECT_EQ(moveSideEars(layout), 0u) << "nothing left to mend";
}

// The sampling error: an input vertex's distance to its chart's surface round its own chart
// coordinates. On a flat grid the charts are the plane itself (rounding only); on the cube sphere
// (a polyhedron: it creases at every edge) it about halves each time the chart side doubles.
TEST(SampleError, ZeroOnAPlaneAndFallingWithTheChartSize) {
  PatchLayout flat = test::gridLayout(12, 12, 1.0f, 1.0f, {6}, true);
  ResampleOptions ro;
  ro.chartSize = 17;
  const GeometryImageSet f = resampleLayout(flat, ro);
  EXPECT_LT(f.image.sampleError, 1e-6);
  double last = 0.0;
  for (uint32_t size : {9u, 17u, 33u, 65u}) {
    PatchLayout sphere = test::cubeLayout(16, true);
    ro.chartSize = size;
    const GeometryImageSet s = resampleLayout(sphere, ro);
    std::printf("  sphere at %u^2: sampling error %.3g (radius 1)\n", size, s.image.sampleError);
    EXPECT_GT(s.image.sampleError, 0.0);
    EXPECT_NE(s.image.sampleErrorVertex, ~0u);
    double worstChart = 0.0;
    for (const GeometryImage& g : s.charts) worstChart = std::max(worstChart, g.quality.sampleError);
    EXPECT_EQ(worstChart, s.image.sampleError);
    if (last > 0.0) {
      EXPECT_LT(s.image.sampleError, last * 0.6) << "chart size " << size;
    }
    last = s.image.sampleError;
  }
}

// Charts smaller than ResampleOptions::chordsBelow also count how far the input vertices of their
// shared sides lie from the polyline through the side's samples. A flat 12 x 12 grid of two
// patches whose shared side zigzags up and down (its vertices at z = +-0.02, the others flat),
// sampled at 5^2 (kites: 9 samples along the side's 13 vertices): counted, the worst vertex is on
// the shared side and the error is the zigzag's; not counted, or with the charts at the threshold,
// it is the flat interior's.
TEST(SampleError, SmallChartsCountTheChordsOfTheirSharedSides) {
  PatchLayout layout = test::gridLayout(12, 12, 1.0f, 1.0f, {6});
  std::set<uint32_t> side;
  for (uint32_t y = 0; y <= 12; ++y) {
    const uint32_t v = y * 13 + 6;
    side.insert(v);
    if (y > 0 && y < 12) layout.positions[v].z = (y % 2 ? 0.02f : -0.02f);
  }
  ResampleOptions ro;
  ro.chartSize = 5;
  const GeometryImageSet off = resampleLayout(layout, ro);
  ro.chordsBelow = 5;
  const GeometryImageSet at = resampleLayout(layout, ro);
  ro.chordsBelow = 9;
  const GeometryImageSet on = resampleLayout(layout, ro);
  std::printf("  zigzag side at 5^2: sampling error %.3g without its chords, %.3g with them\n", off.image.sampleError,
              on.image.sampleError);
  EXPECT_EQ(at.image.sampleError, off.image.sampleError);
  EXPECT_GT(on.image.sampleError, 0.01);
  EXPECT_GT(on.image.sampleError, 2.0 * off.image.sampleError);
  EXPECT_TRUE(side.contains(on.image.sampleErrorVertex)) << on.image.sampleErrorVertex;
  EXPECT_FALSE(side.contains(off.image.sampleErrorVertex));
}

// The repair cuts patches whose charts sample too coarsely until every chart is within the bound
// (the cube sphere: six patches of 16 x 16 cells at 9^2 samples a chart), with no flipped texels,
// and the charts are those of a full resampling of the final layout.
TEST(PatchSplit, SamplingErrorRepairReachesItsBound) {
  PatchLayout layout = test::cubeLayout(16, true);
  ResampleOptions ro;
  ro.chartSize = 9;
  const GeometryImageSet first = resampleLayout(layout, ro);
  ChartRepairOptions repair;
  repair.rounds = 6;
  repair.maxSampleError = first.image.sampleError / 3.0;
  ChartRepairStats st;
  const GeometryImageSet set = repairCharts(layout, resampleLayout(layout, ro), ro, repair, &st);
  std::printf("  cube sphere at 9^2: sampling error %.3g -> %.3g (bound %.3g), %zu patches, %u split\n",
              first.image.sampleError, set.image.sampleError, repair.maxSampleError, layout.patches.size(),
              st.patchesSplit);
  EXPECT_EQ(st.sampleErrorFirst, first.image.sampleError);
  EXPECT_EQ(st.patchesOverErrorFirst, 6u);
  EXPECT_GT(st.patchesSplit, 0u);
  EXPECT_LE(set.image.sampleError, repair.maxSampleError);
  EXPECT_EQ(set.image.flippedTexels, 0u);
  expectValid(layout);
  expectSameCharts(set, resampleLayout(layout, ro));
  // Without a bound the same layout is left alone (it has no folds).
  PatchLayout untouched = test::cubeLayout(16, true);
  ChartRepairStats none;
  repairCharts(untouched, resampleLayout(untouched, ro), ro, ChartRepairOptions{}, &none);
  EXPECT_EQ(none.patchesSplit, 0u);
  EXPECT_EQ(untouched.patches.size(), 6u);
}

// Open sides (the bunny's hole rims) whose vertices slide along their polygon edge, and are
// sampled through the parameterization, fold less than sides pinned by arc length: the shipped
// bunny in 24 patches at 129^2, before any repair or unfolding.
TEST(OpenSides, SlidingRimsFoldLessOnTheBunny) {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = 24;
  PatchLayout layout = buildPatchLayout(mesh, copt);
  straightenSides(layout, 2);
  moveSideEars(layout);
  ResampleOptions ro;
  ro.chartSize = 129;
  ro.unfold = false;
  const GeometryImageSet sliding = resampleLayout(layout, ro);
  ro.param.slideOpenSides = false;
  const GeometryImageSet pinned = resampleLayout(layout, ro);
  std::printf("  bunny, 24 patches at 129^2: %u flipped texels with sliding rims, %u pinned\n",
              sliding.image.flippedTexels, pinned.image.flippedTexels);
  EXPECT_LT(sliding.image.flippedTexels, pinned.image.flippedTexels);
  EXPECT_EQ(sliding.param.flippedTriangles, 0u);
  // The open sides' ends are the corner vertices, bit for bit, as the neighbours sample them.
  const auto offsets = quadChartOffsets(layout);
  uint32_t checked = 0;
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (uint32_t i = 0; i < layout.patches[p].sides.size(); ++i) {
      if (layout.patches[p].sides[i].neighbourPatch >= 0) continue;
      const GeometryImage& g = sliding.charts[offsets[p] + i];  // quad i: (0,0) is corner i
      const glm::vec3 corner = layout.positions[layout.patches[p].sides[i].vertices.front()];
      EXPECT_EQ(std::memcmp(&g.positions[0], &corner, sizeof corner), 0) << "patch " << p << " side " << i;
      ++checked;
    }
  }
  EXPECT_GT(checked, 0u);
}

TEST(PatchSplit, RepairLeavesAFoldFreeLayoutUnchanged) {
  PatchLayout layout = test::cubeLayout(8, true);
  const PatchLayout before = layout;
  ResampleOptions ro;
  ro.chartSize = 17;
  ChartRepairStats st;
  const GeometryImageSet set = resampleAndRepair(layout, ro, {4}, &st);
  EXPECT_EQ(set.image.flippedTexels, 0u);
  EXPECT_EQ(st.rounds, 0u);
  EXPECT_TRUE(sameLayout(layout, before));
}

}  // namespace
}  // namespace gimlod

// Tests for the sides quad layout (atlas/mesh/resample.h QuadLayout::kSides) and evenSides
// (atlas/mesh/layout_refine.h): quad counts; a cube and a sphere of six 4-sided patches are six
// seamless charts; even n-gons (disks and hemispheres) resample without flipped texels, their
// centre spokes seamless; an odd patch is refused; evenSides mends an odd patch on its open side
// and pairs the odd patches of the real bunny, after which its sides layout is seamless with
// reciprocal neighbours and about half the kites' charts; the shipped bunny built with --quads
// sides is seamless on disk with about half the charts; the least-stretch quad map keeps the
// border samples and lowers the stretch of a wide n-gon's quads, and the folding map folds less;
// alignSpokes finds a pairing without two-chart corners and mendTwoChartCorners mends those no
// pairing serves; sides of one edge are split at their midpoints so they can take a corner.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <set>
#include <filesystem>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "atlas/fidelity/fidelity.h"
#include "atlas/mesh/charting.h"
#include "atlas/mesh/layout_refine.h"
#include "atlas/mesh/mesh_io.h"
#include "atlas/mesh/resample.h"
#include "inspect/seams.h"
#include "pipeline/build.h"
#include "runtime/atlas_view.h"
#include "tests/chart_layout_fixture.h"
#include "tests/seam_check.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

using test::expectSeamless;
using test::sameBytes;

ResampleOptions sidesOptions(uint32_t chartSize) {
  ResampleOptions o;
  o.chartSize = chartSize;
  o.quads = QuadLayout::kSides;
  return o;
}

// The shipped bunny charted into `patches` patches, with its side counts made even.
PatchLayout evenedBunny(uint32_t patches) {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = patches;
  PatchLayout layout = buildPatchLayout(mesh, copt);
  if (evenSides(layout).oddLeft > 0) throw std::runtime_error("the bunny's patches could not all be evened");
  return layout;
}

TEST(SideQuads, QuadCounts) {
  EXPECT_EQ(patchQuadCount(4, QuadLayout::kSides), 1u);
  EXPECT_EQ(patchQuadCount(6, QuadLayout::kSides), 3u);
  EXPECT_EQ(patchQuadCount(8, QuadLayout::kSides), 4u);
  EXPECT_EQ(patchQuadCount(10, QuadLayout::kSides), 5u);
  EXPECT_EQ(patchQuadCount(5, QuadLayout::kKites), 5u);
  EXPECT_THROW(patchQuadCount(5, QuadLayout::kSides), std::invalid_argument);
}

TEST(SideQuads, CubeAndSphereAreOneChartAPatch) {
  for (const bool sphere : {false, true}) {
    SCOPED_TRACE(sphere ? "sphere" : "cube");
    const PatchLayout layout = test::cubeLayout(7, sphere);
    const GeometryImageSet set = resampleLayout(layout, sidesOptions(33));
    ASSERT_EQ(set.charts.size(), 6u);
    for (const GeometryImage& g : set.charts) {
      for (const RootNeighbour& nb : g.neighbours) EXPECT_GE(nb.chart, 0);  // closed surface
      // The chart's corners are its patch's corners, in order.
      const auto& sides = layout.patches[g.patch].sides;
      for (uint32_t e = 0; e < 4; ++e) {
        const glm::vec3 corner = layout.positions[sides[e].vertices.front()];
        EXPECT_TRUE(sameBytes(&g.positions[edgeSampleIndex(33, e, 0)], &corner, sizeof(glm::vec3)));
      }
    }
    EXPECT_EQ(expectSeamless(set), 6u * 4 * (33 + 17 + 9 + 5 + 3 + 2));
    EXPECT_EQ(set.image.flippedTexels, 0u);
    test::expectCubeImage(set, sphere);
  }
}

TEST(SideQuads, EvenNGonsHaveNoFlippedTexels) {
  for (const bool hemisphere : {false, true}) {
    for (const uint32_t n : {4u, 6u, 8u, 10u}) {
      SCOPED_TRACE(testing::Message() << "n=" << n << " hemisphere=" << hemisphere);
      const PatchLayout layout = test::diskLayout(n, 12, 60, hemisphere, true);
      const GeometryImageSet set = resampleLayout(layout, sidesOptions(33));
      ASSERT_EQ(set.charts.size(), n == 4 ? 1u : n / 2);
      EXPECT_EQ(set.image.flippedTexels, 0u);
      EXPECT_EQ(set.image.degenerateTexels, 0u);
      EXPECT_EQ(set.param.flippedTriangles, 0u);
      EXPECT_LT(set.image.stretchL2, 2.0);
      if (n > 4) {
        EXPECT_GT(expectSeamless(set), 0u);  // the spokes from corners 2j to the centre
        // The centre, chart sample (1,1), is one sample of every quad.
        for (const GeometryImage& g : set.charts) {
          EXPECT_TRUE(sameBytes(&g.positions.back(), &set.charts[0].positions.back(), sizeof(glm::vec3)));
        }
      }
      for (const GeometryImage& g : set.charts) {
        for (const glm::vec3& p : g.positions) EXPECT_LE(glm::length(p), 1.0f + 1e-5f);
      }
    }
  }
}

// The least-stretch quad map (QuadMap::kStretch) of a wide n-gon's quads: the same border samples
// as the bilinear map, byte for byte (so the seams do not change), no flipped texel, and less
// stretch where the bilinear map of a quad with a near-straight corner adds its own.
TEST(SideQuads, TheStretchQuadMapKeepsTheBorderAndLowersTheStretch) {
  for (const bool hemisphere : {false, true}) {
    for (const uint32_t n : {6u, 10u, 12u}) {
      SCOPED_TRACE(testing::Message() << "n=" << n << " hemisphere=" << hemisphere);
      const PatchLayout layout = test::diskLayout(n, 12, 60, hemisphere);
      ResampleOptions o = sidesOptions(33);
      const GeometryImageSet bilinear = resampleLayout(layout, o);
      o.quadMap = QuadMap::kStretch;
      const GeometryImageSet stretch = resampleLayout(layout, o);
      ASSERT_EQ(stretch.charts.size(), n / 2);
      EXPECT_EQ(stretch.image.flippedTexels, 0u);
      EXPECT_EQ(stretch.image.degenerateTexels, 0u);
      EXPECT_GT(expectSeamless(stretch), 0u);
      uint32_t interiorChanged = 0;
      for (size_t c = 0; c < stretch.charts.size(); ++c) {
        const GeometryImage& a = bilinear.charts[c];
        const GeometryImage& b = stretch.charts[c];
        for (uint32_t e = 0; e < 4; ++e) {
          for (uint32_t k = 0; k < 33; ++k) {
            const size_t i = edgeSampleIndex(33, e, k);
            ASSERT_TRUE(sameBytes(&a.positions[i], &b.positions[i], sizeof(glm::vec3)))
                << "chart " << c << " edge " << e;
          }
        }
        interiorChanged += a.positions[16 * 33 + 16] != b.positions[16 * 33 + 16];
      }
      EXPECT_EQ(interiorChanged, n / 2);  // the map is not the bilinear one
      if (n >= 10) {
        EXPECT_LT(stretch.image.stretchL2, bilinear.image.stretchL2 - 0.005)
            << "bilinear " << bilinear.image.stretchL2 << " stretch " << stretch.image.stretchL2;
      } else {
        EXPECT_LT(stretch.image.stretchL2, bilinear.image.stretchL2 + 0.005);
      }
    }
  }
}

// The bunny's evened 24-patch layout with its two-chart corners mended, and the sides options at
// 33^2 without the unfolding (the charts as their quad map places them).
struct MappedBunny {
  PatchLayout layout;
  ResampleOptions options;
};
MappedBunny mappedBunny() {
  MappedBunny b{evenedBunny(24), sidesOptions(33)};
  mendTwoChartCorners(b.layout);
  b.options.unfold = false;
  return b;
}

// QuadMap::kFolding on the bunny's evened layout: every chart folds no more than under the
// bilinear map, some fold less, and the charts, mixing both maps, stay seamless (the maps alone,
// without the unfolding).
TEST(SideQuads, TheFoldingQuadMapFoldsLessAndStaysSeamless) {
  auto [layout, o] = mappedBunny();
  const GeometryImageSet bilinear = resampleLayout(layout, o);
  o.quadMap = QuadMap::kFolding;
  const GeometryImageSet folding = resampleLayout(layout, o);
  ASSERT_EQ(folding.charts.size(), bilinear.charts.size());
  std::printf("  bunny, %zu patches at 33^2: %u flipped texels bilinear, %u folding\n", layout.patches.size(),
              bilinear.image.flippedTexels, folding.image.flippedTexels);
  ASSERT_GT(bilinear.image.flippedTexels, 0u);
  EXPECT_LT(folding.image.flippedTexels, bilinear.image.flippedTexels);
  for (size_t c = 0; c < folding.charts.size(); ++c) {
    EXPECT_LE(folding.charts[c].quality.flippedTexels, bilinear.charts[c].quality.flippedTexels) << "chart " << c;
    if (bilinear.charts[c].quality.flippedTexels == 0) {
      EXPECT_TRUE(sameBytes(folding.charts[c].positions.data(), bilinear.charts[c].positions.data(),
                            folding.charts[c].positions.size() * sizeof(glm::vec3)))
          << "chart " << c << " does not fold, so it keeps the bilinear map";
    }
  }
  EXPECT_GT(expectSeamless(folding), 0u);
}

// The unfolding on the bunny's evened layout at 33^2 (where a texel spans the most surface): it
// mends most flipped texels; no chart folds more than without it; every chart keeps its border
// bytes, so the charts stay seamless; a chart without flipped texels is untouched; no texel grows
// long across the surface (a chart's largest stretch at most doubles); and every sample that slid
// still lies on the input surface.
TEST(SideQuads, TheUnfoldingMendsFlippedTexelsOnTheSurfaceAndKeepsTheBorder) {
  auto [layout, o] = mappedBunny();
  const GeometryImageSet mapped = resampleLayout(layout, o);
  o.unfold = true;
  const GeometryImageSet unfolded = resampleLayout(layout, o);
  ASSERT_EQ(unfolded.charts.size(), mapped.charts.size());
  std::printf("  bunny, %zu patches at 33^2: %u flipped texels as mapped, %u unfolded (%u mended)\n",
              layout.patches.size(), mapped.image.flippedTexels, unfolded.image.flippedTexels,
              unfolded.image.texelsUnfolded);
  ASSERT_GT(mapped.image.flippedTexels, 20u);
  EXPECT_LT(unfolded.image.flippedTexels * 4, mapped.image.flippedTexels);
  EXPECT_EQ(unfolded.image.texelsUnfolded, mapped.image.flippedTexels - unfolded.image.flippedTexels);
  std::vector<glm::vec3> slid;
  for (size_t c = 0; c < unfolded.charts.size(); ++c) {
    const GeometryImage& a = mapped.charts[c];
    const GeometryImage& b = unfolded.charts[c];
    EXPECT_LE(b.quality.flippedTexels, a.quality.flippedTexels) << "chart " << c;
    EXPECT_LE(b.quality.stretchLinf, 2.0 * a.quality.stretchLinf) << "chart " << c;
    for (uint32_t e = 0; e < 4; ++e) {
      for (uint32_t k = 0; k < 33; ++k) {
        const size_t i = edgeSampleIndex(33, e, k);
        ASSERT_TRUE(sameBytes(&a.positions[i], &b.positions[i], sizeof(glm::vec3))) << "chart " << c << " edge " << e;
      }
    }
    if (a.quality.flippedTexels == 0) {
      EXPECT_TRUE(sameBytes(a.positions.data(), b.positions.data(), a.positions.size() * sizeof(glm::vec3)))
          << "chart " << c << " does not fold, so nothing slides";
    }
    for (size_t i = 0; i < a.positions.size(); ++i) {
      if (!sameBytes(&a.positions[i], &b.positions[i], sizeof(glm::vec3))) slid.push_back(b.positions[i]);
    }
  }
  ASSERT_GE(slid.size(), 3u);
  FidelityDetail detail;
  const FidelityStats f = measureFidelity(layout.positions, layout.triangles, slid, {{0, 1, 2}}, &detail);
  double farthest = 0.0;
  for (const float d : detail.atlasDistances) farthest = std::max(farthest, double(d));
  std::printf("  %zu samples slid, the farthest %.3g of the diagonal from the input surface\n", slid.size(),
              farthest / f.diagonal);
  EXPECT_LT(farthest, 1e-6 * f.diagonal);
  EXPECT_GT(expectSeamless(unfolded), 0u);
}

TEST(SideQuads, AnOddPatchIsRefused) {
  const PatchLayout layout = test::diskLayout(5, 4, 30, false);
  EXPECT_THROW(resampleLayout(layout, sidesOptions(17)), std::invalid_argument);
  EXPECT_THROW(quadNeighbours(layout, QuadLayout::kSides), std::invalid_argument);
}

TEST(EvenSides, AnOpenSideTakesTheCorner) {
  PatchLayout layout = test::diskLayout(5, 4, 30, false);
  const EvenSidesResult r = evenSides(layout);
  EXPECT_EQ(r.corners, 1u);
  EXPECT_EQ(r.oddLeft, 0u);
  ASSERT_EQ(layout.patches[0].sides.size(), 6u);
  EXPECT_TRUE(validatePatchLayout(layout, 3, kMaxPatchSides).empty());
  const GeometryImageSet set = resampleLayout(layout, sidesOptions(17));
  EXPECT_EQ(set.charts.size(), 3u);
  EXPECT_EQ(set.image.flippedTexels, 0u);
  // Already even: nothing to do.
  EXPECT_EQ(evenSides(layout).corners, 0u);
}

// The shipped bunny charted into 48 patches, as the build charts it.
TEST(EvenSides, TheBunnysOddPatchesArePairedAndItsSidesLayoutIsSeamless) {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = 48;
  PatchLayout layout = buildPatchLayout(mesh, copt);
  uint32_t oddBefore = 0, kites = 0;
  for (const Patch& p : layout.patches) {
    oddBefore += p.sides.size() % 2;
    kites += uint32_t(p.sides.size());
  }
  ASSERT_GT(oddBefore, 1u);
  const EvenSidesResult r = evenSides(layout);
  EXPECT_EQ(r.oddLeft, 0u);
  EXPECT_GE(r.corners, (oddBefore + 1) / 2);
  for (const Patch& p : layout.patches) EXPECT_EQ(p.sides.size() % 2, 0u);
  const std::vector<std::string> bad = validatePatchLayout(layout, 3, kMaxPatchSides);
  EXPECT_TRUE(bad.empty()) << bad.front();
  const GeometryImageSet set = resampleLayout(layout, sidesOptions(9));
  EXPECT_GT(expectSeamless(set), 0u);
  EXPECT_LT(set.charts.size() * 10, size_t(kites) * 7) << set.charts.size() << " charts against " << kites << " kites";
  std::printf("  bunny, 48 patches: %u odd, %u corners to even them, %zu charts (kites: %u)\n", oddBefore, r.corners,
              set.charts.size(), kites);
}

// The side count of every hole (loop of open sides) of a layout.
std::vector<uint32_t> holeSideCounts(const PatchLayout& layout) {
  std::map<uint32_t, uint32_t> next;  // open side: start vertex -> end vertex
  for (const Patch& p : layout.patches) {
    for (const PatchSide& s : p.sides) {
      if (s.neighbourPatch < 0) next[s.vertices.front()] = s.vertices.back();
    }
  }
  std::vector<uint32_t> counts;
  std::set<uint32_t> seen;
  for (const auto& [start, end] : next) {
    if (seen.contains(start)) continue;
    uint32_t n = 0;
    for (uint32_t v = start; !seen.contains(v); v = next.at(v)) seen.insert(v), ++n;
    counts.push_back(n);
  }
  return counts;
}

// The shipped bunny's holes, as charted into 48 patches: some are bordered by two sides alone,
// which in the sides layout close at the charts' coarsest level. splitTwoSidedHoles gives each two
// more corners on one side, so every hole has 3 or more sides and every patch keeps its side
// count's parity.
TEST(EvenSides, TwoSidedHolesGetTwoMoreCorners) {
  const IndexedMesh mesh = readMesh(test::repoData() / "meshes/bun_zipper.ply");
  ChartingOptions copt;
  copt.targetPatches = 48;
  PatchLayout layout = buildPatchLayout(mesh, copt);
  straightenSides(layout, 2, true);
  moveSideEars(layout);
  const std::vector<uint32_t> before = holeSideCounts(layout);
  std::vector<size_t> parity;
  for (const Patch& p : layout.patches) parity.push_back(p.sides.size() % 2);
  const uint32_t twoSided = uint32_t(std::count_if(before.begin(), before.end(), [](uint32_t n) { return n <= 2; }));
  std::printf("  bunny, 48 patches: %zu holes, %u of them with two sides or fewer\n", before.size(), twoSided);
  ASSERT_GT(twoSided, 0u);
  EXPECT_EQ(splitTwoSidedHoles(layout), 2 * twoSided);
  const std::vector<uint32_t> after = holeSideCounts(layout);
  ASSERT_EQ(after.size(), before.size());
  for (const uint32_t n : after) EXPECT_GE(n, 3u);
  for (size_t p = 0; p < layout.patches.size(); ++p) EXPECT_EQ(layout.patches[p].sides.size() % 2, parity[p]) << p;
  const std::vector<std::string> bad = validatePatchLayout(layout, 3, kMaxPatchSides);
  EXPECT_TRUE(bad.empty()) << bad.front();
  EXPECT_EQ(splitTwoSidedHoles(layout), 0u);  // nothing left to do
}

// The area of a layout's triangles.
double layoutArea(const PatchLayout& layout) {
  double area = 0.0;
  for (const auto& t : layout.triangles) {
    const glm::dvec3 a(layout.positions[t[0]]), b(layout.positions[t[1]]), c(layout.positions[t[2]]);
    area += 0.5 * glm::length(glm::cross(b - a, c - a));
  }
  return area;
}

// Two triangles of a unit square, each a patch of three one-edge sides (two open, one shared), as
// charting leaves small patches at a hole's rim: no side has an inner vertex to take a corner.
// Split at their midpoints, every side has one; the surface is the same, the layout valid, and
// each patch then takes a corner on an open side and is one chart, seamless.
TEST(EvenSides, SingleEdgeSidesAreSplitAtTheirMidpointsSoTheyCanTakeACorner) {
  PatchLayout layout;
  layout.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  layout.colours = {{0, 0, 0, 255}, {255, 0, 0, 255}, {255, 255, 0, 255}, {0, 255, 0, 255}};
  layout.triangles = {{0, 1, 2}, {0, 2, 3}};
  layout.patches.resize(2);
  layout.patches[0].triangles = {0};
  layout.patches[0].sides = {{{0, 1}}, {{1, 2}}, {{2, 0}}};
  layout.patches[1].triangles = {1};
  layout.patches[1].sides = {{{0, 2}}, {{2, 3}}, {{3, 0}}};
  test::linkSides(layout);
  ASSERT_EQ(layout.patches[0].sides[2].neighbourPatch, 1);
  EXPECT_EQ(patchesNear(layout, {1}, 0), std::vector<uint32_t>{1});
  EXPECT_EQ(patchesNear(layout, {1}, 1), (std::vector<uint32_t>{0, 1}));
  ASSERT_TRUE(validatePatchLayout(layout, 3, kMaxPatchSides).empty());
  {
    PatchLayout copy = layout;
    EXPECT_EQ(evenSides(copy).oddLeft, 2u);
  }
  const double area = layoutArea(layout);
  // The shared side is split once, from whichever patch reaches it first.
  EXPECT_EQ(splitSingleEdgeSides(layout, {0, 1}), 5u);
  EXPECT_EQ(layout.triangles.size(), 2u + 6u);
  EXPECT_EQ(layout.positions.size(), 4u + 5u);
  EXPECT_EQ(layout.colours.size(), layout.positions.size());
  EXPECT_EQ(layout.positions[4], glm::vec3(0.5f, 0.f, 0.f));
  EXPECT_EQ(layout.colours[4], glm::u8vec4(128, 0, 0, 255));  // the mean of its ends, rounded
  EXPECT_NEAR(layoutArea(layout), area, 1e-6);
  for (const Patch& p : layout.patches)
    for (const PatchSide& side : p.sides) EXPECT_EQ(side.vertices.size(), 3u);
  std::vector<std::string> bad = validatePatchLayout(layout, 3, kMaxPatchSides);
  ASSERT_TRUE(bad.empty()) << bad.front();
  EXPECT_EQ(splitSingleEdgeSides(layout, {0, 1}), 0u);  // nothing left to split
  EXPECT_EQ(evenSides(layout).oddLeft, 0u);
  bad = validatePatchLayout(layout, 3, kMaxPatchSides);
  ASSERT_TRUE(bad.empty()) << bad.front();
  const GeometryImageSet set = resampleLayout(layout, sidesOptions(9));
  EXPECT_EQ(set.charts.size(), 2u);
  EXPECT_GT(expectSeamless(set), 0u);
  EXPECT_EQ(set.image.flippedTexels, 0u);
}

// Rotating a patch's sides keeps the layout valid and every link reciprocal; rotating back
// restores it exactly; in the sides layout the other pairing gives the same chart count and
// still seamless charts.
TEST(EvenSides, RotatedSidesKeepTheLayoutValid) {
  PatchLayout layout = test::diskLayout(6, 6, 36, true);
  PatchLayout two = test::gridLayout(12, 4, 3.f, 1.f, {6});
  ASSERT_EQ(evenSides(two).oddLeft, 0u);
  for (PatchLayout* l : {&layout, &two}) {
    const PatchLayout before = *l;
    rotatePatchSides(*l, 0, 1);
    EXPECT_TRUE(validatePatchLayout(*l, 3, kMaxPatchSides).empty());
    EXPECT_EQ(l->patches[0].sides[0].vertices, before.patches[0].sides[1].vertices);
    const GeometryImageSet set = resampleLayout(*l, sidesOptions(17));
    EXPECT_GT(expectSeamless(set), 0u);
    rotatePatchSides(*l, 0, uint32_t(l->patches[0].sides.size()) - 1);
    for (size_t p = 0; p < l->patches.size(); ++p) {
      for (size_t i = 0; i < l->patches[p].sides.size(); ++i) {
        EXPECT_EQ(l->patches[p].sides[i].vertices, before.patches[p].sides[i].vertices);
        EXPECT_EQ(l->patches[p].sides[i].neighbourSide, before.patches[p].sides[i].neighbourSide);
      }
    }
  }
}

// alignSpokes solves the pairings exactly: from any pairing of the bunny's evened patches it
// finds one where every corner of two patches starts spokes in one of them.
TEST(EvenSides, AlignSpokesFindsAPairingWithoutTwoChartCorners) {
  PatchLayout layout = evenedBunny(48);
  EXPECT_EQ(alignSpokes(layout), 0u);
  uint32_t worstStart = 0;
  for (uint32_t seed = 1; seed <= 8; ++seed) {
    // Another pairing for some patches of 6 or more sides.
    for (uint32_t p = 0; p < layout.patches.size(); ++p) {
      if (layout.patches[p].sides.size() >= 6 && ((p * 2654435761u) >> (seed % 24)) % 3 == 0)
        rotatePatchSides(layout, p, 1);
    }
    worstStart = std::max(worstStart, twoQuadCorners(layout));
    EXPECT_EQ(alignSpokes(layout), 0u) << "seed " << seed;
    EXPECT_EQ(twoQuadCorners(layout), 0u);
    const std::vector<std::string> bad = validatePatchLayout(layout, 3, kMaxPatchSides);
    EXPECT_TRUE(bad.empty()) << bad.front();
  }
  EXPECT_GT(worstStart, 0u);  // the other pairings did leave such corners
}

// Where no pairing serves every two-patch corner (a 4-sided patch wrapped by one neighbour, as
// evening leaves some), mendTwoChartCorners adds corners until none is left; the layout stays
// valid and even, and resamples seamlessly.
TEST(EvenSides, MendTwoChartCornersLeavesNone) {
  PatchLayout layout = evenedBunny(24);
  const uint32_t aligned = alignSpokes(layout);
  ASSERT_GT(aligned, 0u);  // this layout needs the mend
  const MendCornersResult mend = mendTwoChartCorners(layout);
  std::printf("  24 patches: %u two-chart corners after alignSpokes, %u after the mend (%u corners added)\n", aligned,
              mend.left, mend.corners);
  EXPECT_EQ(mend.left, 0u);
  EXPECT_EQ(twoQuadCorners(layout), 0u);
  EXPECT_GT(mend.corners, 0u);
  for (const Patch& p : layout.patches) EXPECT_EQ(p.sides.size() % 2, 0u);
  const std::vector<std::string> bad = validatePatchLayout(layout, 3, kMaxPatchSides);
  EXPECT_TRUE(bad.empty()) << bad.front();
  EXPECT_GT(expectSeamless(resampleLayout(layout, sidesOptions(9))), 0u);
}

// `gimlod build --sizing layout --quads sides --repair-rounds 0` on the shipped bunny: the chart size follows the
// density, and is doubled again when the repair (here none; in the sides layout, one whose cuts
// must keep side counts even) leaves charts over the sampling bound (the bunny: 0.12% of the
// diagonal at 129^2, so 257^2), until the atlas meets it or holds kMaxSamplesPerTriangle (the
// bunny's 24 patches at 257^2: 75 samples per triangle, 0.098%).
TEST(SideQuads, TheBunnysSidesBuildMeetsTheSamplingBound) {
  test::TempDir dir("gimlod-side-quads-bound");
  MeshBuildOptions o;
  o.input = test::repoData() / "meshes/bun_zipper.ply";
  o.output = dir.path() / "sides.atlas";
  o.measureFidelity = false;
  o.quads = MeshQuads::kSides;
  o.sizing = MeshSizing::kLayout;
  o.repairRounds = 0;
  buildAtlas(o);
  const nlohmann::json stats = nlohmann::json::parse(std::ifstream(o.output / "stats.json"));
  const nlohmann::json& r = stats.at("resample");
  std::printf("  bunny, sides: %u charts at %u^2, sampling error %.3g (bound %.3g), %u doublings after the repair\n",
              stats.at("charts").get<uint32_t>(), stats.at("chart_size").get<uint32_t>(),
              r.at("sample_error").get<double>(), r.at("max_sample_error").get<double>(),
              r.at("chart_size_doublings_after_repair").get<uint32_t>());
  EXPECT_TRUE(r.at("chart_size_by_density").get<bool>());
  EXPECT_GT(r.at("chart_size_doublings_after_repair").get<uint32_t>(), 0u);
  EXPECT_GT(r.at("max_sample_error").get<double>(), 0.0);
  const double samplesPerTriangle =
      double(stats.at("samples").get<uint64_t>()) / double(stats.at("charting").at("triangles").get<uint64_t>());
  if (r.at("sample_error").get<double>() > r.at("max_sample_error").get<double>()) {
    EXPECT_GE(samplesPerTriangle, kMaxSamplesPerTriangle) << "the doubling stopped over the bound below the cap";
  }
  EXPECT_EQ(r.at("two_quad_corners").get<uint32_t>(), 0u);
  const SeamReport seams = validateSeams(o.output);
  EXPECT_TRUE(seams.seamless()) << seams.mismatches() << " seam mismatches";
}

// `gimlod build --quads sides|kites|auto` on the shipped bunny: the atlas on disk (compressed) is seamless at
// every level, has corners added to even the side counts, and about half the charts of kites from
// the same patches; auto keeps the one that leaves fewer flipped texels.
TEST(SideQuads, TheShippedBunnyBuildsWithHalfTheCharts) {
  test::TempDir dir("gimlod-side-quads");
  uint32_t charts[2] = {0, 0}, flipped[2] = {0, 0}, twoChartCorners = 0;
  for (const bool sides : {false, true}) {
    MeshBuildOptions o;
    o.input = test::repoData() / "meshes/bun_zipper.ply";
    o.output = dir.path() / (sides ? "sides.atlas" : "kites.atlas");
    o.patches = 24;
    o.chartSize = 33;
    o.measureFidelity = false;
    o.quads = sides ? MeshQuads::kSides : MeshQuads::kKites;
    buildAtlas(o);
    const SeamReport seams = validateSeams(o.output);
    EXPECT_TRUE(seams.seamless()) << seams.mismatches() << " seam mismatches";
    EXPECT_GT(seams.sharedEdges, 0u);
    const nlohmann::json stats = nlohmann::json::parse(std::ifstream(o.output / "stats.json"));
    const nlohmann::json& r = stats.at("resample");
    EXPECT_EQ(r.at("quads").get<std::string>(), sides ? "sides" : "kites");
    if (sides) {
      EXPECT_GT(r.at("even_side_corners").get<uint32_t>(), 0u);
    }
    charts[sides] = openAtlas(o.output).hierarchy.chartCount();
    flipped[sides] = r.at("flipped_texels").get<uint32_t>();
    if (sides) twoChartCorners = r.at("two_quad_corners").get<uint32_t>();
  }
  std::printf("  bunny, 24 patches at 33^2: kites %u charts (%u flipped), sides %u charts (%u flipped)\n", charts[0],
              flipped[0], charts[1], flipped[1]);
  EXPECT_LT(charts[1] * 10, charts[0] * 7);
  // auto keeps the layout that leaves fewer flipped texels (sides on a tie, with no two-chart
  // corner), and names the other's count.
  MeshBuildOptions o;
  o.input = test::repoData() / "meshes/bun_zipper.ply";
  o.output = dir.path() / "auto.atlas";
  o.patches = 24;
  o.chartSize = 33;
  o.measureFidelity = false;
  o.quads = MeshQuads::kAuto;
  buildAtlas(o);
  const nlohmann::json r = nlohmann::json::parse(std::ifstream(o.output / "stats.json")).at("resample");
  const bool sidesWin = flipped[1] <= flipped[0] && twoChartCorners == 0;
  EXPECT_EQ(r.at("quads").get<std::string>(), sidesWin ? "sides" : "kites");
  EXPECT_EQ(openAtlas(o.output).hierarchy.chartCount(), charts[sidesWin]);
  EXPECT_EQ(r.at("flipped_texels").get<uint32_t>(), flipped[sidesWin]);
  if (flipped[1] > 0 || twoChartCorners > 0) {
    EXPECT_EQ(r.at("other_quads_flipped_texels").get<int64_t>(), int64_t(flipped[!sidesWin]));
  }
}

}  // namespace
}  // namespace gimlod

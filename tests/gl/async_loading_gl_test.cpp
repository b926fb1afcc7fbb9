// Asynchronous page loading in the scene (paper 7.2): missing nodes draw as resident ancestors,
// every drawn frame is a stitched, crack-free partition, and a static view converges to the
// desired cut. Cracks are measured on the real vertex shader (transform feedback).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>

#include "pipeline/build.h"
#include "runtime/adapt.h"
#include "runtime/atlas_view.h"
#include "runtime/gl/atlas_scene.h"
#include "runtime/gl/egl_context.h"
#include "tests/gl/gl_context_test.h"
#include "tests/small_atlases.h"
#include "runtime/stitch.h"
#include "tests/adapt_fixture.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

class AsyncLoadingTest : public test::GlContextTest<> {
 protected:
  AtlasView build() {
    [[maybe_unused]] const test::SerialTbbUnderTsan serial;
    test::buildRainierAtlas(dir_.path() / "atlas", 129, 4, 32, 2);
    return openAtlas(dir_.path() / "atlas");
  }

  static Camera camera(const AtlasView& a, double t) {
    const glm::dvec3 ext = a.hi - a.lo;
    Camera c;
    c.eye = a.lo + glm::dvec3((0.15 + 0.5 * t) * ext.x, (0.1 + 0.3 * t) * ext.y, a.hi.z + 0.06 * ext.x);
    c.target = a.lo + glm::dvec3((0.5 + 0.3 * t) * ext.x, (0.6 + 0.2 * t) * ext.y, a.lo.z);
    c.nearPlane = c.farPlane = 0.0;
    fitClipPlanes(c, a.lo, a.hi);
    return c;
  }

  // A 96x72 scene's options, and the bytes of one of its pages (*standIns: whether a scene at the
  // default cache gives its roots stand-ins).
  static gl::SceneOptions smallScene(const AtlasView& a, uint64_t* pageBytes, bool* standIns = nullptr) {
    gl::SceneOptions so;
    so.width = 96;
    so.height = 72;
    gl::AtlasScene probe(a, so);
    *pageBytes = probe.pageBytes();
    if (standIns) *standIns = !probe.rootStandIns().empty();
    return so;
  }

  test::TempDir dir_{"gimlod-async"};
};

// The drawn cut is a coarsening of the desired one: every desired node is drawn itself (at its
// resolution, or coarser for a root on its stand-in with rootsOnStandIns) or through exactly one
// drawn ancestor, and every drawn node covers a desired node.
void expectDrawnCoversDesired(const Cut& drawn, const Cut& desired, int frame, bool rootsOnStandIns = false) {
  std::vector<uint32_t> covers(drawn.nodes.size(), 0);
  for (const CutNode& n : desired.nodes) {
    uint32_t found = 0;
    for (NodeId a = n.id;; a = a.parent()) {
      const int32_t i = drawn.find(a);
      if (i >= 0) {
        ++found;
        ++covers[i];
        if (a.key() == n.id.key() && rootsOnStandIns && a.level == 0) {
          EXPECT_LE(drawn.nodes[i].resLog2, n.resLog2) << "frame " << frame;
        } else if (a.key() == n.id.key()) {
          EXPECT_EQ(drawn.nodes[i].resLog2, n.resLog2) << "frame " << frame;
        }
      }
      if (a.level == 0) break;
    }
    EXPECT_EQ(found, 1u) << "frame " << frame << ": desired node not drawn exactly once";
  }
  for (size_t i = 0; i < covers.size(); ++i)
    EXPECT_GT(covers[i], 0u) << "frame " << frame << ": drawn node covers no desired node";
}

TEST_F(AsyncLoadingTest, SubstitutesResidentAncestorsCrackFreeAndConverges) {
  const AtlasView atlas = build();
  const Hierarchy& h = atlas.hierarchy;
  ASSERT_GE(h.params.maxNodeResLog2 + 1, h.params.depth) << "substitution needs log2 R >= depth-1";
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  so.asyncLoads = true;
  so.maxUploadsPerFrame = 4;
  gl::AtlasScene scene(atlas, so);
  ASSERT_NE(scene.loader(), nullptr);
  AdaptOptions ao;
  ao.tolerancePx = 1.0;
  ao.maxNodes = 1500;

  auto checkFrame = [&](const gl::FrameResult& f, int i) {
    EXPECT_EQ(f.pagesMissing, 0u) << "frame " << i;
    EXPECT_EQ(f.stitchUnfixable, 0u) << "frame " << i;
    EXPECT_LE(f.pagesUploaded, so.maxUploadsPerFrame) << "frame " << i;
    EXPECT_EQ(countStitchViolations(h, f.cut), 0u) << "frame " << i;
    expectDrawnCoversDesired(f.cut, f.desiredCut, i);
    const auto verts = scene.capture(f.cut);
    ASSERT_EQ(verts.size(), f.cut.nodes.size());
    const CrackReport r = countCracks(h, f.cut, verts);
    EXPECT_EQ(r.mismatches, 0u) << "frame " << i << ": " << r.mismatches << " of " << r.borderVertices
                                << " border vertices";
    if (f.cut.nodes.size() > 1) {
      EXPECT_GT(r.borderVertices, 0u) << "frame " << i;
    }
  };

  // Moving camera: the first frame has nothing but the roots resident.
  uint32_t uploaded = 0, substitutedFrames = 0;
  const int kMoving = 10;
  for (int i = 0; i < kMoving; ++i) {
    const gl::FrameResult f = scene.renderFrame(camera(atlas, double(i) / kMoving), ao);
    if (i == 0) {
      uint32_t nonRoot = 0;
      for (const CutNode& n : f.desiredCut.nodes) nonRoot += n.id.level > 0;
      ASSERT_GT(nonRoot, so.maxUploadsPerFrame) << "the view must need more pages than one upload batch";
      EXPECT_GT(f.nodesSubstituted, 0u);
      EXPECT_GT(f.pagesRequested, 0u);
      EXPECT_LT(f.cut.nodes.size(), f.desiredCut.nodes.size());
    }
    substitutedFrames += f.nodesSubstituted > 0;
    uploaded += f.pagesUploaded;
    checkFrame(f, i);
    if (i % 2 == 1) scene.waitForLoads();  // let some loads finish between frames
  }
  EXPECT_GT(substitutedFrames, 0u);
  EXPECT_GT(uploaded, 0u);

  // Static camera: converges to the desired cut.
  const Camera still = camera(atlas, 1.0);
  gl::FrameResult f;
  int frames = 0;
  for (; frames < 2000; ++frames) {
    f = scene.renderFrame(still, ao);
    if (frames < 5 || f.nodesSubstituted == 0) checkFrame(f, kMoving + frames);
    if (f.nodesSubstituted == 0) break;
    scene.waitForLoads();
  }
  ASSERT_EQ(f.nodesSubstituted, 0u) << "no convergence after " << frames << " static frames";
  // note: the converged frame may still have requested pages that were uploaded in that frame.
  f = scene.renderFrame(still, ao);
  checkFrame(f, kMoving + frames + 1);
  EXPECT_EQ(f.pagesRequested, 0u);
  EXPECT_EQ(f.nodesSubstituted, 0u);
  ASSERT_EQ(f.cut.nodes.size(), f.desiredCut.nodes.size());
  for (size_t i = 0; i < f.cut.nodes.size(); ++i) {
    EXPECT_EQ(f.cut.nodes[i].id.key(), f.desiredCut.nodes[i].id.key());
    EXPECT_EQ(f.cut.nodes[i].resLog2, f.desiredCut.nodes[i].resLog2);
  }
  const PageLoaderStats s = scene.loader()->stats();
  EXPECT_GT(s.requested, 0u);
  EXPECT_GT(s.loadedFromDisk, 0u);
  // The pages uploaded with the mips the loader's threads made draw as those the scene reads and
  // uploads itself.
  const std::vector<uint8_t> streamed = scene.renderer().readPixels();
  gl::SceneOptions direct = so;
  direct.asyncLoads = false;
  gl::AtlasScene sync(atlas, direct);
  sync.drawCut(still, f.cut);
  EXPECT_TRUE(sync.renderer().readPixels() == streamed) << "the loader's mips draw otherwise";
}

// Pixels of the "pages loading" view's magenta stripes (mixed 60% over the shading).
size_t magentaPixels(const std::vector<uint8_t>& rgba) {
  size_t n = 0;
  for (size_t i = 0; i + 3 < rgba.size(); i += 4) n += rgba[i] > 150 && rgba[i + 2] > 120 && rgba[i + 1] < 110;
  return n;
}

// The "pages loading" view stripes the nodes standing in for pages still loading, only when it
// is on, and nothing once every page has loaded.
TEST_F(AsyncLoadingTest, PagesLoadingViewMarksTheStandInsUntilTheirPagesArrive) {
  const AtlasView atlas = build();
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  so.asyncLoads = true;
  so.maxUploadsPerFrame = 4;
  AdaptOptions ao;
  ao.tolerancePx = 1.0;
  ao.maxNodes = 1500;
  const Camera cam = camera(atlas, 0.5);
  {
    gl::AtlasScene plain(atlas, so);
    const gl::FrameResult f = plain.renderFrame(cam, ao);
    ASSERT_GT(f.nodesSubstituted, 0u);  // the first frame has only the roots resident
    EXPECT_EQ(magentaPixels(plain.renderer().readPixels()), 0u) << "stripes with the view off";
  }
  gl::AtlasScene scene(atlas, so);
  scene.renderer().setInspectionViews({.loading = true});
  gl::FrameResult f = scene.renderFrame(cam, ao);
  ASSERT_GT(f.nodesSubstituted, 0u);
  EXPECT_GT(magentaPixels(scene.renderer().readPixels()), size_t(96 * 72 / 20)) << "no stripes while pages load";
  for (int frames = 0; frames < 2000 && f.nodesSubstituted > 0; ++frames) {
    scene.waitForLoads();
    f = scene.renderFrame(cam, ao);
  }
  ASSERT_EQ(f.nodesSubstituted, 0u);
  EXPECT_EQ(magentaPixels(scene.renderer().readPixels()), 0u) << "stripes left once every page is in";
}

// The byte budgets hold in every frame, on budgets below one level of pages: the GPU pool holds
// the roots and a dozen pages, the RAM three loaded pages, one frame's uploads two pool pages. Every
// frame stays complete. The same GPU budget holds without the loader, and one below the roots is
// refused with the least it needs.
TEST_F(AsyncLoadingTest, ByteBudgetsHoldInEveryFrame) {
  const AtlasView atlas = build();
  const Hierarchy& h = atlas.hierarchy;
  uint64_t pageBytes = 0;
  gl::SceneOptions so = smallScene(atlas, &pageBytes);
  ASSERT_GT(pageBytes, 0u);
  const uint32_t roots = h.chartCount();
  ASSERT_GT(4 * roots, 12u) << "the pool must hold less than one level of pages";
  so.gpuCacheBytes = (roots + 12) * pageBytes + pageBytes / 2;
  PageReader reader(atlas.dir, atlas.manifest, h.params);
  const size_t loadedBytes = reader.pageBytes({0, 1, 0, 0});
  AdaptOptions ao;
  ao.tolerancePx = 1.0;
  ao.maxNodes = 1500;
  for (const bool async : {true, false}) {
    SCOPED_TRACE(async ? "loader" : "synchronous");
    so.asyncLoads = async;
    so.ramCacheBytes = 3 * loadedBytes;
    so.uploadBytesPerFrame = 2 * pageBytes;
    so.loaderThreads = 2;
    gl::AtlasScene scene(atlas, so);
    ASSERT_EQ(scene.renderer().pageCapacity(), roots + 12);
    uint32_t substituted = 0;
    for (int i = 0; i < 24; ++i) {
      const gl::FrameResult f = scene.renderFrame(camera(atlas, double(std::min(i, 16)) / 16), ao);
      EXPECT_LE(f.residentGpuBytes, so.gpuCacheBytes) << "frame " << i;
      EXPECT_LE(f.gpuBudgetBytes, so.gpuCacheBytes) << "frame " << i;
      EXPECT_LE(f.residentRamBytes, so.ramCacheBytes) << "frame " << i;
      if (async) {
        EXPECT_LE(f.uploadBytes, so.uploadBytesPerFrame) << "frame " << i;
      }
      EXPECT_FALSE(f.incomplete) << "frame " << i;
      EXPECT_EQ(f.pagesMissing, 0u) << "frame " << i;
      EXPECT_LE(f.cut.nodeCount(), scene.nodeRoom()) << "frame " << i;
      EXPECT_EQ(countStitchViolations(h, f.cut), 0u) << "frame " << i;
      substituted += f.nodesSubstituted;
      if (async && i % 3 == 2) scene.waitForLoads();
    }
    if (async) {
      EXPECT_GT(substituted, 0u) << "the budgets never held a page back";
    }
  }
}

// A GPU cache below every root's page and room to split one: the roots get stand-ins (each root's
// page at a coarser resolution, in arrays of their own), the pool the rest. With the loader and
// without, the budgets hold in every frame, every frame is complete, stitched and crack-free, and
// roots are drawn from their stand-ins. A cache below the stand-ins and four pages is refused.
TEST_F(AsyncLoadingTest, ACacheBelowTheRootsDrawsThemFromStandIns) {
  const AtlasView atlas = build();
  const Hierarchy& h = atlas.hierarchy;
  uint64_t pageBytes = 0;
  bool standInsAtDefault = true;
  gl::SceneOptions so = smallScene(atlas, &pageBytes, &standInsAtDefault);
  EXPECT_FALSE(standInsAtDefault) << "a pool that holds the roots locks them";
  const uint32_t roots = h.chartCount();
  so.gpuCacheBytes = (roots + 3) * pageBytes;
  AdaptOptions ao;
  ao.tolerancePx = 1.0;
  ao.maxNodes = 1500;
  // The stand-ins at their default resolution, then at the coarsest, below depth - 1: a root on
  // its stand-in may then hold the charts beside it coarser.
  for (const uint32_t standInRes : {0u, h.params.minResLog2()})
    for (const bool async : {true, false}) {
      SCOPED_TRACE(async ? "loader" : "synchronous");
      so.asyncLoads = async;
      so.maxUploadsPerFrame = 2;
      so.standInResLog2 = standInRes;
      gl::AtlasScene scene(atlas, so);
      ASSERT_EQ(scene.rootStandIns().resLog2.size(), roots);
      EXPECT_LT(scene.renderer().pageCapacity(), roots + 3);
      EXPECT_GE(scene.renderer().pageCapacity(), 4u);
      uint32_t onStandIns = 0, coarsened = 0;
      for (int i = 0; i < 24; ++i) {
        const gl::FrameResult f = scene.renderFrame(camera(atlas, double(std::min(i, 16)) / 16), ao);
        EXPECT_LE(f.residentGpuBytes, so.gpuCacheBytes) << "frame " << i;
        EXPECT_LE(f.gpuBudgetBytes, so.gpuCacheBytes) << "frame " << i;
        EXPECT_FALSE(f.incomplete) << "frame " << i;
        EXPECT_EQ(f.pagesMissing, 0u) << "frame " << i;
        EXPECT_EQ(f.stitchUnfixable, 0u) << "frame " << i;
        EXPECT_EQ(countStitchViolations(h, f.cut), 0u) << "frame " << i;
        expectDrawnCoversDesired(f.cut, f.desiredCut, i, true);
        const auto verts = scene.capture(f.cut);
        const CrackReport r = countCracks(h, f.cut, verts);
        EXPECT_EQ(r.mismatches, 0u) << "frame " << i << ": " << r.mismatches << " of " << r.borderVertices;
        onStandIns += f.rootsOnStandIns;
        coarsened += f.chartsCoarsened;
        if (async && i % 3 == 2) scene.waitForLoads();
      }
      EXPECT_GT(onStandIns, 0u) << "no root was drawn from its stand-in";
      std::cout << "  " << (async ? "loader" : "synchronous") << ": " << scene.renderer().pageCapacity()
                << " pool pages, stand-ins of 2^" << uint32_t(scene.rootStandIns().resLog2[0]) << " intervals; "
                << onStandIns << " roots drawn from stand-ins, " << coarsened << " charts held coarser beside them\n";
    }
  so.gpuCacheBytes = 3 * pageBytes;
  try {
    gl::AtlasScene tooSmall(atlas, so);
    ADD_FAILURE() << "a GPU cache below the stand-ins and four pages was taken";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("stand-ins"), std::string::npos) << e.what();
  }
}

// A root drawn from its stand-in, at the stand-in's resolution or coarser, has the vertices its
// own page gives, bit for bit, so a cut mixing both stays crack-free.
TEST_F(AsyncLoadingTest, AStandInDrawsItsRootsVerticesBitForBit) {
  const AtlasView atlas = build();
  const Hierarchy& h = atlas.hierarchy;
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  gl::AtlasScene locked(atlas, so);
  so.gpuCacheBytes = (h.chartCount() + 3) * locked.pageBytes();
  gl::AtlasScene standing(atlas, so);
  ASSERT_FALSE(standing.rootStandIns().empty());
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const uint32_t s = standing.rootStandIns().resLog2[c];
    ASSERT_LT(s, h.maxResLog2(NodeId{c, 0, 0, 0})) << "the stand-in is the page itself";
    for (uint32_t res = h.params.minResLog2(); res <= s; ++res) {
      Cut cut;
      cut.nodes.push_back({NodeId{c, 0, 0, 0}, res});
      cut.rebuildIndex();
      const auto a = locked.capture(cut), b = standing.capture(cut);
      ASSERT_EQ(a.size(), 1u);
      ASSERT_EQ(b.size(), 1u);
      ASSERT_EQ(a[0].size(), b[0].size());
      EXPECT_EQ(0, std::memcmp(a[0].data(), b[0].data(), a[0].size() * sizeof(glm::vec3)))
          << "chart " << c << " at 2^" << res;
    }
  }
}

// Blocks that turn corrupt on disk while the scene runs: their pages fail once each (reported
// once), their nodes stay on resident stand-ins, and every frame is complete and crack-free.
TEST_F(AsyncLoadingTest, ACorruptBlockAtRunTimeLeavesItsNodeOnAStandIn) {
  const AtlasView atlas = build();
  const Hierarchy& h = atlas.hierarchy;
  std::mutex toldMutex;
  std::vector<PageFailure> told;
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  so.asyncLoads = true;
  so.onPageFailure = [&](const PageFailure& f) {
    std::lock_guard<std::mutex> lock(toldMutex);
    told.push_back(f);
  };
  gl::AtlasScene scene(atlas, so);  // the roots are read now
  for (const auto& e : std::filesystem::directory_iterator(atlas.dir / "charts")) {
    const auto size = std::filesystem::file_size(e.path());
    std::fstream file(e.path(), std::ios::in | std::ios::out | std::ios::binary);
    file.seekp(std::streamoff(size / 4));
    for (uint64_t i = size / 4; i < size; ++i) file.put(char(0x5A ^ (i * 167)));
  }
  AdaptOptions ao;
  ao.tolerancePx = 0.5;
  ao.maxNodes = 1500;
  gl::FrameResult f;
  for (int i = 0; i < 12; ++i) {
    f = scene.renderFrame(camera(atlas, 0.5), ao);
    EXPECT_FALSE(f.incomplete) << "frame " << i;
    EXPECT_EQ(f.pagesMissing, 0u) << "frame " << i;
    EXPECT_EQ(countStitchViolations(h, f.cut), 0u) << "frame " << i;
    expectDrawnCoversDesired(f.cut, f.desiredCut, i);
    if (i % 4 == 3) {
      const CrackReport r = countCracks(h, f.cut, scene.capture(f.cut));
      EXPECT_EQ(r.mismatches, 0u) << "frame " << i;
    }
    scene.waitForLoads();
  }
  const std::vector<PageFailure> failures = scene.loader()->failures();
  ASSERT_GT(failures.size(), 0u) << "no page read the garbage";
  EXPECT_GT(f.nodesSubstituted, 0u) << "failed pages left no stand-in";
  std::lock_guard<std::mutex> lock(toldMutex);
  EXPECT_EQ(told.size(), failures.size()) << "a failure reported twice, or not at all";
  for (const PageFailure& p : told) EXPECT_NE(p.message.find("charts"), std::string::npos) << p.message;
}

// Prefetching the view half a second ahead loads the pages a moving camera is about to need, so
// more of each frame's pages are resident as it begins (the hit rate) than without: at least a
// tenth fewer misses. One loader
// thread and a wait for its loads after each frame make both runs deterministic.
TEST_F(AsyncLoadingTest, PrefetchRaisesTheHitRate) {
  const AtlasView atlas = build();
  AdaptOptions ao;
  ao.tolerancePx = 0.5;
  ao.maxNodes = 1500;
  auto hitRate = [&](double prefetchSeconds, uint32_t* prefetched) {
    gl::SceneOptions so;
    so.width = 96;
    so.height = 72;
    so.asyncLoads = true;
    so.loaderThreads = 1;
    so.prefetchSeconds = prefetchSeconds;
    so.frameSeconds = 0.1;  // five frames ahead
    gl::AtlasScene scene(atlas, so);
    uint64_t needed = 0, resident = 0;
    *prefetched = 0;
    for (int i = 0; i < 30; ++i) {
      const gl::FrameResult f = scene.renderFrame(camera(atlas, double(i) / 30), ao);
      EXPECT_FALSE(f.incomplete);
      if (i >= 5) needed += f.pagesNeeded, resident += f.pagesResident;
      *prefetched += f.prefetchRequests;
      scene.waitForLoads();
    }
    return double(resident) / double(std::max<uint64_t>(needed, 1));
  };
  uint32_t none = 0, ahead = 0;
  const double without = hitRate(0.0, &none), with = hitRate(0.5, &ahead);
  EXPECT_EQ(none, 0u);
  EXPECT_GT(ahead, 0u);
  // At least a tenth of the misses go (0.765 against 0.701 when this was written: a fifth).
  EXPECT_LE(1.0 - with, 0.9 * (1.0 - without)) << "hit rate " << with << " with prefetch, " << without << " without";
  std::printf("hit rate along the path: %.3f with prefetch, %.3f without\n", with, without);
}

TEST_F(AsyncLoadingTest, SynchronousDefaultDrawsDesiredCut) {
  const AtlasView atlas = build();
  gl::SceneOptions so;
  so.width = 96;
  so.height = 72;
  gl::AtlasScene scene(atlas, so);
  EXPECT_EQ(scene.loader(), nullptr);
  AdaptOptions ao;
  ao.maxNodes = 500;  // below the page pool's room, so the scene does not clamp it
  const Camera cam = camera(atlas, 0.0);
  const gl::FrameResult f = scene.renderFrame(cam, ao);
  EXPECT_EQ(f.nodesSubstituted, 0u);
  EXPECT_EQ(f.pagesRequested, 0u);
  EXPECT_EQ(f.pagesMissing, 0u);
  EXPECT_GT(f.pagesLoaded, 0u);
  EXPECT_TRUE(f.desiredCut.nodes.empty());
  // The drawn cut is exactly what the adaptation (a fresh dual-queue adapter, as the scene's
  // first frame) chooses for this view.
  DualQueueAdapter independent(atlas.hierarchy);
  const Cut& expected = independent.update(makeViewParams(cam, so.width, so.height), ao);
  EXPECT_EQ(test::sortedNodes(f.cut), test::sortedNodes(expected));
  // The stateless top-down greedy draws a valid cut too.
  so.coherentAdaptation = false;
  gl::AtlasScene topDown(atlas, so);
  const gl::FrameResult g = topDown.renderFrame(cam, ao);
  EXPECT_EQ(test::sortedNodes(g.cut),
            test::sortedNodes(adaptErrorThreshold(atlas.hierarchy, makeViewParams(cam, so.width, so.height), ao)));
}

}  // namespace
}  // namespace gimlod

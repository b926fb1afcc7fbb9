// The asynchronous page loader (paper 7.2): priority order, data equal to direct reads, the RAM
// cache budget with LRU eviction, and prompt shutdown with requests pending.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <future>

#include <memory>

#include "pipeline/build.h"
#include "runtime/atlas_view.h"
#include "runtime/page_loader.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

class PageLoaderTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = std::make_unique<test::TempDir>("gimlod-loader");
    TerrainBuildOptions o;
    o.input = test::repoData() / "terrain/mt_rainier_90m.tif";
    o.output = dir_->path() / "atlas";
    o.chartSize = 129;
    o.depth = 3;
    o.nodeRes = 32;
    o.minNodeRes = 4;
    [[maybe_unused]] const test::SerialTbbUnderTsan serial;
    buildAtlas(o);
    atlas_ = std::make_unique<AtlasView>(openAtlas(o.output));
    pages_ = std::make_unique<PageReader>(atlas_->dir, atlas_->manifest, atlas_->hierarchy.params);
  }
  static void TearDownTestSuite() {
    pages_.reset();
    atlas_.reset();
    dir_.reset();
  }
  static size_t pageBytes(uint32_t level) {
    const size_t s = pages_->pageSamples({0, level, 0, 0});
    return s * s * (sizeof(float) + sizeof(PackedNormal));
  }
  static void expectPageEquals(const NodeId& n, const std::vector<float>& h,
                               const std::vector<PackedNormal>& nr) {
    std::vector<float> eh;
    std::vector<PackedNormal> en;
    pages_->read(n, eh, en);
    EXPECT_EQ(h, eh) << "chart " << n.chart << " level " << n.level;
    EXPECT_EQ(nr, en) << "chart " << n.chart << " level " << n.level;
  }

  static std::unique_ptr<test::TempDir> dir_;
  static std::unique_ptr<AtlasView> atlas_;
  static std::unique_ptr<PageReader> pages_;
};

std::unique_ptr<test::TempDir> PageLoaderTest::dir_;
std::unique_ptr<AtlasView> PageLoaderTest::atlas_;
std::unique_ptr<PageReader> PageLoaderTest::pages_;

const NodeId kRoot{0, 0, 0, 0};

TEST_F(PageLoaderTest, ServesHigherPriorityFirstAndDeduplicates) {
  PageLoader loader(*pages_, 64u << 20, /*startPaused=*/true);
  const NodeId a = kRoot, b = kRoot.child(1), c = kRoot.child(2), d = kRoot.child(3).child(0);
  loader.request(a, 1.0);
  loader.request(b, 5.0);
  loader.request(c, 3.0);
  loader.request(d, 4.0);
  loader.request(b, 5.0);   // duplicate: ignored
  loader.request(a, 10.0);  // re-request: raises a above everything
  loader.request(d, 2.0);   // re-request: lowers d below c
  EXPECT_EQ(loader.stats().requested, 4u);
  EXPECT_EQ(loader.stats().inFlight, 4u);
  EXPECT_TRUE(loader.takeCompleted(10).empty());
  loader.resume();
  loader.waitIdle();
  const std::vector<LoadedPage> done = loader.takeCompleted(10);
  ASSERT_EQ(done.size(), 4u);
  EXPECT_EQ(done[0].id.key(), a.key());
  EXPECT_EQ(done[1].id.key(), b.key());
  EXPECT_EQ(done[2].id.key(), c.key());
  EXPECT_EQ(done[3].id.key(), d.key());
  const PageLoaderStats s = loader.stats();
  EXPECT_EQ(s.loadedFromDisk, 4u);
  EXPECT_EQ(s.ramHits, 0u);
  EXPECT_EQ(s.inFlight, 0u);
  EXPECT_EQ(s.completed, 0u);
}

TEST_F(PageLoaderTest, TakeCompletedRespectsMaxAndCancelDropsQueued) {
  PageLoader loader(*pages_, 64u << 20, true);
  for (uint32_t i = 0; i < 4; ++i) loader.request(kRoot.child(i), double(i));
  loader.cancelPending();
  EXPECT_EQ(loader.stats().inFlight, 0u);
  for (uint32_t i = 0; i < 4; ++i) loader.request(kRoot.child(i), double(i));
  loader.resume();
  loader.waitIdle();
  EXPECT_EQ(loader.takeCompleted(3).size(), 3u);
  EXPECT_EQ(loader.takeCompleted(3).size(), 1u);
  EXPECT_TRUE(loader.takeCompleted(3).empty());
}

TEST_F(PageLoaderTest, DataEqualsDirectRead) {
  PageLoader loader(*pages_, 64u << 20);
  const Hierarchy& h = atlas_->hierarchy;
  std::vector<NodeId> nodes;
  for (uint32_t c = 0; c < h.chartCount(); ++c) {
    const NodeId r{c, 0, 0, 0};
    nodes.push_back(r);
    nodes.push_back(r.child(c % 4));
    nodes.push_back(r.child(3).child(c % 4));
  }
  for (size_t i = 0; i < nodes.size(); ++i) loader.request(nodes[i], double(i % 7));
  loader.waitIdle();
  const std::vector<LoadedPage> done = loader.takeCompleted(nodes.size());
  ASSERT_EQ(done.size(), nodes.size());
  for (const LoadedPage& p : done) {
    EXPECT_FALSE(p.fromRam);
    const uint32_t s = pages_->pageSamples(p.id);
    EXPECT_EQ(p.samples.size(), size_t(s) * s);
    expectPageEquals(p.id, p.samples, p.normals);
    std::vector<float> h2;
    std::vector<PackedNormal> n2;
    ASSERT_TRUE(loader.tryGetResident(p.id, h2, n2));
    EXPECT_EQ(h2, p.samples);
    EXPECT_EQ(n2, p.normals);
  }
  // A second request is served from RAM with the same data.
  loader.request(nodes[0], 1.0);
  loader.waitIdle();
  const std::vector<LoadedPage> again = loader.takeCompleted(10);
  ASSERT_EQ(again.size(), 1u);
  EXPECT_TRUE(again[0].fromRam);
  expectPageEquals(again[0].id, again[0].samples, again[0].normals);
  EXPECT_EQ(loader.stats().ramHits, 1u);
  EXPECT_EQ(loader.stats().loadedFromDisk, nodes.size());
}

TEST_F(PageLoaderTest, RamBudgetEvictsLeastRecentlyUsed) {
  // Room for exactly two level-2 pages.
  const NodeId x = kRoot.child(0).child(0), y = kRoot.child(0).child(1), z = kRoot.child(0).child(2);
  PageLoader loader(*pages_, 2 * pageBytes(2) + pageBytes(2) / 2);
  auto load = [&](const NodeId& n) {
    loader.request(n, 1.0);
    loader.waitIdle();
    EXPECT_EQ(loader.takeCompleted(10).size(), 1u);
  };
  std::vector<float> h;
  std::vector<PackedNormal> nr;
  load(x);
  load(y);
  EXPECT_TRUE(loader.tryGetResident(x, h, nr));  // x is now more recent than y
  load(z);                                        // evicts y
  EXPECT_TRUE(loader.tryGetResident(x, h, nr));
  EXPECT_FALSE(loader.tryGetResident(y, h, nr));
  EXPECT_TRUE(loader.tryGetResident(z, h, nr));
  expectPageEquals(z, h, nr);
  PageLoaderStats s = loader.stats();
  EXPECT_EQ(s.loadedFromDisk, 3u);
  EXPECT_EQ(s.ramEvictions, 1u);
  EXPECT_LE(s.ramBytes, 2 * pageBytes(2) + pageBytes(2) / 2);
  load(x);  // RAM hit: no disk read
  s = loader.stats();
  EXPECT_EQ(s.ramHits, 1u);
  EXPECT_EQ(s.loadedFromDisk, 3u);
  load(y);  // from disk again; evicts z (least recent)
  s = loader.stats();
  EXPECT_EQ(s.loadedFromDisk, 4u);
  EXPECT_FALSE(loader.tryGetResident(z, h, nr));
  EXPECT_TRUE(loader.tryGetResident(x, h, nr));
  // A zero budget caches nothing.
  PageLoader none(*pages_, 0);
  none.request(x, 1.0);
  none.waitIdle();
  EXPECT_EQ(none.takeCompleted(10).size(), 1u);
  EXPECT_FALSE(none.tryGetResident(x, h, nr));
}

TEST_F(PageLoaderTest, DestructorWithPendingRequestsReturns) {
  const Hierarchy& h = atlas_->hierarchy;
  std::vector<NodeId> all;
  for (uint32_t c = 0; c < h.chartCount(); ++c)
    for (uint32_t l = 0; l < h.params.depth; ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) all.push_back({c, l, x, y});
  // Run on another thread so that a destructor that waits for the queue fails the test instead
  // of hanging it (the bound is far above anything a working destructor takes).
  auto destroyAll = [&] {
    const uint64_t before = pages_->bytesRead();
    {
      PageLoader paused(*pages_, 1u << 20, true);
      for (const NodeId& n : all) paused.request(n, 1.0);
      EXPECT_EQ(paused.stats().inFlight, all.size());
    }  // must not wait for the queue
    EXPECT_EQ(pages_->bytesRead(), before) << "a paused loader read pages while being destroyed";
    uint64_t atDestruction = 0;
    {
      PageLoader running(*pages_, 1u << 20);
      for (const NodeId& n : all) running.request(n, double(n.level));
    }  // stops after at most the read in progress
    atDestruction = pages_->bytesRead();
    {
      PageLoader idle(*pages_, 1u << 20);  // thread waiting on an empty queue
    }
    // The loader threads are joined: nothing reads any more.
    EXPECT_EQ(pages_->bytesRead(), atDestruction);
  };
  std::future<void> done = std::async(std::launch::async, destroyAll);
  if (done.wait_for(std::chrono::seconds(120)) != std::future_status::ready) {
    // The future's destructor would wait for the stuck thread: end the test process instead.
    std::fprintf(stderr, "FAILED: a PageLoader destructor did not return within 120 s\n");
    std::_Exit(1);
  }
  done.get();
}

}  // namespace
}  // namespace gimlod

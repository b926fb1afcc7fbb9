// The asynchronous page loader (paper 7.2): priority order, data equal to direct reads, the RAM
// cache budget with LRU eviction, and prompt shutdown with requests pending.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>
#include <unordered_set>

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
  static void expectPageEquals(const NodeId& n, const std::vector<float>& h, const std::vector<PackedNormal>& nr) {
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
  load(z);                                       // evicts y
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

// Several threads read every page once, with the data of a direct read and the bytes PageReader
// says a page has.
TEST_F(PageLoaderTest, SeveralThreadsServeEveryRequestWithTheDirectData) {
  PageLoaderOptions o;
  o.threads = 3;
  o.ramBytes = 64u << 20;
  PageLoader loader(*pages_, o);
  const Hierarchy& h = atlas_->hierarchy;
  std::vector<NodeId> nodes;
  for (uint32_t c = 0; c < h.chartCount(); ++c)
    for (uint32_t l = 0; l < std::min(h.params.depth, 3u); ++l)
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) nodes.push_back({c, l, x, y});
  for (size_t i = 0; i < nodes.size(); ++i) loader.request(nodes[i], double(i % 5));
  loader.waitIdle();
  const std::vector<LoadedPage> done = loader.takeCompleted(nodes.size());
  ASSERT_EQ(done.size(), nodes.size());
  std::unordered_set<uint64_t> seen;
  for (const LoadedPage& p : done) {
    EXPECT_TRUE(seen.insert(p.id.key()).second) << "a page served twice";
    EXPECT_EQ(p.bytes(), pages_->pageBytes(p.id));
    expectPageEquals(p.id, p.samples, p.normals);
  }
  const PageLoaderStats s = loader.stats();
  EXPECT_EQ(s.loadedFromDisk, nodes.size());
  EXPECT_EQ(s.inFlight, 0u);
  EXPECT_EQ(s.stagedBytes, 0u);
}

// A request the frame no longer wants is dropped before its read: the pages read are the kept ones.
TEST_F(PageLoaderTest, RetainOnlyCancelsRequestsBeforeTheirRead) {
  PageLoaderOptions o;
  o.threads = 2;
  o.startPaused = true;
  PageLoader loader(*pages_, o);
  std::vector<NodeId> nodes;
  for (uint32_t i = 0; i < 4; ++i) {
    nodes.push_back(kRoot.child(i));
    nodes.push_back(kRoot.child(i).child(3 - i));
  }
  for (size_t i = 0; i < nodes.size(); ++i) loader.request(nodes[i], double(i));
  std::unordered_set<uint64_t> keep{nodes[1].key(), nodes[4].key(), nodes[6].key()};
  loader.retainOnly([&](uint64_t key) { return keep.count(key) != 0; });
  PageLoaderStats s = loader.stats();
  EXPECT_EQ(s.cancelled, nodes.size() - keep.size());
  EXPECT_EQ(s.inFlight, keep.size());
  const uint64_t before = pages_->bytesRead();
  loader.resume();
  loader.waitIdle();
  const std::vector<LoadedPage> done = loader.takeCompleted(nodes.size());
  ASSERT_EQ(done.size(), keep.size());
  for (const LoadedPage& p : done) EXPECT_TRUE(keep.count(p.id.key())) << "a cancelled page was read";
  s = loader.stats();
  EXPECT_EQ(s.loadedFromDisk, keep.size());
  EXPECT_GT(pages_->bytesRead(), before);
  // Cancelling everything leaves nothing to read.
  loader.pause();
  for (const NodeId& n : nodes) loader.request(n, 1.0);
  loader.cancelPending();
  EXPECT_EQ(loader.stats().inFlight, 0u);
}

// The finished pages waiting for the render thread stay within stagedBytes, and with the cache
// within ramBytes; taking pages lets the threads read on.
TEST_F(PageLoaderTest, StagedBytesBoundTheReadAhead) {
  const Hierarchy& h = atlas_->hierarchy;
  std::vector<NodeId> nodes;
  for (uint32_t c = 0; c < h.chartCount(); ++c)
    for (uint32_t i = 0; i < 4; ++i) nodes.push_back(NodeId{c, 0, 0, 0}.child(i));
  const size_t page = pages_->pageBytes(nodes[0]);
  PageLoaderOptions o;
  o.threads = 2;
  o.stagedBytes = 3 * page;
  o.ramBytes = 5 * page;
  PageLoader loader(*pages_, o);
  for (size_t i = 0; i < nodes.size(); ++i) loader.request(nodes[i], double(nodes.size() - i));
  size_t taken = 0;
  for (int round = 0; round < 1000 && taken < nodes.size(); ++round) {
    loader.waitIdle();
    const PageLoaderStats s = loader.stats();
    EXPECT_LE(s.stagedBytes, o.stagedBytes);
    EXPECT_LE(s.ramBytes + s.stagedBytes, o.ramBytes);
    if (s.inFlight > 0) {
      EXPECT_GT(s.stagedBytes + page, o.stagedBytes) << "held back with room to read";
    }
    taken += loader.takeCompleted(1).size();
  }
  EXPECT_EQ(taken, nodes.size());
  // Below one page, one read at a time still runs.
  PageLoaderOptions tiny = o;
  tiny.stagedBytes = page / 2;
  PageLoader slow(*pages_, tiny);
  slow.request(nodes[0], 1.0);
  slow.request(nodes[1], 1.0);
  slow.waitIdle();
  EXPECT_EQ(slow.stats().completed, 1u);
  EXPECT_EQ(slow.takeCompleted(4).size(), 1u);
  slow.waitIdle();
  EXPECT_EQ(slow.takeCompleted(4).size(), 1u);
}

// takeCompleted with a filter drops the finished pages no longer wanted and keeps within its byte
// limit (at least one page).
TEST_F(PageLoaderTest, TakeCompletedDropsUnwantedPagesAndKeepsToItsBytes) {
  PageLoader loader(*pages_, 64u << 20);
  std::vector<NodeId> nodes;
  for (uint32_t i = 0; i < 4; ++i) nodes.push_back(kRoot.child(i));
  for (const NodeId& n : nodes) loader.request(n, 1.0);
  loader.waitIdle();
  const size_t page = pages_->pageBytes(nodes[0]);
  auto notFirst = [&](uint64_t key) { return key != nodes[0].key(); };
  std::vector<LoadedPage> got = loader.takeCompleted(notFirst, 10, page / 2);
  ASSERT_EQ(got.size(), 1u);  // one page even past the bytes
  EXPECT_NE(got[0].id.key(), nodes[0].key());
  EXPECT_EQ(loader.stats().unwanted, 1u);
  got = loader.takeCompleted(notFirst, 10, 2 * page);
  EXPECT_EQ(got.size(), 2u);
  EXPECT_EQ(loader.stats().completed, 0u);
}

// Simulated slow storage: each disk read waits at least the latency; RAM hits do not read. With an
// I/O depth of 1 the one thread waits for each read in turn; with a depth of 3 the storage serves
// the three reads at once, and the thread decodes each as it arrives.
TEST_F(PageLoaderTest, SimulatedLatencyDelaysEveryDiskRead) {
  for (const uint32_t depth : {1u, 3u}) {
    SCOPED_TRACE("I/O depth " + std::to_string(depth));
    PageLoaderOptions o;
    o.threads = 1;
    o.ioLatencyMs = 50.0;
    o.ioJitterMs = 10.0;
    o.ioDepth = depth;
    o.startPaused = true;
    PageLoader loader(*pages_, o);
    for (uint32_t i = 0; i < 3; ++i) loader.request(kRoot.child(i), 1.0);
    const auto t0 = std::chrono::steady_clock::now();
    loader.resume();
    loader.waitIdle();
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_GE(ms, (depth == 1 ? 3 : 1) * o.ioLatencyMs);
    EXPECT_EQ(loader.stats().ioPeak, depth);
    EXPECT_EQ(loader.stats().loadedFromDisk, 3u);
    EXPECT_EQ(loader.takeCompleted(10).size(), 3u);
  }
  PageLoaderOptions o;
  o.threads = 1;
  o.ioLatencyMs = 25.0;
  PageLoader loader(*pages_, o);
  for (uint32_t i = 0; i < 3; ++i) loader.request(kRoot.child(i), 1.0);
  loader.waitIdle();
  EXPECT_EQ(loader.takeCompleted(10).size(), 3u);
  loader.request(kRoot.child(0), 1.0);
  loader.waitIdle();
  const std::vector<LoadedPage> again = loader.takeCompleted(10);
  ASSERT_EQ(again.size(), 1u);
  EXPECT_TRUE(again[0].fromRam);
}

// A page whose block is corrupt on disk is reported once, with the file's name, is not read again,
// and does not stop the other pages.
TEST_F(PageLoaderTest, ACorruptPageIsReportedOnceAndNotReadAgain) {
  test::TempDir copy("gimlod-loader-corrupt");
  std::filesystem::copy(atlas_->dir, copy.path() / "atlas", std::filesystem::copy_options::recursive);
  const AtlasView atlas = openAtlas(copy.path() / "atlas");
  PageReader reader(atlas.dir, atlas.manifest, atlas.hierarchy.params);
  // Every byte past the chart file's first quarter becomes garbage: some blocks cannot decode.
  std::filesystem::path chart;
  for (const auto& e : std::filesystem::directory_iterator(atlas.dir / "charts")) {
    if (chart.empty() || e.path() < chart) chart = e.path();
  }
  ASSERT_FALSE(chart.empty());
  {
    const auto size = std::filesystem::file_size(chart);
    std::fstream f(chart, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(size / 4));
    for (uint64_t i = size / 4; i < size; ++i) f.put(char(0xA5 ^ (i * 131)));
  }
  const uint32_t c = 0;
  std::vector<NodeId> nodes;
  for (uint32_t l = 0; l < atlas.hierarchy.params.depth; ++l)
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x) nodes.push_back({c, l, x, y});
  nodes.push_back({atlas.hierarchy.chartCount() - 1, 1, 0, 0});  // another chart's page reads
  std::vector<PageFailure> told;
  std::mutex toldMutex;
  PageLoaderOptions o;
  o.threads = 2;
  o.onFailure = [&](const PageFailure& f) {
    std::lock_guard<std::mutex> lock(toldMutex);
    told.push_back(f);
  };
  PageLoader loader(reader, o);
  for (const NodeId& n : nodes) loader.request(n, 1.0);
  loader.waitIdle();
  const std::vector<PageFailure> failures = loader.failures();
  ASSERT_GT(failures.size(), 0u) << "garbage in the chart file went unnoticed";
  EXPECT_EQ(told.size(), failures.size());
  for (const PageFailure& f : failures) {
    EXPECT_EQ(f.id.chart, c);
    EXPECT_NE(f.message.find(chart.filename().string()), std::string::npos) << f.message;
  }
  const std::vector<LoadedPage> done = loader.takeCompleted(nodes.size());
  EXPECT_EQ(done.size() + failures.size(), nodes.size());
  bool otherChart = false;
  for (const LoadedPage& p : done) otherChart = otherChart || p.id.chart != c;
  EXPECT_TRUE(otherChart);
  // Asked again, the failed pages are not read again, nor reported again.
  const uint64_t before = reader.bytesRead();
  for (const PageFailure& f : failures) loader.request(f.id, 2.0);
  loader.waitIdle();
  EXPECT_EQ(reader.bytesRead(), before);
  EXPECT_EQ(loader.failures().size(), failures.size());
  EXPECT_EQ(loader.stats().failed, failures.size());
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

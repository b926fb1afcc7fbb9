// Asynchronous node-page loading: a prioritized request queue served by loader threads, with a
// byte-budgeted RAM cache of recently read pages in front of the disk (paper section 7.2). Pages
// are read and decoded on the loader threads; the render thread only takes finished pages. Pure
// C++, no GL.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <list>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "runtime/normal_mips.h"
#include "runtime/page_reader.h"

namespace gimlod {

// A page read by the loader, waiting for the render thread to upload it.
struct LoadedPage {
  NodeId id;
  std::vector<float> samples;
  std::vector<PackedNormal> normals;
  std::vector<PackedColour> colours;  // empty unless the atlas has colours
  PageMips mips;                      // made by PageLoaderOptions::prepare, if set
  bool fromRam = false;               // served by the RAM cache, not the disk
  size_t bytes() const {
    return samples.size() * sizeof(float) + normals.size() * sizeof(PackedNormal) +
           colours.size() * sizeof(PackedColour) + mips.bytes();
  }
};

// A page that could not be read (a corrupt or truncated block, a file gone): the reader's message,
// which names the file.
struct PageFailure {
  NodeId id;
  std::string message;
};

struct PageLoaderOptions {
  // The RAM the loader holds: its cache of read pages and the finished pages waiting for the
  // render thread (staged). 0: no cache (staged pages are then not bounded by it).
  size_t ramBytes = size_t(256) << 20;
  // Finished pages may wait for the render thread up to this many bytes; the threads start no
  // read past it. It is taken out of ramBytes, so the cache gets the rest. 0: unbounded, and not
  // counted in ramBytes (the cache alone is).
  size_t stagedBytes = 0;
  uint32_t threads = 1;  // loader threads (at least 1)
  // Simulated slow storage: every disk read first waits latency plus a uniform random share of
  // jitter (milliseconds). RAM hits do not wait. The storage serves up to ioDepth requests at
  // once, as an asynchronous reader keeps that many in flight against a slow disk or a network
  // (the threads decode what arrives); 1: each thread waits for its own read.
  double ioLatencyMs = 0.0, ioJitterMs = 0.0;
  uint32_t ioDepth = 32;
  bool startPaused = false;  // serve nothing until resume()
  // Called once for each page whose read fails, on the loader thread that read it (no lock
  // held): where the caller logs it.
  std::function<void(const PageFailure&)> onFailure;
  // Work on a page before the render thread takes it, on the loader thread that read it (no lock
  // held): making its mips. preparedBytes, if set, is what it adds to a page's bytes, so the
  // staged bytes are known before the read.
  std::function<void(LoadedPage&)> prepare;
  std::function<size_t(const NodeId&)> preparedBytes;
};

struct PageLoaderStats {
  uint64_t requested = 0;       // distinct requests accepted (duplicates not counted)
  uint64_t loadedFromDisk = 0;  // pages read through PageReader::read
  uint64_t ramHits = 0;         // requests served by the RAM cache
  uint64_t failed = 0;          // pages whose read threw: never requested again (failures())
  uint64_t cancelled = 0;       // queued requests dropped before their read (retainOnly, cancelPending)
  uint64_t unwanted = 0;        // finished pages dropped by takeCompleted as no longer wanted
  uint64_t ramEvictions = 0;    // pages dropped from the RAM cache for the budget
  uint64_t ramBytes = 0;        // bytes now held by the RAM cache
  uint64_t stagedBytes = 0;     // bytes of finished pages waiting in takeCompleted
  uint32_t inFlight = 0;        // requests queued or being read
  uint32_t completed = 0;       // pages waiting in takeCompleted
  uint32_t ioPeak = 0;          // the most reads the simulated storage served at once
};

class PageLoader {
 public:
  // Starts the loader threads; `pages` must outlive the loader.
  PageLoader(const PageReader& pages, const PageLoaderOptions& options);
  // One thread, a RAM cache of ramBudgetBytes (0 disables it), staged pages unbounded.
  PageLoader(const PageReader& pages, size_t ramBudgetBytes, bool startPaused = false);
  // Stops the threads promptly: pending requests are dropped, reads in progress finish.
  ~PageLoader();
  PageLoader(const PageLoader&) = delete;
  PageLoader& operator=(const PageLoader&) = delete;

  // Queues n with `priority` (higher is served first). A request for a node already queued
  // updates its priority; one being read, waiting in takeCompleted or failed before is ignored.
  void request(const NodeId& n, double priority);
  // Drops every queued request that no thread has started (reads in progress finish).
  void cancelPending();
  // Drops the queued requests whose key `keep` rejects (counted in cancelled).
  void retainOnly(const std::function<bool(uint64_t key)>& keep);
  // Moves up to `max` finished pages out, oldest first. For the render thread.
  std::vector<LoadedPage> takeCompleted(size_t max);
  // The same, dropping the finished pages `wanted` rejects (counted in unwanted) and stopping
  // before a page would take the bytes past maxBytes (but always taking one wanted page); the
  // others wait. With `first`, the wanted pages it accepts are taken before the rest (a frame's
  // own pages before prefetched ones).
  std::vector<LoadedPage> takeCompleted(const std::function<bool(uint64_t key)>& wanted, size_t maxPages,
                                        size_t maxBytes, const std::function<bool(uint64_t key)>& first = {});
  // Copies n's page from the RAM cache; false (outputs untouched) when it is not there.
  bool tryGetResident(const NodeId& n, std::vector<float>& samples, std::vector<PackedNormal>& normals,
                      std::vector<PackedColour>* colours = nullptr);

  // Stops / restarts serving the queue (reads in progress finish). For tests and throttling.
  void pause();
  void resume();
  // Blocks until nothing is queued or being read (or, while paused or held back by the staged
  // bytes, nothing is being read).
  void waitIdle();

  PageLoaderStats stats() const;
  // The pages that failed, in the order they failed (each logged once when it failed).
  std::vector<PageFailure> failures() const;

 private:
  struct Queued {
    double priority;
    uint64_t seq;  // FIFO among equal priorities
    NodeId id;
    bool operator<(const Queued& o) const { return priority != o.priority ? priority > o.priority : seq < o.seq; }
  };
  void run(uint32_t thread);
  // Reads and decodes q's page (whose key is in reading_), unlocking `lock` meanwhile, and files
  // it as finished or failed.
  void readPage(const Queued& q, std::unique_lock<std::mutex>& lock);
  bool canStart() const;                        // mutex_ held
  size_t stagedBytesOf(const NodeId& n) const;  // a page's bytes once read and prepared
  size_t cacheBudget() const;
  void insertRam(LoadedPage&& page);  // a page as read (no mips)
  void finish(LoadedPage&& page);

  const PageReader& pages_;
  const PageLoaderOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;  // the loader threads wait here
  std::condition_variable idle_;  // waitIdle waits here
  bool stop_ = false, paused_ = false;
  std::set<Queued> queue_;
  std::unordered_map<uint64_t, std::set<Queued>::iterator> queued_;
  uint64_t seq_ = 0;
  std::unordered_set<uint64_t> reading_;  // keys being read (issued to the simulated storage too)
  // Requests the simulated storage is serving, by the time their data arrives.
  std::multimap<std::chrono::steady_clock::time_point, Queued> issued_;
  std::deque<LoadedPage> completed_;
  std::unordered_set<uint64_t> completedKeys_;
  std::list<LoadedPage> ram_;  // front = most recent
  std::unordered_map<uint64_t, std::list<LoadedPage>::iterator> ramIndex_;
  std::unordered_set<uint64_t> failedKeys_;
  std::vector<PageFailure> failures_;
  PageLoaderStats stats_;
  std::vector<std::thread> threads_;  // last: start after every other member is constructed
};

}  // namespace gimlod

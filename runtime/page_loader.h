// Asynchronous node-page loading: a prioritized request queue served by one loader thread, with
// a RAM cache of recently read pages in front of the disk (paper section 7.2). Pure C++, no GL.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <list>
#include <mutex>
#include <set>
#include <thread>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "runtime/page_reader.h"

namespace gimlod {

// A page read by the loader, waiting for the render thread to upload it.
struct LoadedPage {
  NodeId id;
  std::vector<float> samples;
  std::vector<PackedNormal> normals;
  std::vector<PackedColour> colours;  // empty unless the atlas has colours
  bool fromRam = false;  // served by the RAM cache, not the disk
};

struct PageLoaderStats {
  uint64_t requested = 0;       // distinct requests accepted (duplicates not counted)
  uint64_t loadedFromDisk = 0;  // pages read through PageReader::read
  uint64_t ramHits = 0;         // requests served by the RAM cache
  uint64_t failed = 0;          // disk reads that threw (dropped)
  uint64_t ramEvictions = 0;    // pages dropped from the RAM cache for the budget
  uint64_t ramBytes = 0;        // bytes now held by the RAM cache
  uint32_t inFlight = 0;        // requests queued or being read
  uint32_t completed = 0;       // pages waiting in takeCompleted
};

class PageLoader {
 public:
  // Starts the loader thread; `pages` must outlive the loader. ramBudgetBytes bounds the RAM
  // cache (0 disables it). With startPaused the thread serves nothing until resume().
  PageLoader(const PageReader& pages, size_t ramBudgetBytes, bool startPaused = false);
  // Stops the thread promptly: pending requests are dropped, a read in progress finishes.
  ~PageLoader();
  PageLoader(const PageLoader&) = delete;
  PageLoader& operator=(const PageLoader&) = delete;

  // Queues n with `priority` (higher is served first). A request for a node already queued
  // updates its priority; one being read or waiting in takeCompleted is ignored.
  void request(const NodeId& n, double priority);
  // Drops every queued request that the thread has not started (a read in progress finishes).
  void cancelPending();
  // Moves up to `max` finished pages out, oldest first. For the render thread.
  std::vector<LoadedPage> takeCompleted(size_t max);
  // Copies n's page from the RAM cache; false (outputs untouched) when it is not there.
  bool tryGetResident(const NodeId& n, std::vector<float>& samples,
                      std::vector<PackedNormal>& normals, std::vector<PackedColour>* colours = nullptr);

  // Stops / restarts serving the queue (a read in progress finishes). For tests and throttling.
  void pause();
  void resume();
  // Blocks until nothing is queued or being read (or, while paused, nothing is being read).
  void waitIdle();

  PageLoaderStats stats() const;

 private:
  struct Queued {
    double priority;
    uint64_t seq;  // FIFO among equal priorities
    NodeId id;
    bool operator<(const Queued& o) const {
      return priority != o.priority ? priority > o.priority : seq < o.seq;
    }
  };
  struct RamPage {
    uint64_t key;
    std::vector<float> samples;
    std::vector<PackedNormal> normals;
    std::vector<PackedColour> colours;
    size_t bytes() const {
      return samples.size() * sizeof(float) + normals.size() * sizeof(PackedNormal) +
             colours.size() * sizeof(PackedColour);
    }
  };
  void run();
  void insertRam(uint64_t key, const LoadedPage& page);

  const PageReader& pages_;
  const size_t ramBudget_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;  // the loader thread waits here
  std::condition_variable idle_;  // waitIdle waits here
  bool stop_ = false, paused_ = false;
  std::set<Queued> queue_;
  std::unordered_map<uint64_t, std::set<Queued>::iterator> queued_;
  uint64_t seq_ = 0;
  bool reading_ = false;
  uint64_t readingKey_ = 0;
  std::deque<LoadedPage> completed_;
  std::unordered_set<uint64_t> completedKeys_;
  std::list<RamPage> ram_;  // front = most recent
  std::unordered_map<uint64_t, std::list<RamPage>::iterator> ramIndex_;
  PageLoaderStats stats_;
  std::thread thread_;  // last: starts after every other member is constructed
};

}  // namespace gimlod

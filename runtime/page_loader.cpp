// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.2 (Data Management): pages are requested
// by priority, read by a separate thread into a RAM cache, and uploaded by the render thread.
#include "runtime/page_loader.h"

#include <algorithm>

namespace gimlod {

PageLoader::PageLoader(const PageReader& pages, size_t ramBudgetBytes, bool startPaused)
    : pages_(pages), ramBudget_(ramBudgetBytes), paused_(startPaused) {
  thread_ = std::thread([this] { run(); });
}

PageLoader::~PageLoader() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void PageLoader::request(const NodeId& n, double priority) {
  const uint64_t key = n.key();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if ((reading_ && readingKey_ == key) || completedKeys_.count(key)) return;
    auto it = queued_.find(key);
    if (it != queued_.end()) {
      if (it->second->priority == priority) return;
      const uint64_t seq = it->second->seq;
      queue_.erase(it->second);
      it->second = queue_.insert({priority, seq, n}).first;
      return;
    }
    queued_[key] = queue_.insert({priority, seq_++, n}).first;
    ++stats_.requested;
  }
  wake_.notify_one();
}

void PageLoader::cancelPending() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.clear();
    queued_.clear();
  }
  idle_.notify_all();
}

std::vector<LoadedPage> PageLoader::takeCompleted(size_t max) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<LoadedPage> out;
  const size_t n = std::min(max, completed_.size());
  out.reserve(n);
  for (size_t i = 0; i < n; ++i) {
    completedKeys_.erase(completed_.front().id.key());
    out.push_back(std::move(completed_.front()));
    completed_.pop_front();
  }
  return out;
}

bool PageLoader::tryGetResident(const NodeId& n, std::vector<float>& samples,
                                std::vector<PackedNormal>& normals, std::vector<PackedColour>* colours) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = ramIndex_.find(n.key());
  if (it == ramIndex_.end()) return false;
  ram_.splice(ram_.begin(), ram_, it->second);
  samples = it->second->samples;
  normals = it->second->normals;
  if (colours) *colours = it->second->colours;
  return true;
}

void PageLoader::pause() {
  std::lock_guard<std::mutex> lock(mutex_);
  paused_ = true;
}

void PageLoader::resume() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    paused_ = false;
  }
  wake_.notify_all();
}

void PageLoader::waitIdle() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [this] { return !reading_ && (queue_.empty() || paused_ || stop_); });
}

PageLoaderStats PageLoader::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  PageLoaderStats s = stats_;
  s.inFlight = uint32_t(queue_.size()) + (reading_ ? 1u : 0u);
  s.completed = uint32_t(completed_.size());
  return s;
}

void PageLoader::insertRam(uint64_t key, const LoadedPage& loaded) {
  // Caller holds mutex_.
  RamPage page{key, loaded.samples, loaded.normals, loaded.colours};
  const size_t bytes = page.bytes();
  if (bytes > ramBudget_ || ramIndex_.count(key)) return;
  while (stats_.ramBytes + bytes > ramBudget_ && !ram_.empty()) {
    stats_.ramBytes -= ram_.back().bytes();
    ramIndex_.erase(ram_.back().key);
    ram_.pop_back();
    ++stats_.ramEvictions;
  }
  ram_.push_front(std::move(page));
  ramIndex_[key] = ram_.begin();
  stats_.ramBytes += bytes;
}

void PageLoader::run() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || (!paused_ && !queue_.empty()); });
    if (stop_) break;
    const Queued q = *queue_.begin();
    const uint64_t key = q.id.key();
    queue_.erase(queue_.begin());
    queued_.erase(key);
    reading_ = true;
    readingKey_ = key;
    LoadedPage page;
    page.id = q.id;
    auto hit = ramIndex_.find(key);
    if (hit != ramIndex_.end()) {
      ram_.splice(ram_.begin(), ram_, hit->second);
      page.samples = hit->second->samples;
      page.normals = hit->second->normals;
      page.colours = hit->second->colours;
      page.fromRam = true;
      ++stats_.ramHits;
    } else {
      // note: the disk read runs unlocked, so request()/takeCompleted() never wait on the disk.
      lock.unlock();
      bool ok = true;
      try {
        pages_.read(q.id, page.samples, page.normals, &page.colours);
      } catch (...) {
        ok = false;  // note: a failed read is counted and dropped; a later request retries it
      }
      lock.lock();
      if (ok) {
        ++stats_.loadedFromDisk;
        insertRam(key, page);
      } else {
        ++stats_.failed;
      }
      if (!ok) {
        reading_ = false;
        idle_.notify_all();
        continue;
      }
    }
    completedKeys_.insert(key);
    completed_.push_back(std::move(page));
    reading_ = false;
    idle_.notify_all();
  }
  reading_ = false;
  idle_.notify_all();
}

}  // namespace gimlod

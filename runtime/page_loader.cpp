// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.2 (Data Management): pages are requested
// by priority, read by separate threads into a RAM cache, and uploaded by the render thread.
#include "runtime/page_loader.h"

#include <algorithm>
#include <chrono>
#include <exception>
#include <random>

namespace gimlod {

PageLoader::PageLoader(const PageReader& pages, const PageLoaderOptions& options)
    : pages_(pages), options_(options), paused_(options.startPaused) {
  const uint32_t n = std::max(options_.threads, 1u);
  threads_.reserve(n);
  for (uint32_t t = 0; t < n; ++t) threads_.emplace_back([this, t] { run(t); });
}

namespace {
PageLoaderOptions singleThread(size_t ramBudgetBytes, bool startPaused) {
  PageLoaderOptions o;
  o.ramBytes = ramBudgetBytes;
  o.startPaused = startPaused;
  return o;
}
}  // namespace

PageLoader::PageLoader(const PageReader& pages, size_t ramBudgetBytes, bool startPaused)
    : PageLoader(pages, singleThread(ramBudgetBytes, startPaused)) {}

PageLoader::~PageLoader() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (std::thread& t : threads_) t.join();
}

void PageLoader::request(const NodeId& n, double priority) {
  const uint64_t key = n.key();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (reading_.count(key) || completedKeys_.count(key) || failedKeys_.count(key)) return;
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
  retainOnly([](uint64_t) { return false; });
}

void PageLoader::retainOnly(const std::function<bool(uint64_t key)>& keep) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = queue_.begin(); it != queue_.end();) {
      const uint64_t key = it->id.key();
      if (keep(key)) {
        ++it;
        continue;
      }
      queued_.erase(key);
      it = queue_.erase(it);
      ++stats_.cancelled;
    }
  }
  idle_.notify_all();
}

std::vector<LoadedPage> PageLoader::takeCompleted(size_t max) {
  return takeCompleted([](uint64_t) { return true; }, max, SIZE_MAX);
}

std::vector<LoadedPage> PageLoader::takeCompleted(const std::function<bool(uint64_t key)>& wanted, size_t maxPages,
                                                  size_t maxBytes, const std::function<bool(uint64_t key)>& first) {
  std::vector<LoadedPage> out;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    size_t bytes = 0;
    // With `first`: its pages in a first pass, the other wanted ones in a second.
    for (int pass = 0; pass < (first ? 2 : 1); ++pass) {
      std::deque<LoadedPage> kept;
      for (LoadedPage& pg : completed_) {
        const size_t b = pg.bytes();
        const uint64_t key = pg.id.key();
        const bool now = !first || pass == 1 || first(key);
        if (!wanted(key)) {
          ++stats_.unwanted;
        } else if (now && out.size() < maxPages && (out.empty() || bytes + b <= maxBytes)) {
          bytes += b;
          out.push_back(std::move(pg));
        } else {
          kept.push_back(std::move(pg));
          continue;
        }
        completedKeys_.erase(key);
        stats_.stagedBytes -= b;
      }
      completed_.swap(kept);
    }
  }
  wake_.notify_all();  // room for reads held back by the staged bytes
  return out;
}

bool PageLoader::tryGetResident(const NodeId& n, std::vector<float>& samples, std::vector<PackedNormal>& normals,
                                std::vector<PackedColour>* colours) {
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
  idle_.wait(lock, [this] { return reading_.empty() && (stop_ || !canStart()); });
}

PageLoaderStats PageLoader::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  PageLoaderStats s = stats_;
  s.inFlight = uint32_t(queue_.size() + reading_.size());
  s.completed = uint32_t(completed_.size());
  return s;
}

std::vector<PageFailure> PageLoader::failures() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return failures_;
}

size_t PageLoader::cacheBudget() const {
  if (options_.stagedBytes == 0) return options_.ramBytes;
  return options_.ramBytes > options_.stagedBytes ? options_.ramBytes - options_.stagedBytes : 0;
}

bool PageLoader::canStart() const {
  if (paused_ || queue_.empty()) return false;
  if (options_.stagedBytes == 0) return true;
  // The reads in progress count as staged already (their bytes are known before the read); one
  // read may always run when nothing waits, so a cap below one page still makes progress.
  size_t ahead = stats_.stagedBytes;
  for (uint64_t key : reading_) ahead += stagedBytesOf(NodeId::fromKey(key));
  if (ahead == 0) return true;
  return ahead + stagedBytesOf(queue_.begin()->id) <= options_.stagedBytes;
}

size_t PageLoader::stagedBytesOf(const NodeId& n) const {
  return pages_.pageBytes(n) + (options_.preparedBytes ? options_.preparedBytes(n) : 0);
}

void PageLoader::insertRam(LoadedPage&& page) {
  // Caller holds mutex_.
  const size_t budget = cacheBudget();
  const uint64_t key = page.id.key();
  const size_t bytes = page.bytes();
  if (bytes > budget || ramIndex_.count(key)) return;
  while (stats_.ramBytes + bytes > budget && !ram_.empty()) {
    stats_.ramBytes -= ram_.back().bytes();
    ramIndex_.erase(ram_.back().id.key());
    ram_.pop_back();
    ++stats_.ramEvictions;
  }
  ram_.push_front(std::move(page));
  ramIndex_[key] = ram_.begin();
  stats_.ramBytes += bytes;
}

void PageLoader::finish(LoadedPage&& page) {
  // Caller holds mutex_.
  completedKeys_.insert(page.id.key());
  stats_.stagedBytes += page.bytes();
  completed_.push_back(std::move(page));
}

void PageLoader::run(uint32_t thread) {
  std::mt19937 random(thread + 1);  // the simulated latency's jitter, per thread
  std::uniform_real_distribution<double> share(0.0, 1.0);
  using Clock = std::chrono::steady_clock;
  const bool slow = options_.ioLatencyMs > 0.0 || options_.ioJitterMs > 0.0;
  const size_t depth = std::max<uint32_t>(options_.ioDepth, 1);
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    if (stop_) break;
    // 1. A read the simulated storage has answered: decode it.
    if (!issued_.empty() && issued_.begin()->first <= Clock::now()) {
      const Queued q = issued_.begin()->second;
      issued_.erase(issued_.begin());
      readPage(q, lock);
      continue;
    }
    // 2. The next request: a RAM hit is served now; a disk read starts now, or with the simulated
    // storage is issued to it while it has room.
    if (canStart() && (!slow || issued_.size() < depth)) {
      const Queued q = *queue_.begin();
      const uint64_t key = q.id.key();
      queue_.erase(queue_.begin());
      queued_.erase(key);
      reading_.insert(key);
      auto hit = ramIndex_.find(key);
      if (hit != ramIndex_.end()) {
        ram_.splice(ram_.begin(), ram_, hit->second);
        LoadedPage page = *hit->second;
        page.fromRam = true;
        ++stats_.ramHits;
        if (options_.prepare) {
          lock.unlock();
          options_.prepare(page);
          lock.lock();
        }
        reading_.erase(key);
        finish(std::move(page));
        idle_.notify_all();
      } else if (slow) {
        const double waitMs = options_.ioLatencyMs + options_.ioJitterMs * share(random);
        issued_.emplace(Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double, std::milli>(waitMs)),
                        q);
        stats_.ioPeak = std::max(stats_.ioPeak, uint32_t(issued_.size()));
        wake_.notify_all();  // another thread may sleep until a later answer
      } else {
        readPage(q, lock);
      }
      continue;
    }
    // 3. Nothing to do now: wait for a request, a stop, or the storage's next answer.
    if (issued_.empty())
      wake_.wait(lock);
    else
      wake_.wait_until(lock, issued_.begin()->first);
  }
  idle_.notify_all();
}

void PageLoader::readPage(const Queued& q, std::unique_lock<std::mutex>& lock) {
  const uint64_t key = q.id.key();
  LoadedPage page;
  page.id = q.id;
  // note: the disk read and its decoding run unlocked, so request()/takeCompleted() never wait
  // on the disk.
  lock.unlock();
  std::string error;
  try {
    pages_.read(q.id, page.samples, page.normals, &page.colours);
  } catch (const std::exception& e) {
    error = e.what();
    if (error.empty()) error = "unreadable page";
  } catch (...) {
    error = "unreadable page";
  }
  if (!error.empty() && options_.onFailure) options_.onFailure({q.id, error});
  LoadedPage cached;  // the page as read, for the cache (without what prepare adds), copied unlocked
  if (error.empty()) {
    cached = page;
    if (options_.prepare) options_.prepare(page);
  }
  lock.lock();
  reading_.erase(key);
  if (error.empty()) {
    ++stats_.loadedFromDisk;
    insertRam(std::move(cached));
    finish(std::move(page));
  } else {
    // note: a failed page is not read again (the node stays on a coarser stand-in); a request
    // for it is ignored.
    ++stats_.failed;
    failedKeys_.insert(key);
    failures_.push_back({q.id, std::move(error)});
  }
  idle_.notify_all();
  wake_.notify_all();
}

}  // namespace gimlod

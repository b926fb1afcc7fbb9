#include "core/progress.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <vector>

namespace gimlod::progress {
namespace {

using Clock = std::chrono::steady_clock;

struct StageState {
  std::string name;
  uint64_t total = 0;
  std::atomic<uint64_t> done{0};
  Clock::time_point start = Clock::now();
  std::atomic<int64_t> lastReportNs{0};  // since start
};

struct Registry {
  std::mutex mutex;  // guards the stack and serialises the sink
  Sink sink;
  double interval = 1.0;
  std::vector<std::unique_ptr<StageState>> stack;
  std::atomic<StageState*> current{nullptr};
};

Registry& registry() {
  static Registry r;
  return r;
}

Report reportOf(const StageState& s, bool finished) {
  Report r;
  r.stage = s.name;
  r.total = s.total;
  r.done = std::min(s.done.load(), s.total);
  r.seconds = std::chrono::duration<double>(Clock::now() - s.start).count();
  r.finished = finished;
  if (finished)
    r.etaSeconds = 0.0;
  else if (r.done > 0 && r.total > 0)
    r.etaSeconds = r.seconds * double(r.total - r.done) / double(r.done);
  return r;
}

std::string duration(double s) {
  char buf[32];
  if (s < 60)
    std::snprintf(buf, sizeof buf, "%.0f s", s);
  else if (s < 3600)
    std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else
    std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, int(s) / 60 % 60);
  return buf;
}

}  // namespace

void setSink(Sink sink, double intervalSeconds) {
  Registry& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  r.sink = std::move(sink);
  r.interval = std::max(intervalSeconds, 0.0);
}

ProgressStage::ProgressStage(std::string name, uint64_t total) {
  Registry& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  auto s = std::make_unique<StageState>();
  s->name = std::move(name);
  s->total = total;
  r.current = s.get();
  r.stack.push_back(std::move(s));
}

ProgressStage::~ProgressStage() {
  Registry& r = registry();
  std::lock_guard<std::mutex> lock(r.mutex);
  if (r.stack.empty()) return;
  if (r.sink) r.sink(reportOf(*r.stack.back(), true));
  r.stack.pop_back();
  r.current = r.stack.empty() ? nullptr : r.stack.back().get();
}

void advance(uint64_t n) {
  Registry& r = registry();
  StageState* s = r.current.load(std::memory_order_acquire);
  if (!s) return;
  s->done.fetch_add(n, std::memory_order_relaxed);
  // Report when the interval has passed since the last report; one thread wins the slot.
  const int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - s->start).count();
  int64_t last = s->lastReportNs.load(std::memory_order_relaxed);
  if (double(now - last) * 1e-9 < r.interval) return;
  if (!s->lastReportNs.compare_exchange_strong(last, now)) return;
  std::unique_lock<std::mutex> lock(r.mutex, std::try_to_lock);
  if (!lock.owns_lock() || !r.sink || r.current.load() != s) return;
  r.sink(reportOf(*s, false));
}

std::string format(const Report& r, int width) {
  const double frac = r.total > 0 ? double(r.done) / double(r.total) : (r.finished ? 1.0 : 0.0);
  std::string bar;
  if (width > 0) {
    const int full = int(std::lround(frac * width));
    bar = " [" + std::string(size_t(full), '#') + std::string(size_t(width - full), '.') + "]";
  }
  char buf[160];
  std::snprintf(buf, sizeof buf, "%s%s %3.0f%% %llu/%llu, %s", r.stage.c_str(), bar.c_str(), 100.0 * frac,
                static_cast<unsigned long long>(r.done), static_cast<unsigned long long>(r.total),
                duration(r.seconds).c_str());
  std::string out = buf;
  if (r.finished)
    out += ", done";
  else if (r.etaSeconds >= 0.0)
    out += ", ETA " + duration(r.etaSeconds);
  return out;
}

}  // namespace gimlod::progress

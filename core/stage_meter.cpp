#include "core/stage_meter.h"

#include <unistd.h>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace gimlod {
namespace {

// A kB figure ("VmHWM:", "VmRSS:") of /proc/self/status, in bytes; 0 where unavailable.
uint64_t procStatusBytes(const char* key) {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return 0;
  char line[256];
  uint64_t kb = 0;
  const size_t n = std::strlen(key);
  while (std::fgets(line, sizeof line, f))
    if (std::strncmp(line, key, n) == 0) {
      kb = std::strtoull(line + n, nullptr, 10);
      break;
    }
  std::fclose(f);
  return kb * 1024;
}

}  // namespace

// A sanitizer's allocator (which replaces malloc, so malloc_trim reaches nothing) holds freed blocks in
// its quarantine and hands its free pages back on a timer of its own; this hands them back now, so that
// what the process holds does not fall later of its own accord. Null without a sanitizer.
extern "C" void __sanitizer_purge_allocator() __attribute__((weak));

uint64_t residentBytes() { return procStatusBytes("VmRSS:"); }

uint64_t peakResidentBytes() { return procStatusBytes("VmHWM:"); }

uint64_t physicalMemoryBytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), size = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && size > 0 ? uint64_t(pages) * uint64_t(size) : 0;
}

void releaseFreedMemory() {
  if (__sanitizer_purge_allocator) {
    __sanitizer_purge_allocator();
    return;
  }
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

StageMeter::StageMeter() {
  sampler_ = std::thread([this] {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stop_) {
      lock.unlock();
      const uint64_t rss = residentBytes();
      lock.lock();
      stagePeak_ = std::max(stagePeak_, rss);
      wake_.wait_for(lock, std::chrono::milliseconds(5));
    }
  });
}

StageMeter::~StageMeter() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  sampler_.join();
}

void StageMeter::start() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stagePeak_ = residentBytes();
  }
  hwm0_ = peakResidentBytes();
  t0_ = std::chrono::steady_clock::now();
  cpu0_ = std::clock();
}

const StageTiming& StageMeter::finish(const std::string& name) {
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
  const double cpu = double(std::clock() - cpu0_) / CLOCKS_PER_SEC;
  const uint64_t hwm = peakResidentBytes();
  uint64_t peak = residentBytes();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    peak = std::max(peak, stagePeak_);
  }
  if (hwm > hwm0_) peak = std::max(peak, hwm);  // the process peak was reached in this stage
  stages_.push_back({name, wall, cpu, peak});
  largestStagePeak_ = std::max(largestStagePeak_, peak);
  start();
  return stages_.back();
}

uint64_t StageMeter::peak() const { return std::max(peakResidentBytes(), largestStagePeak_); }

}  // namespace gimlod

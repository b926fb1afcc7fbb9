// Per-stage wall time, CPU time and peak resident memory of a long-running build, read from
// /proc/self/status (Linux; the memory figures are 0 elsewhere).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <ctime>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace gimlod {

// The process's resident set size (VmRSS) in bytes; 0 where unavailable.
uint64_t residentBytes();

// The process's peak resident set size so far (VmHWM) in bytes; 0 where unavailable.
uint64_t peakResidentBytes();

// The machine's physical memory in bytes; 0 where unavailable.
uint64_t physicalMemoryBytes();

// Hands freed heap memory back to the system (glibc keeps the freed pages of its worker arenas,
// which would count against a memory cap in the stages after); a no-op without glibc.
void releaseFreedMemory();

// Wall seconds on the steady clock since t0.
inline double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// One finished stage.
struct StageTiming {
  std::string stage;
  double seconds = 0.0;       // wall time
  double cpuSeconds = 0.0;    // process CPU time, all threads
  uint64_t peakRssBytes = 0;  // the largest resident size seen during the stage
};

// Measures consecutive stages. A sampler thread reads the resident size every 5 ms and keeps the
// largest since the stage began (the kernel's own peak, VmHWM, is left alone: resetting it would
// also reset the rusage peak that /usr/bin/time reports). A stage's figure is the larger of its
// sampled peak and VmHWM when VmHWM grew during the stage; the whole run's peak is the larger of
// VmHWM and the stages' peaks.
class StageMeter {
 public:
  StageMeter();  // starts the sampler; call start() when the first stage begins
  ~StageMeter();
  StageMeter(const StageMeter&) = delete;
  StageMeter& operator=(const StageMeter&) = delete;

  // Begins a stage now.
  void start();
  // Ends the running stage, records it under `name` and returns it, and starts the next one.
  const StageTiming& finish(const std::string& name);
  // The stages finished so far, in order.
  const std::vector<StageTiming>& stages() const { return stages_; }
  // The run's peak: VmHWM, or a stage's sampled peak where that is higher (pages handed back
  // with madvise, as malloc_trim does, leave before the kernel's high-water mark sees them).
  uint64_t peak() const;

 private:
  std::vector<StageTiming> stages_;
  std::chrono::steady_clock::time_point t0_;
  std::clock_t cpu0_ = 0;
  uint64_t hwm0_ = 0;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  uint64_t stagePeak_ = 0;
  uint64_t largestStagePeak_ = 0;
  std::thread sampler_;
};

}  // namespace gimlod

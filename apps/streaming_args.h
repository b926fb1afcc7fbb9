// Streaming options `render` and `view` share (and `bench --render` the GPU cache): byte budgets of
// the GPU page pool, the loader's RAM and a frame's uploads, the loader's threads, a simulated
// storage latency and prefetch of the view ahead.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include "core/atlas_format.h"
#include "runtime/gl/atlas_scene.h"

namespace gimlod {

// "4G", "512M", "65536", ...; throws InputError naming the option.
inline uint64_t parseBytes(const std::string& option, const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  double unit = 1.0;
  const std::string suffix = end ? std::string(end) : std::string();
  if (suffix == "K" || suffix == "k")
    unit = 1024.0;
  else if (suffix == "M" || suffix == "m")
    unit = 1024.0 * 1024.0;
  else if (suffix == "G" || suffix == "g")
    unit = 1024.0 * 1024.0 * 1024.0;
  else if (!suffix.empty())
    throw InputError(option + " '" + text + "': unknown unit (use K, M or G)");
  if (!(v > 0.0) || !std::isfinite(v) || v * unit > 1e15)
    throw InputError(option + " '" + text + "' must be a positive size");
  return uint64_t(v * unit);
}

struct StreamingArgs {
  bool asyncLoads = false;
  uint32_t uploadsPerFrame = 64;
  std::string gpuCache = "auto";     // bytes, or auto: the pool for the node budget
  std::string ramCache = "512M";     // CesiumJS's cacheBytes
  std::string uploadBudget = "32M";  // a frame's uploads (vk_lod_clusters: 32 MiB of transfer a frame)
  uint32_t loaderThreads = 2;
  std::string ioLatency;                 // MS[,JITTER]
  uint32_t ioDepth = 32;                 // reads the simulated storage serves at once
  double prefetch = 0.5;                 // seconds ahead (P-BDAM: half a second)
  std::vector<CLI::Option*> loaderOnly;  // given, they switch the loader on
};

// Registers --async-loads, --uploads-per-frame, --gpu-cache, --ram-cache, --upload-budget,
// --loader-threads, --io-latency, --io-depth and --prefetch on cmd.
inline void addStreamingOptions(CLI::App* cmd, StreamingArgs& a) {
  cmd->add_flag("--async-loads", a.asyncLoads,
                "Load pages on loader threads; missing nodes draw with a resident ancestor's data (implied by the "
                "loader's options below)");
  cmd->add_option("--gpu-cache", a.gpuCache,
                  "GPU page pool in bytes (K, M, G): as many pages as fit, the chart roots resident while they fit "
                  "with room to split one, else each root a coarser stand-in; auto: a pool that holds the node "
                  "budget's cuts")
      ->capture_default_str();
  a.loaderOnly = {
      cmd->add_option("--ram-cache", a.ramCache,
                      "The loader's RAM in bytes: its cache of read pages and the pages read for upload")
          ->capture_default_str(),
      cmd->add_option("--upload-budget", a.uploadBudget,
                      "Bytes of pages uploaded to the GPU a frame (one page at least)")
          ->capture_default_str(),
      cmd->add_option("--uploads-per-frame", a.uploadsPerFrame, "Pages uploaded a frame at most")
          ->capture_default_str(),
      cmd->add_option("--loader-threads", a.loaderThreads, "Threads that read and decode pages")->capture_default_str(),
      cmd->add_option("--io-latency", a.ioLatency,
                      "MS[,JITTER]: simulate slow storage, every disk read waiting MS milliseconds plus up to JITTER"),
      cmd->add_option("--io-depth", a.ioDepth,
                      "Reads the simulated storage serves at once, as an asynchronous reader keeps them in flight "
                      "(1: each loader thread waits for its own)")
          ->capture_default_str(),
      cmd->add_option("--prefetch", a.prefetch,
                      "Seconds ahead: also load the cut of the view the camera's motion reaches then (0: off)")
          ->capture_default_str()};
}

// Whether the loader runs: --async-loads, or any of its options given.
inline bool streamingAsync(const StreamingArgs& a) {
  if (a.asyncLoads) return true;
  for (const CLI::Option* o : a.loaderOnly)
    if (o && o->count() > 0) return true;
  return false;
}

// Sets so's streaming fields from a, pages that cannot be read logged as warnings; throws
// InputError naming a bad option.
inline void applyStreamingArgs(const StreamingArgs& a, gl::SceneOptions& so) {
  so.onPageFailure = [](const PageFailure& f) {
    spdlog::warn("page of chart {} level {} ({}, {}) cannot be read, its node stays on a coarser one: {}", f.id.chart,
                 f.id.level, f.id.x, f.id.y, f.message);
  };
  so.gpuCacheBytes = a.gpuCache == "auto" ? 0 : parseBytes("--gpu-cache", a.gpuCache);
  so.asyncLoads = streamingAsync(a);
  so.ramCacheBytes = size_t(parseBytes("--ram-cache", a.ramCache));
  so.uploadBytesPerFrame = parseBytes("--upload-budget", a.uploadBudget);
  so.maxUploadsPerFrame = a.uploadsPerFrame;  // at least 1: validateViewOptions
  if (a.loaderThreads == 0 || a.loaderThreads > 64) throw InputError("--loader-threads must be in [1, 64]");
  so.loaderThreads = a.loaderThreads;
  if (a.ioDepth == 0 || a.ioDepth > 4096) throw InputError("--io-depth must be in [1, 4096]");
  so.ioDepth = a.ioDepth;
  if (!(a.prefetch >= 0.0) || !std::isfinite(a.prefetch) || a.prefetch > 60.0)
    throw InputError("--prefetch must be in [0, 60] seconds");
  so.prefetchSeconds = a.prefetch;
  so.ioLatencyMs = so.ioJitterMs = 0.0;
  if (!a.ioLatency.empty()) {
    double ms = 0.0, jitter = 0.0;
    char extra;
    const int n = std::sscanf(a.ioLatency.c_str(), "%lf,%lf%c", &ms, &jitter, &extra);
    if ((n != 1 && n != 2) || !(ms >= 0.0 && jitter >= 0.0) || ms > 60000.0 || jitter > 60000.0)
      throw InputError("--io-latency '" + a.ioLatency + "' must be MS or MS,JITTER in milliseconds (at most 60000)");
    so.ioLatencyMs = ms;
    so.ioJitterMs = jitter;
  }
}

}  // namespace gimlod

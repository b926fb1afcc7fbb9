// Node pages read from the atlas blocks on disk (paper section 7.2). Pure C++.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <vector>

#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"

namespace gimlod {

// Chart files opened on demand: at most maxOpen stay open (the least recently used is closed when
// another must open), so an atlas may hold more charts than a process may have files open. A
// reader in use stays valid while it is held. Thread-safe.
class ChartFileSet {
 public:
  explicit ChartFileSet(size_t maxOpen);
  void add(std::filesystem::path path);
  size_t size() const { return paths_.size(); }
  bool empty() const { return paths_.empty(); }
  std::shared_ptr<const ChartFileReader> get(uint32_t i) const;  // throws InputError naming the file
  size_t openFiles() const;

 private:
  std::vector<std::filesystem::path> paths_;
  size_t maxOpen_;
  mutable std::mutex mutex_;
  mutable std::vector<std::shared_ptr<const ChartFileReader>> open_;
  mutable std::vector<uint64_t> lastUse_;
  mutable uint64_t clock_ = 0;
  mutable size_t openCount_ = 0;
};

// The most chart files a PageReader keeps open: a quarter of the process's limit, at most 2048.
size_t chartFilesKeptOpen();

// Reads node pages: a node's page is its finest-resolution window, (2^maxResLog2 + 1)^2 samples of
// pyramid level intervalsLog2 - level - maxResLog2 (Hierarchy::maxResLog2: within its chart's finest
// level, which the chart file's level 0 is); every coarser resolution of the node is a subsampling
// of it. Thread-safe.
class PageReader {
 public:
  PageReader(const std::filesystem::path& atlasDir, const AtlasManifest& manifest, const HierarchyParams& params);
  uint32_t pageResLog2(const NodeId& n) const { return params_.maxResLog2(n.level, finest_[n.chart]); }
  uint32_t pageSamples(const NodeId& n) const { return (1u << pageResLog2(n)) + 1; }
  // samples: (pageSamples)^2 heights, or 3 floats (x, y, z) per sample for a geometry atlas.
  // colours, if given, receives the page's RGBA8 colours when the atlas has them (colours()):
  // (colourPageSamples)^2 texels, and is cleared otherwise.
  void read(const NodeId& n, std::vector<float>& samples, std::vector<PackedNormal>& normals,
            std::vector<PackedColour>* colours = nullptr) const;
  bool geometry() const { return geometry_; }
  // Every chart has colours: a mesh's vertex colours (in the chart file), or terrain imagery (an
  // attribute file per chart, at 2^colourScaleLog2 samples per geometry sample interval).
  bool colours() const { return colours_; }
  uint32_t colourScaleLog2() const { return colourScaleLog2_; }
  uint32_t colourPageSamples(const NodeId& n) const { return (1u << (pageResLog2(n) + colourScaleLog2_)) + 1; }
  // The bytes read() gives for n: samples, normals and colours (LoadedPage::bytes).
  size_t pageBytes(const NodeId& n) const {
    const size_t s = pageSamples(n), c = colours_ ? colourPageSamples(n) : 0;
    return s * s * ((geometry_ ? 3 : 1) * sizeof(float) + sizeof(PackedNormal)) + c * c * sizeof(PackedColour);
  }
  uint64_t bytesRead() const { return bytesRead_; }

 private:
  HierarchyParams params_;
  std::vector<uint32_t> finest_;  // per chart, ChartInfo::finestLevel
  bool geometry_ = false;
  bool colours_ = false;
  uint32_t colourScaleLog2_ = 0;
  ChartFileSet charts_;
  ChartFileSet imagery_;  // per chart, for terrain imagery
  mutable std::atomic<uint64_t> bytesRead_{0};
};

}  // namespace gimlod

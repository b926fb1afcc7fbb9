// Node pages: reading a node's data from the atlas blocks, and the LRU assignment of pages to
// layers of the GPU page pool (paper section 7.2). Pure C++.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <list>
#include <memory>
#include <unordered_map>
#include <vector>

#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"
#include "runtime/cut.h"
#include "runtime/draw_list.h"

namespace gimlod {

// Reads node pages: a node's page is its finest-resolution window, (2^maxRes(level) + 1)^2
// samples of pyramid level intervalsLog2 - level - maxRes(level); every coarser resolution of the
// node is a subsampling of it. Thread-safe.
class AtlasPages {
 public:
  AtlasPages(const std::filesystem::path& atlasDir, const AtlasManifest& manifest,
             const HierarchyParams& params);
  uint32_t pageSamples(uint32_t level) const { return (1u << params_.maxRes(level)) + 1; }
  // heights: (pageSamples)^2 heights, or 3 floats (x, y, z) per sample for a geometry atlas.
  void read(const NodeId& n, std::vector<float>& heights, std::vector<PackedNormal>& normals) const;
  bool geometry() const { return geometry_; }
  uint64_t bytesRead() const { return bytesRead_; }

 private:
  HierarchyParams params_;
  bool geometry_ = false;
  std::vector<std::unique_ptr<ChartFileReader>> charts_;
  mutable std::atomic<uint64_t> bytesRead_{0};
};

// Least-recently-used assignment of keys to `capacity` layers. Pages touched in the current frame
// and locked pages are never evicted.
class PageCache {
 public:
  explicit PageCache(uint32_t capacity);
  struct Slot {
    uint32_t layer = 0;
    bool needsUpload = false;
  };
  // Finds or assigns a layer for key in `frame`; false when every layer is in use this frame.
  bool acquire(uint64_t key, uint64_t frame, Slot* slot);
  void lock(uint64_t key);  // never evict key (it must be resident)
  // Whether key holds a layer now (does not touch the LRU order).
  bool contains(uint64_t key) const { return map_.count(key) != 0; }
  uint32_t resident() const { return uint32_t(map_.size()); }
  uint32_t capacity() const { return capacity_; }
  uint64_t evictions() const { return evictions_; }

 private:
  struct Entry {
    uint64_t key;
    uint32_t layer;
    uint64_t frame;
    bool locked;
  };
  uint32_t capacity_;
  std::list<Entry> lru_;  // front = most recent
  std::unordered_map<uint64_t, std::list<Entry>::iterator> map_;
  uint64_t evictions_ = 0;
};

// The draw record of a cut node whose page is in `layer`.
DrawNode makeDrawNode(const AtlasManifest& m, const HierarchyParams& p, const CutNode& n,
                      uint32_t layer);

}  // namespace gimlod

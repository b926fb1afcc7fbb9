// The GPU page pool's bookkeeping: least-recently-used assignment of node pages to its layers
// (paper section 7.2), numbered across the renderer's texture arrays. Pure C++; the renderer owns
// the textures.
#pragma once

#include <cstdint>
#include <list>
#include <unordered_map>

namespace gimlod {

// Least-recently-used assignment of keys to `capacity` layers. Pages touched in the current frame
// and locked pages are never evicted.
class PagePool {
 public:
  explicit PagePool(uint32_t capacity);
  struct Slot {
    uint32_t layer = 0;
    bool needsUpload = false;
  };
  // Finds or assigns a layer for key in `frame`; false when every layer is in use this frame.
  // keepFrom > 0: a new key evicts only a page last used before that frame (a prefetched page
  // takes a stale layer or none, never one the recent frames drew from).
  bool acquire(uint64_t key, uint64_t frame, Slot* slot, uint64_t keepFrom = 0);
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

}  // namespace gimlod

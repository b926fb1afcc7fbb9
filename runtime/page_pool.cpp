#include "runtime/page_pool.h"

#include <algorithm>
#include <cassert>
#include <iterator>

namespace gimlod {

PagePool::PagePool(uint32_t capacity) : capacity_(capacity) {}

bool PagePool::acquire(uint64_t key, uint64_t frame, Slot* slot, uint64_t keepFrom) {
  auto it = map_.find(key);
  if (it != map_.end()) {
    it->second->frame = frame;
    lru_.splice(lru_.begin(), lru_, it->second);
    *slot = {it->second->layer, false};
    return true;
  }
  uint32_t layer;
  if (map_.size() < capacity_) {
    layer = uint32_t(map_.size());
  } else {
    // Least recent evictable entry: not locked, not used this frame (nor since keepFrom).
    const uint64_t keep = keepFrom > 0 ? std::min(keepFrom, frame) : frame;
    auto victim = lru_.end();
    for (auto r = lru_.rbegin(); r != lru_.rend(); ++r)
      if (!r->locked && r->frame < keep) {
        victim = std::prev(r.base());
        break;
      }
    if (victim == lru_.end()) return false;
    layer = victim->layer;
    map_.erase(victim->key);
    lru_.erase(victim);
    ++evictions_;
  }
  lru_.push_front({key, layer, frame, false});
  map_[key] = lru_.begin();
  *slot = {layer, true};
  return true;
}

void PagePool::lock(uint64_t key) {
  auto it = map_.find(key);
  assert(it != map_.end() && "PagePool::lock: key not resident");
  if (it != map_.end()) it->second->locked = true;
}

}  // namespace gimlod

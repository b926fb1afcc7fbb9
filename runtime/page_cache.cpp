#include "runtime/page_cache.h"

#include <cassert>

namespace gimlod {

AtlasPages::AtlasPages(const std::filesystem::path& atlasDir, const AtlasManifest& manifest,
                       const HierarchyParams& params)
    : params_(params), geometry_(manifest.kind == AtlasKind::Geometry) {
  for (const ChartInfo& c : manifest.charts) {
    charts_.push_back(std::make_unique<ChartFileReader>(atlasDir / c.file));
    if (!charts_.back()->hasChannel(geometry_ ? kChannelPositions : kChannelHeights))
      throw InputError((atlasDir / c.file).string() + ": has no " + (geometry_ ? "positions" : "heights") +
                       " for a " + atlasKindName(manifest.kind) + " atlas");
  }
}

void AtlasPages::read(const NodeId& n, std::vector<float>& heights,
                      std::vector<PackedNormal>& normals) const {
  const uint32_t L = params_.intervalsLog2;
  const uint32_t r = params_.maxRes(n.level);
  const uint32_t k = params_.pyramidLevel(n.level, r);
  const uint32_t size = 1u << (L - n.level);  // level-0 intervals
  const uint32_t u0 = (n.x * size) >> k, v0 = (n.y * size) >> k;
  const uint32_t s = (1u << r) + 1;
  heights.resize(size_t(s) * s * (geometry_ ? 3 : 1));
  normals.resize(size_t(s) * s);
  if (geometry_)
    charts_[n.chart]->readPositions(k, u0, v0, 1u << r, reinterpret_cast<glm::vec3*>(heights.data()));
  else
    charts_[n.chart]->readHeights(k, u0, v0, 1u << r, heights.data());
  charts_[n.chart]->readNormals(k, u0, v0, 1u << r, normals.data());
  bytesRead_ += heights.size() * sizeof(float) + normals.size() * sizeof(PackedNormal);
}

PageCache::PageCache(uint32_t capacity) : capacity_(capacity) {}

bool PageCache::acquire(uint64_t key, uint64_t frame, Slot* slot) {
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
    // Least recent evictable entry: not locked, not used this frame.
    auto victim = lru_.end();
    for (auto r = lru_.rbegin(); r != lru_.rend(); ++r)
      if (!r->locked && r->frame != frame) {
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

void PageCache::lock(uint64_t key) {
  auto it = map_.find(key);
  assert(it != map_.end() && "PageCache::lock: key not resident");
  if (it != map_.end()) it->second->locked = true;
}

DrawNode makeDrawNode(const AtlasManifest& m, const HierarchyParams& p, const CutNode& n,
                      uint32_t layer) {
  const ChartInfo& c = m.charts[n.id.chart];
  const uint32_t L = p.intervalsLog2;
  const int32_t M = int32_t(1u << L);
  const int32_t size = int32_t(1u << (L - n.id.level));
  DrawNode d;
  d.originX = c.gridX * M + int32_t(n.id.x) * size;
  d.originY = c.gridY * M + int32_t(n.id.y) * size;
  d.sizeLog2 = L - n.id.level;
  d.res = n.res;
  d.pageResLog2 = p.maxRes(n.id.level);
  d.pageLayer = layer;
  // note: an attribute resolution above the page's is clamped to it (finer attribute pages are
  // not loaded); AttributeStats::abovePage counts those nodes.
  if (n.texRes != 0 && n.texRes < d.pageResLog2) d.texLod = d.pageResLog2 - n.texRes;
  return d;
}

}  // namespace gimlod

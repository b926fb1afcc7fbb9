// The GPU page pool's LRU bookkeeping: layers are reused least recently used first, never for
// pages touched this frame or locked. No GL.
#include <gtest/gtest.h>

#include "runtime/page_pool.h"

namespace gimlod {
namespace {

TEST(PagePool, AssignsFreeLayersThenEvictsTheLeastRecentlyUsed) {
  PagePool pool(3);
  PagePool::Slot s;
  ASSERT_TRUE(pool.acquire(10, 1, &s));
  EXPECT_EQ(s.layer, 0u);
  EXPECT_TRUE(s.needsUpload);
  ASSERT_TRUE(pool.acquire(11, 1, &s));
  ASSERT_TRUE(pool.acquire(12, 1, &s));
  EXPECT_EQ(s.layer, 2u);
  EXPECT_EQ(pool.resident(), 3u);
  // Touching 10 again keeps its layer and needs no upload; 11 becomes the least recent.
  ASSERT_TRUE(pool.acquire(10, 2, &s));
  EXPECT_EQ(s.layer, 0u);
  EXPECT_FALSE(s.needsUpload);
  ASSERT_TRUE(pool.acquire(13, 2, &s));
  EXPECT_EQ(s.layer, 1u);  // 11's layer
  EXPECT_TRUE(s.needsUpload);
  EXPECT_FALSE(pool.contains(11));
  EXPECT_TRUE(pool.contains(13));
  EXPECT_EQ(pool.evictions(), 1u);
}

TEST(PagePool, NeverEvictsPagesOfThisFrameOrLockedPages) {
  PagePool pool(2);
  PagePool::Slot s;
  ASSERT_TRUE(pool.acquire(1, 1, &s));
  pool.lock(1);
  ASSERT_TRUE(pool.acquire(2, 5, &s));
  // 1 is locked and 2 is in use this frame: no layer for 3.
  EXPECT_FALSE(pool.acquire(3, 5, &s));
  EXPECT_EQ(pool.evictions(), 0u);
  // Next frame 2 may go, 1 stays.
  ASSERT_TRUE(pool.acquire(3, 6, &s));
  EXPECT_EQ(s.layer, 1u);
  EXPECT_TRUE(pool.contains(1));
  EXPECT_FALSE(pool.contains(2));
}

// keepFrom: a page (a prefetched one) takes a free layer, or a layer last used before keepFrom;
// a layer used since stays.
TEST(PagePool, KeepFromSparesRecentlyUsedLayers) {
  PagePool pool(3);
  PagePool::Slot s;
  ASSERT_TRUE(pool.acquire(1, 2, &s));
  ASSERT_TRUE(pool.acquire(2, 8, &s));
  // A free layer is taken whatever keepFrom says.
  ASSERT_TRUE(pool.acquire(3, 10, &s, 9));
  EXPECT_EQ(pool.evictions(), 0u);
  // Full: 1 (used at frame 2) is older than frame 5, so it may go; then 2 (frame 8) may not.
  ASSERT_TRUE(pool.acquire(4, 10, &s, 5));
  EXPECT_FALSE(pool.contains(1));
  EXPECT_FALSE(pool.acquire(5, 10, &s, 5));
  EXPECT_TRUE(pool.contains(2));
  // Without keepFrom, 2 goes (not used this frame).
  ASSERT_TRUE(pool.acquire(5, 10, &s));
  EXPECT_FALSE(pool.contains(2));
  EXPECT_EQ(pool.evictions(), 2u);
}

}  // namespace
}  // namespace gimlod

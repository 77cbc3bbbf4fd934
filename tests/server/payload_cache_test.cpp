// The server's payload cache: bounded by its byte budget whatever is inserted, least
// recently used out first, never a payload too big for its share, and a payload evicted
// while a write still holds it stays valid.
#include <gtest/gtest.h>

#include <random>

#include "server/payload_cache.hpp"

namespace st::server {
namespace {

PayloadCache::Bytes payload(size_t n, uint8_t fill) {
  return std::make_shared<const std::vector<uint8_t>>(n, fill);
}

const int kMapA = 1, kMapB = 2;  // two distinct addresses: two packs

TEST(PayloadCache, StaysWithinItsBudgetAndEvictsTheLeastRecentlyUsed) {
  const size_t cost = 1000 + PayloadCache::kEntryOverhead;
  PayloadCache c(16 * cost);  // the most a payload may take is 1/16 of the budget
  for (uint64_t t = 0; t < 16; ++t) c.insert(&kMapA, t, payload(1000, uint8_t(t)));
  EXPECT_EQ(c.entries(), 16u);
  EXPECT_EQ(c.bytes(), 16 * cost);
  ASSERT_TRUE(c.find(&kMapA, 0));  // tile 0 is now the most recent; tile 1 the least
  c.insert(&kMapA, 16, payload(1000, 16));
  EXPECT_EQ(c.entries(), 16u);
  EXPECT_FALSE(c.find(&kMapA, 1));
  ASSERT_TRUE(c.find(&kMapA, 0));
  EXPECT_EQ((*c.find(&kMapA, 0))[0], 0);
  EXPECT_FALSE(c.find(&kMapB, 0)) << "same tile id, other map";
  EXPECT_EQ(c.hits(), 3u);
  EXPECT_EQ(c.misses(), 2u);
}

TEST(PayloadCache, RandomSizesNeverExceedTheBudget) {
  PayloadCache c(64 * 1024);
  std::mt19937 rng(7);
  for (int i = 0; i < 5000; ++i) {
    const uint64_t tile = rng() % 300;
    if (!c.find(&kMapA, tile)) c.insert(&kMapA, tile, payload(rng() % 6000, uint8_t(tile)));
    ASSERT_LE(c.bytes(), c.budget());
    if (auto b = c.find(&kMapA, tile); b && !b->empty()) {
      ASSERT_EQ((*b)[0], uint8_t(tile));
    }
  }
  EXPECT_GT(c.entries(), 10u);
}

TEST(PayloadCache, ABigPayloadIsNotCachedAndAZeroBudgetCachesNothing) {
  PayloadCache c(16 * 1024);
  c.insert(&kMapA, 1, payload(2000, 1));  // over 1/16 of the budget with its overhead
  EXPECT_EQ(c.entries(), 0u);
  c.insert(&kMapA, 2, payload(100, 2));
  EXPECT_EQ(c.entries(), 1u);
  PayloadCache none(0);
  none.insert(&kMapA, 2, payload(1, 2));
  EXPECT_FALSE(none.find(&kMapA, 2));
  EXPECT_EQ(none.bytes(), 0u);
}

TEST(PayloadCache, AnEvictedPayloadStaysValidWhileReferenced) {
  const size_t cost = 100 + PayloadCache::kEntryOverhead;
  PayloadCache c(16 * cost);
  c.insert(&kMapA, 1, payload(100, 0xab));
  PayloadCache::Bytes writing = c.find(&kMapA, 1);  // a gathered write holds it
  for (uint64_t t = 2; t < 40; ++t) c.insert(&kMapA, t, payload(100, 0));
  EXPECT_FALSE(c.find(&kMapA, 1));
  ASSERT_EQ(writing->size(), 100u);
  EXPECT_EQ((*writing)[99], 0xab);
  EXPECT_EQ(writing.use_count(), 1);  // the cache let go of it
}

}  // namespace
}  // namespace st::server

// The server's payload cache: bounded by its byte budget whatever is inserted (pages
// included), a recently sent payload outlives one that was not (CLOCK), never a payload
// too big for its share, nothing out of range, and a payload evicted while a write still
// holds it stays valid.
#include <gtest/gtest.h>

#include <random>

#include "server/payload_cache.hpp"

namespace st::server {
namespace {

PayloadCache::Bytes payload(size_t n, uint8_t fill) {
  return std::make_shared<const std::vector<uint8_t>>(n, fill);
}

constexpr size_t kPage = sizeof(std::array<std::shared_ptr<int>, PayloadCache::kPageSlots>);

TEST(PayloadCache, StaysWithinItsBudgetAndKeepsWhatWasSent) {
  const size_t cost = 4000 + PayloadCache::kEntryOverhead;
  PayloadCache c;
  const std::vector<size_t> tiles{100, 100};
  c.configure(2 * kPage + 16 * cost, tiles);
  for (uint32_t t = 0; t < 16; ++t) c.insert(0, t, payload(4000, uint8_t(t)));
  EXPECT_EQ(c.entries(), 16u);
  EXPECT_LE(c.bytes(), c.budget());
  ASSERT_TRUE(c.find(0, 3));  // sent since: the hand spares it
  for (uint32_t t = 16; t < 24; ++t) c.insert(0, t, payload(4000, uint8_t(t)));
  EXPECT_LE(c.bytes(), c.budget());
  ASSERT_TRUE(c.find(0, 3));
  EXPECT_EQ((*c.find(0, 3))[0], 3);
  EXPECT_TRUE(c.find(0, 23));
  EXPECT_FALSE(c.find(1, 3)) << "same position, other map";
  EXPECT_FALSE(c.find(0, 100)) << "past the map's tiles";
  EXPECT_FALSE(c.find(2, 0)) << "no such map";
  c.insert(0, 100, payload(10, 1));
  c.insert(5, 0, payload(10, 1));
  EXPECT_LE(c.entries(), 16u);
}

TEST(PayloadCache, RandomSizesNeverExceedTheBudget) {
  PayloadCache c;
  const std::vector<size_t> tiles{700, 3, 5000};
  c.configure(160 * 1024, tiles);
  std::mt19937 rng(7);
  for (int i = 0; i < 20000; ++i) {
    const uint32_t map = rng() % 3, tile = uint32_t(rng() % tiles[map]);
    const uint8_t tag = uint8_t(map * 31 + tile);
    if (!c.find(map, tile)) c.insert(map, tile, payload(1 + rng() % 12000, tag));
    ASSERT_LE(c.bytes(), c.budget());
    if (auto b = c.find(map, tile)) {
      ASSERT_EQ((*b)[0], tag);
    }
  }
  EXPECT_GT(c.entries(), 10u);
  EXPECT_GT(c.hits(), 0u);
  EXPECT_GT(c.misses(), 0u);
}

TEST(PayloadCache, ABigPayloadIsNotCachedAndAZeroBudgetCachesNothing) {
  PayloadCache c;
  const std::vector<size_t> tiles{10};
  c.configure(16 * 1024 + kPage, tiles);
  c.insert(0, 1, payload(2000, 1));  // over 1/16 of the budget
  EXPECT_EQ(c.entries(), 0u);
  c.insert(0, 2, payload(100, 2));
  EXPECT_EQ(c.entries(), 1u);
  PayloadCache none;
  none.configure(0, tiles);
  none.insert(0, 2, payload(1, 2));
  EXPECT_FALSE(none.find(0, 2));
  EXPECT_EQ(none.bytes(), 0u);
}

TEST(PayloadCache, AnEvictedPayloadStaysValidWhileReferenced) {
  PayloadCache c;
  const std::vector<size_t> tiles{1000};
  c.configure(64 * 1024, tiles);
  c.insert(0, 1, payload(100, 0xab));
  PayloadCache::Bytes writing = c.find(0, 1);  // a gathered write holds it
  for (uint32_t t = 2; t < 1000; ++t) c.insert(0, t, payload(2000, 0));
  EXPECT_FALSE(c.find(0, 1));
  ASSERT_EQ(writing->size(), 100u);
  EXPECT_EQ((*writing)[99], 0xab);
  EXPECT_EQ(writing.use_count(), 1);  // the cache let go of it
}

}  // namespace
}  // namespace st::server

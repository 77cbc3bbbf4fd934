// The tile cache's change journal and CacheView::changed_slots on it: a mirror that
// visits only the slots the journal names ends up equal to the cache, under churn (tiles
// arriving, evicted, re-arriving, made constant, fetches aborted), with changes left for
// later (an upload budget) and with readers so late that the journal overran.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <thread>
#include <vector>

#include "shadowtile/cache_view.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/core/tile_cache.hpp"

namespace st::client {
namespace {

// What a mirror of slot s should hold: the tile resident in it, else kInvalidTile.
TileId truth(const TileCache& c, uint32_t s) {
  const TileId t = c.slot_tile(s);
  if (t == kInvalidTile) return t;
  const PageEntry e = c.lookup(t);
  return e.state == PageState::resident && e.slot == s ? t : kInvalidTile;
}

TEST(TileCacheJournal, AMirrorVisitingOnlyJournaledSlotsEqualsTheCacheUnderChurn) {
  uint32_t followed = 0, overran = 0;
  for (uint32_t seed = 1; seed <= 40; ++seed) {
    std::mt19937_64 rng(seed);
    const uint32_t slots = 1 + uint32_t(rng() % 12);
    TileCache c(slots, 32);
    ASSERT_GE(c.journal_capacity(), slots);
    std::vector<TileId> known(slots, kInvalidTile);
    uint64_t cursor = 0;
    const std::vector<uint8_t> bytes(20, 7);
    for (int step = 0; step < 2000; ++step) {
      const TileId t = rng() % 40;  // few ids: tiles leave and come back
      switch (rng() % 6) {
        case 0:
        case 1: c.insert(t, std::span(bytes).first(rng() % 20)); break;  // may evict; a resident t: no-op
        case 2: c.evict(t); break;
        case 3: c.set_constant(t, 0.5f); break;  // drops a resident copy
        case 4: {  // a fetch that fails: reserve (may evict) then abort
          if (c.lookup(t).state == PageState::resident) break;
          c.abort(c.reserve(t));
          break;
        }
        case 5: {  // a fetch that lands while the tile became constant meanwhile: commit refuses
          if (c.lookup(t).state == PageState::resident) break;
          const uint32_t s = c.reserve(t);
          if (rng() % 2) c.set_constant(t, 0.25f);
          c.commit(s, 4);
          break;
        }
      }
      if (rng() % 50 != 0) continue;  // a frame: the mirror catches up (sometimes very late)
      std::vector<uint32_t> named;
      const uint64_t end = c.journal_end();
      if (c.changes_since(cursor, [&](uint32_t s) { named.push_back(s); })) {
        ++followed;
        ASSERT_EQ(named.size(), end - cursor);  // O(changes): one entry a change
        // Complete: every slot whose truth moved is named.
        for (uint32_t s = 0; s < slots; ++s)
          if (known[s] != truth(c, s)) {
            ASSERT_NE(std::find(named.begin(), named.end(), s), named.end()) << s;
          }
      } else {
        ++overran;
        ASSERT_GT(end - cursor, c.journal_capacity());
        for (uint32_t s = 0; s < slots; ++s) named.push_back(s);
      }
      for (uint32_t s : named) known[s] = truth(c, s);
      cursor = end;
      for (uint32_t s = 0; s < slots; ++s) ASSERT_EQ(known[s], truth(c, s)) << "seed " << seed << " slot " << s;
    }
    EXPECT_FALSE(c.changes_since(c.journal_end() + 1, [](uint32_t) {}));  // a cursor from the future
  }
  EXPECT_GT(followed, 100u);
  EXPECT_GT(overran, 0u);
}

// A served map with a small cache, tiles requested all over it while the consumer follows
// with changed_slots and takes only some changes per call (the rest come again): at rest
// its copy equals a fresh view's full comparison, each call visited only real changes, and
// calls after the cache stopped changing visit nothing.
TEST(CacheViewJournal, ChangedSlotsUnderChurnWithDeferralsEndsEqualToAFullComparison) {
  const looptest::TestPack pack = looptest::build_pack("cache_journal", 7, 3, looptest::first_encoding(), 2, 512);
  looptest::TestServer server = looptest::start_server({pack.path});
  ClientOptions o = looptest::quick_options();
  o.cache_slots = 12;  // far fewer than the map's tiles: arrivals evict
  Client client(Endpoint{"127.0.0.1", server.port}, o);
  Map map = client.open("cache_journal");
  CacheView view(map);
  const uint32_t slots = view.shape().slot_count;
  std::vector<uint64_t> known(slots, kNoTile);
  std::mt19937_64 rng(11);
  const uint32_t l = map.finest_level(), side = 1u << l;
  size_t visited = 0, refused = 0;
  auto follow = [&](uint32_t take) {
    uint32_t taken = 0;
    return view.changed_slots(known, [&](const SlotChange& ch) {
      EXPECT_LT(ch.slot, slots);
      EXPECT_NE(known[ch.slot], ch.tile);  // only real changes
      EXPECT_EQ(ch.tile == kNoTile, ch.bytes.empty());
      if (taken == take) return ++refused, false;
      ++taken;
      return true;
    });
  };
  for (int i = 0; i < 40; ++i) {
    const uint32_t w = side / 8;
    map.request_region(l, uint32_t(rng() % (side - w)), uint32_t(rng() % (side - w)), w, w, uint16_t(1 + i));
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    visited += follow(1 + uint32_t(rng() % 3));  // an upload budget of 1-3 slots a call
  }
  EXPECT_GT(map.stats().tiles_received, slots);  // slots were reused
  EXPECT_GT(refused, 0u);
  server.stop();
  ASSERT_TRUE(looptest::wait_until([&] { return !client.stats().connected; }));
  while (follow(~0u) != 0) {
  }
  EXPECT_EQ(follow(~0u), 0u);
  // The truth: a fresh view compares every slot against an empty copy.
  CacheView fresh(map);
  std::vector<uint64_t> all(slots, kNoTile);
  fresh.changed_slots(all, [](const SlotChange&) { return true; });
  EXPECT_EQ(known, all);
  EXPECT_GT(std::count_if(all.begin(), all.end(), [](uint64_t t) { return t != kNoTile; }), 0);
  EXPECT_GT(visited, 0u);
  // Another array on the same view is compared in full (it is not the consumer the journal follows).
  std::vector<uint64_t> other(slots, kNoTile);
  EXPECT_EQ(view.changed_slots(other, [](const SlotChange&) { return true; }),
            size_t(std::count_if(all.begin(), all.end(), [](uint64_t t) { return t != kNoTile; })));
  EXPECT_EQ(other, all);
}

}  // namespace
}  // namespace st::client

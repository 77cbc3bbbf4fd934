// Tile cache: pool layout, LRU eviction order, pinning, page table states, and a property
// test running random operation sequences against a simple reference model.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <map>
#include <optional>
#include <random>
#include <vector>

#include "client/tile_arena.hpp"
#include "common/error.hpp"
#include "tiles/core/tile_cache.hpp"

namespace st::client {
namespace {

std::vector<uint8_t> bytes_of(uint32_t n, uint8_t seed) {
  std::vector<uint8_t> b(n);
  for (uint32_t i = 0; i < n; ++i) b[i] = uint8_t(seed * 31 + i * 7 + 1);
  return b;
}

TEST(TileCache, SlotsAreContiguousAtFixedOffsets) {
  TileCache c(4, 16);
  EXPECT_EQ(c.pool().size(), 64u);
  for (uint32_t t = 0; t < 4; ++t) {
    auto b = bytes_of(10 + t, uint8_t(t));
    uint32_t s = c.insert(100 + t, b);
    EXPECT_EQ(c.slot_offset(s), uint64_t(s) * 16);
    auto in_pool = c.pool().subspan(c.slot_offset(s), 16);
    EXPECT_TRUE(std::equal(b.begin(), b.end(), in_pool.begin()));
    // The unused tail of a slot is zero.
    EXPECT_TRUE(std::all_of(in_pool.begin() + b.size(), in_pool.end(), [](uint8_t v) { return v == 0; }));
  }
}

TEST(TileCache, EvictsLeastRecentlyUsedAndCountsHitsMisses) {
  TileCache c(3, 8);
  c.insert(1, bytes_of(4, 1));
  c.insert(2, bytes_of(4, 2));
  c.insert(3, bytes_of(4, 3));
  EXPECT_EQ(c.access(1).state, PageState::resident);  // order now 1, 3, 2 (2 is LRU)
  EXPECT_EQ(c.access(9).state, PageState::absent);
  c.insert(4, bytes_of(4, 4));
  EXPECT_EQ(c.lookup(2).state, PageState::absent);
  EXPECT_EQ(c.lookup(1).state, PageState::resident);
  auto s = c.stats();
  EXPECT_EQ(s.hits, 1u);
  EXPECT_EQ(s.misses, 1u);
  EXPECT_EQ(s.evictions, 1u);
  EXPECT_EQ(s.resident, 3u);
}

TEST(TileCache, PinnedSlotsAreNeverEvictedAndAllPinnedFailsClearly) {
  TileCache c(2, 8);
  uint32_t a = c.insert(1, bytes_of(3, 1));
  uint32_t b = c.insert(2, bytes_of(3, 2));
  c.pin(a);
  c.insert(3, bytes_of(3, 3));  // must evict 2, not the older but pinned 1
  EXPECT_EQ(c.lookup(1).state, PageState::resident);
  EXPECT_EQ(c.lookup(2).state, PageState::absent);
  c.pin(b);  // b now holds tile 3
  EXPECT_THROW(c.insert(4, bytes_of(3, 4)), CacheFullError);
  EXPECT_EQ(c.lookup(4).state, PageState::absent);
  c.unpin(a);
  EXPECT_NO_THROW(c.insert(4, bytes_of(3, 4)));
  EXPECT_EQ(c.lookup(1).state, PageState::absent);
}

TEST(TileCache, PageStatesConstantRequestedResident) {
  TileCache c(2, 8);
  c.set_constant(7, 0.25f);
  EXPECT_EQ(c.lookup(7).state, PageState::constant);
  EXPECT_EQ(c.lookup(7).value, 0.25f);
  EXPECT_FALSE(c.request(7));
  EXPECT_TRUE(c.request(8));
  EXPECT_FALSE(c.request(8));
  EXPECT_EQ(c.lookup(8).state, PageState::requested);
  c.cancel_request(8);
  EXPECT_EQ(c.lookup(8).state, PageState::absent);
  // Two-phase fill: the page stays requested until commit.
  ASSERT_TRUE(c.request(9));
  uint32_t s = c.reserve(9);
  EXPECT_EQ(c.pin_count(s), 1u);
  EXPECT_EQ(c.lookup(9).state, PageState::requested);
  c.slot_span(s)[0] = 42;
  EXPECT_TRUE(c.commit(s, 1));
  EXPECT_EQ(c.lookup(9).state, PageState::resident);
  EXPECT_EQ(c.tile_bytes(s)[0], 42);
  EXPECT_EQ(c.pin_count(s), 0u);
  // A tile larger than a slot is refused and leaves nothing behind.
  EXPECT_THROW(c.insert(10, bytes_of(9, 1)), Error);
  EXPECT_EQ(c.lookup(10).state, PageState::absent);
  EXPECT_THROW(TileCache(0, 8), Error);
  EXPECT_THROW(TileCache(8, 0), Error);
}

// ---------------------------------------------------------------- reference model

struct RefSlotless {
  PageState state = PageState::absent;
  float value = 0;
  std::vector<uint8_t> bytes;
  uint32_t pins = 0;
  uint64_t stamp = 0;  // recency: larger = more recently used
};

struct RefModel {
  uint32_t slots;
  std::map<TileId, RefSlotless> pages;
  uint64_t clock = 0, hits = 0, misses = 0, evictions = 0;

  uint32_t resident() const {
    uint32_t n = 0;
    for (auto& [t, p] : pages) n += p.state == PageState::resident;
    return n;
  }
  std::optional<TileId> victim() const {
    std::optional<TileId> v;
    uint64_t best = ~uint64_t(0);
    for (auto& [t, p] : pages)
      if (p.state == PageState::resident && p.pins == 0 && p.stamp < best) best = p.stamp, v = t;
    return v;
  }
};

void check_same(const TileCache& c, const RefModel& m, const std::vector<TileId>& universe) {
  for (TileId t : universe) {
    PageEntry e = c.lookup(t);
    auto it = m.pages.find(t);
    PageState want = it == m.pages.end() ? PageState::absent : it->second.state;
    ASSERT_EQ(int(e.state), int(want)) << "tile " << t;
    if (want == PageState::constant) { ASSERT_EQ(e.value, it->second.value); }
    if (want == PageState::resident) {
      auto got = c.tile_bytes(e.slot);
      ASSERT_EQ(std::vector<uint8_t>(got.begin(), got.end()), it->second.bytes) << "tile " << t;
      ASSERT_EQ(c.slot_tile(e.slot), t);
      ASSERT_EQ(c.pin_count(e.slot), it->second.pins);
      auto slot = c.pool().subspan(c.slot_offset(e.slot), c.slot_bytes());
      ASSERT_TRUE(std::all_of(slot.begin() + got.size(), slot.end(), [](uint8_t v) { return v == 0; }));
    }
  }
  auto s = c.stats();
  ASSERT_EQ(s.hits, m.hits);
  ASSERT_EQ(s.misses, m.misses);
  ASSERT_EQ(s.evictions, m.evictions);
  ASSERT_EQ(s.resident, m.resident());
  ASSERT_EQ(s.free, m.slots - m.resident());
  auto v = m.victim();
  ASSERT_EQ(c.lru_victim() == kNoSlot, !v.has_value());
  if (v) { ASSERT_EQ(c.slot_tile(c.lru_victim()), *v); }
}

// A tile committed with its bytes held elsewhere (RemoteMap's tile arena) is read there
// and leaves its slot unwritten; a slot is cleared only as far as it was written; the
// pages a dropped tile wrote go back (release_pages) where they are the slot's alone.
TEST(TileCache, HeldTilesLeaveTheirSlotUnwrittenAndWrittenPagesGoBack) {
  const uint32_t page = uint32_t(::sysconf(_SC_PAGESIZE));
  TileCache c(4, 2 * page);
  const uint32_t s = c.reserve(1);
  std::fill_n(c.slot_span(s, 3000).data(), 3000, uint8_t(0xAB));
  ASSERT_TRUE(c.commit(s, 2000));  // written past the tile: cleared on commit
  EXPECT_EQ(c.written_bytes(), 3000u);
  auto own = [&](uint32_t slot) { return c.pool().subspan(c.slot_offset(slot), c.slot_bytes()); };
  EXPECT_TRUE(std::all_of(own(s).begin() + 2000, own(s).end(), [](uint8_t v) { return v == 0; }));
  ASSERT_TRUE(c.evict(1));
  EXPECT_TRUE(std::all_of(own(s).begin(), own(s).end(), [](uint8_t v) { return v == 0; }));
  EXPECT_EQ(c.written_bytes(), 3000u);  // zeroed, its pages still in use
  const uint32_t s2 = c.reserve(2);
  ASSERT_EQ(s2, s);
  EXPECT_TRUE(c.release_pages(s2));
  EXPECT_EQ(c.written_bytes(), 0u);
  const std::vector<uint8_t> held = bytes_of(500, 7);
  ASSERT_TRUE(c.commit_held(s2, held));
  EXPECT_EQ(c.tile_bytes(s2).data(), held.data());
  EXPECT_EQ(c.tile_bytes(s2).size(), held.size());
  EXPECT_EQ(c.written_bytes(), 0u);
  EXPECT_TRUE(std::all_of(own(s2).begin(), own(s2).end(), [](uint8_t v) { return v == 0; }));
  ASSERT_TRUE(c.evict(2));  // the held bytes are forgotten with the tile
  const uint32_t s3 = c.reserve(3);
  EXPECT_TRUE(c.tile_bytes(s3).empty());
  c.abort(s3);
  // Slots that share pages with their neighbours keep theirs (and say so).
  TileCache odd(4, 1000);
  const uint32_t t = odd.reserve(1);
  std::fill_n(odd.slot_span(t, 10).data(), 10, uint8_t(1));
  odd.abort(t);
  const uint32_t t2 = odd.reserve(2);
  ASSERT_EQ(t2, t);
  EXPECT_FALSE(odd.release_pages(t2));
  EXPECT_EQ(odd.written_bytes(), 10u);
}

TEST(TileCacheProperty, RandomOperationsMatchReferenceModel) {
  for (uint32_t seed = 1; seed <= 60; ++seed) {
    std::mt19937_64 rng(seed);
    const uint32_t slots = 1 + uint32_t(rng() % 8), slot_bytes = 1 + uint32_t(rng() % 48);
    TileCache c(slots, slot_bytes);
    RefModel m{slots, {}, 0, 0, 0, 0};
    // Ids spread over 64 bits (and some adjacent) to exercise the hash table's probing.
    std::vector<TileId> universe;
    for (uint32_t i = 0; i < 24; ++i) universe.push_back(i < 12 ? i : (rng() >> 1));
    auto pick = [&] { return universe[rng() % universe.size()]; };
    for (int step = 0; step < 1500; ++step) {
      TileId t = pick();
      RefSlotless& p = m.pages[t];  // absent pages are erased again below
      switch (rng() % 9) {
        case 0: {  // access
          PageEntry e = c.access(t);
          (void)e;
          if (p.state == PageState::resident) {
            ++m.hits;
            if (p.pins == 0) p.stamp = ++m.clock;
          } else if (p.state != PageState::constant) {
            ++m.misses;
          }
          break;
        }
        case 1:
        case 2: {  // insert (the fetcher's reserve + write + commit)
          uint32_t n = uint32_t(rng() % (slot_bytes + 2));
          auto b = bytes_of(n, uint8_t(rng()));
          bool all_pinned = m.resident() == slots && !m.victim();
          if (n > slot_bytes) {
            EXPECT_THROW(c.insert(t, b), Error);
          } else if (all_pinned) {
            EXPECT_THROW(c.insert(t, b), CacheFullError);  // even a resident tile: reserve first
          } else {
            if (m.resident() == slots) {
              TileId v = *m.victim();
              m.pages[v] = RefSlotless{};
              ++m.evictions;
            }
            c.insert(t, b);
            RefSlotless& q = m.pages[t];
            if (q.state != PageState::constant && q.state != PageState::resident) {
              q.state = PageState::resident;
              q.bytes = b;
              q.pins = 0;
              q.stamp = ++m.clock;
            }
          }
          break;
        }
        case 3:  // request
          EXPECT_EQ(c.request(t), p.state == PageState::absent);
          if (p.state == PageState::absent) p.state = PageState::requested;
          break;
        case 4:  // cancel
          c.cancel_request(t);
          if (p.state == PageState::requested) p.state = PageState::absent;
          break;
        case 5: {  // constant
          if (p.state == PageState::resident && p.pins > 0) {
            EXPECT_THROW(c.set_constant(t, 0.5f), Error);
          } else {
            float v = float(rng() % 100) / 100.0f;
            c.set_constant(t, v);
            p = RefSlotless{PageState::constant, v, {}, 0, 0};
          }
          break;
        }
        case 6:  // pin
          if (p.state == PageState::resident && p.pins < 3) {
            c.pin(c.lookup(t).slot);
            ++p.pins;
          }
          break;
        case 7:  // unpin
          if (p.state == PageState::resident && p.pins > 0) {
            c.unpin(c.lookup(t).slot);
            if (--p.pins == 0) p.stamp = ++m.clock;
          }
          break;
        case 8: {  // explicit evict
          bool ok = p.state == PageState::resident && p.pins == 0;
          EXPECT_EQ(c.evict(t), ok);
          if (ok) {
            p = RefSlotless{};
            ++m.evictions;
          }
          break;
        }
      }
      for (auto it = m.pages.begin(); it != m.pages.end();)
        it = it->second.state == PageState::absent ? m.pages.erase(it) : std::next(it);
      check_same(c, m, universe);
      if (testing::Test::HasFatalFailure()) {
        ADD_FAILURE() << "seed " << seed << " step " << step;
        return;
      }
    }
  }
}

}  // namespace
}  // namespace st::client

// The evaluators' tight copies of the tiles (client/tile_arena.hpp): random places and
// releases over a few slots; every live copy keeps its bytes (no two overlap), starts on
// a line, and the arena never holds more chunks than live tiles (a chunk whose tiles all
// left is freed, the one being filled too): a map's tiles in the arena and not in their
// slots stay within the slots' bytes (RemoteMap's budget).
namespace st::client::arena_test {

TEST(TileArena, RandomPlacesKeepEveryLiveCopyIntactAndBoundTheChunks) {
  constexpr uint32_t kSlots = 24, kChunk = 4096;
  TileArena arena(kSlots, kChunk);
  std::mt19937 rng(7);
  std::vector<std::vector<uint8_t>> want(kSlots);
  std::vector<std::span<const uint8_t>> got(kSlots);
  std::vector<bool> live(kSlots, false);
  for (int op = 0; op < 4000; ++op) {
    const uint32_t slot = rng() % kSlots;
    if (rng() % 4 == 0) {
      arena.release(slot);
      live[slot] = false;
    } else {
      // Mostly small tiles (a real level's), now and then up to a whole chunk.
      const uint32_t n = rng() % 8 == 0 ? rng() % (kChunk + 1) : rng() % 400;
      want[slot] = bytes_of(n, uint8_t(op));
      got[slot] = arena.place(slot, want[slot]);
      live[slot] = n > 0;  // no bytes: nothing placed (the slot's old copy released)
      ASSERT_EQ(got[slot].size(), n);
      if (n) {
        EXPECT_EQ(reinterpret_cast<uintptr_t>(got[slot].data()) % TileArena::kAlign, 0u);
      }
    }
    uint64_t live_count = 0;
    for (uint32_t s = 0; s < kSlots; ++s) {
      if (!live[s]) continue;
      ++live_count;
      ASSERT_TRUE(std::equal(got[s].begin(), got[s].end(), want[s].begin(), want[s].end()))
          << "slot " << s << " after op " << op;
    }
    ASSERT_LE(arena.held_bytes(), live_count * kChunk) << op;
  }
  for (uint32_t s = 0; s < kSlots; ++s) arena.release(s);
  EXPECT_EQ(arena.held_bytes(), 0u);  // the chunk being filled too
  EXPECT_THROW(arena.place(0, std::vector<uint8_t>(kChunk + 1)), Error);
  EXPECT_TRUE(arena.place(1, {}).empty());
}

// With a ceiling of chunks, a copy that needs one more is not made (a span without data:
// the caller reads its own bytes) and the arena never holds more; the copies made keep
// their bytes.
TEST(TileArena, ACeilingOfChunksIsNeverPassedAndRefusedCopiesAreNotMade) {
  constexpr uint32_t kSlots = 32, kChunk = 1024, kMax = 3;
  TileArena arena(kSlots, kChunk, kMax);
  std::mt19937 rng(11);
  std::vector<std::vector<uint8_t>> want(kSlots);
  std::vector<std::span<const uint8_t>> got(kSlots);
  uint32_t refused = 0;
  for (int op = 0; op < 3000; ++op) {
    const uint32_t slot = rng() % kSlots;
    if (rng() % 3 == 0) {
      arena.release(slot);
      got[slot] = {};
      continue;
    }
    want[slot] = bytes_of(1 + rng() % 700, uint8_t(op));
    got[slot] = arena.place(slot, want[slot]);
    if (!got[slot].data()) ++refused;
    ASSERT_LE(arena.held_bytes(), uint64_t(kMax) * kChunk) << op;
    for (uint32_t s = 0; s < kSlots; ++s) {
      if (got[s].data()) {
        ASSERT_TRUE(std::equal(got[s].begin(), got[s].end(), want[s].begin(), want[s].end())) << s << " " << op;
      }
    }
  }
  EXPECT_GT(refused, 0u) << "the ceiling was never reached: the test proves nothing";
}

}  // namespace st::client::arena_test

// Loopback tests of the client against an in-process server: every tile fetched answers
// bit-exactly like the local PackEvaluator; a tiny cache evicts, refetches and stays
// exact; answers before a tile arrives come from the coarser level; corrupt payloads
// are caught by the end-to-end CRC (or, matching it, by decoding) and refetched or given
// up.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <filesystem>
#include <mutex>
#include <set>
#include <thread>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/core/map_preview.hpp"

namespace st::client {
namespace remote_map_test {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::start_server;
using looptest::wait_until;

// Level 7 at every scale: the map preview answers levels up to K + its levels exactly (no
// tile needed), and these tests need tiles below them.
uint32_t test_level() { return 7; }
uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

using looptest::quick_options;

// "" if every texel of every level answers like `want`, else the first difference.
std::string first_difference(const Evaluator& got, const Evaluator& want) {
  for (uint32_t l = 0; l <= want.finest_level(); ++l)
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x)
        if (bits(got.depth(l, x, y)) != bits(want.depth(l, x, y)))
          return "level " + std::to_string(l) + " texel (" + std::to_string(x) + ", " + std::to_string(y) +
                 "): got " + std::to_string(got.depth(l, x, y)) + ", want " + std::to_string(want.depth(l, x, y));
  return "";
}

TEST(RemoteMap, FetchesEveryTileAndAnswersBitExactlyLikeThePack) {
  const auto encodings = looptest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t level = test_level(), side = 1u << level;
  for (Encoding e : encodings) {
    SCOPED_TRACE(to_string(e));
    // Small tiles: noisy cells are cut deeper into index tiles (a page-table quadtree).
    auto p = build_pack("every_" + to_string(e), level, 42, e, 3, 512);
    ASSERT_FALSE(p.reader->tiles().empty());
    auto srv = start_server({p.path});
    ClientOptions o = quick_options();
    o.cache_slots = uint32_t(p.reader->tiles().size()) + 4;
    Client client({"127.0.0.1", srv.port}, o);
    Map map = client.open("every_" + to_string(e));
    EXPECT_EQ(map.finest_level(), level);
    map.request_region(level, 0, 0, side, side, 10);
    ASSERT_TRUE(wait_until([&] { return map.region_resident(level, 0, 0, side, side); }))
        << map.stats().tiles_received << " of " << p.reader->tiles().size() << " tiles";
    PackEvaluator local(p.reader);
    EXPECT_EQ(first_difference(client::evaluator(map), local), "");
    // PCF and the lit test over the cache equal the local ones exactly.
    for (uint64_t i = 0; i < 200; ++i) {
      uint64_t x = (i * 37) % side, y = (i * 91) % side;
      float recv = float(i % 17) / 16.0f;
      EXPECT_EQ(map.pcf(level, x, y, 3, recv), local.pcf(level, x, y, 3, recv));
      EXPECT_EQ(map.lit(x, y, recv), local.lit(x, y, recv));
    }
    const MapStats s = map.stats();
    EXPECT_EQ(s.tiles_received, p.reader->tiles().size());
    EXPECT_EQ(s.crc_errors, 0u);
    EXPECT_EQ(s.tiles_failed, 0u);
    EXPECT_EQ(s.cache.evictions, 0u);
    // Each tile written once (client/tile_arena.hpp): the map tiles only in the arena,
    // which the cache hands out as their bytes, and only the index tiles in their slots.
    uint64_t index_bytes = 0, encoded = 0;
    for (const TileIndexEntry& t : p.reader->tiles()) {
      if (t.kind == TileKind::index) index_bytes += t.raw_size;
      else ++encoded;
    }
    EXPECT_EQ(s.slot_bytes_written, index_bytes);
    EXPECT_GT(s.arena_bytes, 0u);
    EXPECT_LE(s.arena_bytes, encoded * ((map.slot_bytes() + 63) / 64 * 64));
    uint64_t in_pool = 0, in_arena = 0;
    MapAccess::remote(map).inspect_cache([&](const TileCache& c) {
      const uint8_t* p0 = c.pool().data();
      for (uint32_t slot = 0; slot < c.slot_count(); ++slot) {
        if (!c.slot_resident(slot)) continue;
        const std::span<const uint8_t> b = c.tile_bytes(slot);
        const bool pool = b.data() >= p0 && b.data() < p0 + c.pool().size();
        (pool ? in_pool : in_arena) += b.size();
        if (!pool) {  // the slot itself was never written
          const auto own = c.pool().subspan(c.slot_offset(slot), c.slot_bytes());
          EXPECT_TRUE(std::all_of(own.begin(), own.end(), [](uint8_t v) { return v == 0; })) << slot;
        }
      }
    });
    EXPECT_EQ(in_pool, index_bytes);
    EXPECT_GT(in_arena, 0u);
  }
}

TEST(RemoteMap, TinyCacheRandomWalkEvictsRefetchesAndStaysExact) {
  const auto encodings = looptest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t level = test_level(), side = 1u << level;
  auto p = build_pack("walk", level, 7, encodings[0], 3, 512);
  auto srv = start_server({p.path});
  ClientOptions o = quick_options();
  o.cache_slots = 4;  // >= the longest index-tile chain of these packs
  Client client({"127.0.0.1", srv.port}, o);
  Map map = client.open("walk");
  PackEvaluator local(p.reader);
  uint64_t x = side / 2, y = side / 2, seed = 99;
  const int steps = looptest::small_scale() ? 40 : 150;
  for (int step = 0; step < steps; ++step) {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    // Jumps far enough to change cells most of the time.
    x = (x + (seed >> 33) % (side / 2)) % side;
    y = (y + (seed >> 45) % (side / 2)) % side;
    map.cancel_outside(level, x, y, 1, 1);
    // Once resident the answer is exact at every level. A tile from an earlier step may
    // still arrive and evict one of ours, so, like a renderer every frame, ask again on
    // every poll (queued or resident tiles are not asked for twice).
    bool exact = wait_until([&] {
      map.request_region(level, x, y, 1, 1, 5);
      if (!map.region_resident(level, x, y, 1, 1)) return false;
      for (uint32_t l = 0; l <= level; ++l)
        if (bits(map.depth(l, x >> (level - l), y >> (level - l))) != bits(local.depth(l, x >> (level - l), y >> (level - l))))
          return false;
      return true;
    });
    ASSERT_TRUE(exact) << "step " << step << " texel (" << x << ", " << y << ")";
    const MapStats now = map.stats();
    ASSERT_LE(now.arena_bytes + now.slot_bytes_written, uint64_t(now.tile_slots) * ((map.slot_bytes() + 63) / 64 * 64))
        << "step " << step;
  }
  const MapStats s = map.stats();
  EXPECT_GT(s.cache.evictions, 0u);
  EXPECT_LE(s.cache.resident, 4u);
  // The tiles' bytes, in the arena or their slots, within the slots' (tile_arena.hpp).
  EXPECT_LE(s.arena_bytes + s.slot_bytes_written, uint64_t(s.tile_slots) * ((map.slot_bytes() + 63) / 64 * 64));
  EXPECT_EQ(s.tiles_failed, 0u);
}

// A byte budget of kMinTileSlots page-sized slots over a map of more tiles: tiles arrive
// and evict each other, and at every poll the tiles' bytes (the arena's chunks and the
// slot bytes written: client/tile_arena.hpp) stay within the slots' bytes (each tile in
// one place; a slot an index tile wrote gives its pages back before a map tile goes to
// the arena), and the map's accounted bytes never pass the budget.
TEST(RemoteMap, ByteBudgetHoldsTheArenaAndTheSlotsUnderChurn) {
  const auto encodings = looptest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t level = test_level(), side = 1u << level;
  auto p = build_pack("budget", level, 5, encodings[0], 3, 4096);
  auto srv = start_server({p.path});
  ClientOptions big = quick_options();
  big.cache_bytes = uint64_t(16) << 20;
  Client probe({"127.0.0.1", srv.port}, big);
  const Map pm = probe.open("budget");
  const uint64_t per_slot = pm.slot_bytes() + kSlotOverheadBytes;
  const uint64_t meta = pm.stats().accounted_bytes - uint64_t(pm.stats().tile_slots) * per_slot;
  ClientOptions o = quick_options();
  o.cache_bytes = meta + kMinTileSlots * per_slot;
  Client client({"127.0.0.1", srv.port}, o);
  Map map = client.open("budget");
  ASSERT_EQ(map.stats().tile_slots, kMinTileSlots);
  ASSERT_GT(p.reader->tiles().size(), kMinTileSlots + 2u) << "no churn: the test proves nothing";
  uint64_t polls = 0, most = 0;
  const bool done = wait_until([&] {
    map.request_region(level, 0, 0, side, side, 5);
    const MapStats s = map.stats();
    ++polls;
    most = std::max(most, s.arena_bytes + s.slot_bytes_written);
    EXPECT_LE(s.accounted_bytes, o.cache_bytes);
    EXPECT_LE(s.arena_bytes + s.slot_bytes_written, uint64_t(s.tile_slots) * ((map.slot_bytes() + 63) / 64 * 64))
        << s.arena_bytes << " + " << s.slot_bytes_written;
    return s.cache.evictions >= 2 * kMinTileSlots;
  });
  ASSERT_TRUE(done) << map.stats().cache.evictions << " evictions";
  EXPECT_GT(most, 0u);
  EXPECT_GT(polls, 0u);
}

TEST(RemoteMap, WantCapacityBoundsTheQueueAndTheMapStillArrivesWhole) {
  const auto encodings = looptest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t level = test_level(), side = 1u << level;
  auto p = build_pack("bounded", level, 23, encodings[0], 3, 512);
  ClientOptions o = quick_options();
  o.cache_slots = uint32_t(p.reader->tiles().size()) + 4;
  o.want_capacity = 2;  // and one tile in flight: a request table of 3 records
  o.max_in_flight = 1;
  o.tiles_per_request = 1;
  auto srv = start_server({p.path});
  Client client({"127.0.0.1", srv.port}, o);
  Map map = client.open("bounded");
  // One call queues under one lock, so the fetcher cannot drain the queue meanwhile.
  EXPECT_EQ(map.request_region(level, 0, 0, side, side, 1), 2u);
  EXPECT_GT(map.stats().queue_full, 0u);
  ASSERT_TRUE(wait_until([&] {
    map.request_region(level, 0, 0, side, side, 1);
    return map.region_resident(level, 0, 0, side, side);
  }));
  PackEvaluator local(p.reader);
  EXPECT_EQ(first_difference(client::evaluator(map), local), "");
  const MapStats s = map.stats();
  EXPECT_EQ(s.tiles_received, p.reader->tiles().size());
  EXPECT_EQ(s.tiles_requested, p.reader->tiles().size()) << "each tile asked for once";
  EXPECT_EQ(s.tiles_failed, 0u);
}

// A server whose tile sends wait at a gate: nothing arrives until the test opens it.
struct Gate {
  std::atomic<bool> open{false};
  void wait() const {
    for (int i = 0; i < 20000 && !open.load(); ++i) std::this_thread::sleep_for(1ms);
  }
};

TEST(RemoteMap, AnswersFromTheCoarserLevelUntilTilesArrive) {
  const auto encodings = looptest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t level = test_level(), side = 1u << level, k = 3;
  auto p = build_pack("coarse", level, 5, encodings[0], k, 1024);
  auto gate = std::make_shared<Gate>();
  server::ServerOptions so;
  so.tile_source = std::make_shared<looptest::WatchedTiles>([gate](uint64_t, std::span<uint8_t>) { gate->wait(); });
  auto srv = start_server({p.path}, so);
  Client client({"127.0.0.1", srv.port}, quick_options());
  Map map = client.open("coarse");
  PackEvaluator local(p.reader);
  // Nothing resident: every level answers, levels <= K + p exactly (the skip grid, then
  // the map preview's p levels), finer levels with the value of the level-(K + p) node
  // above them.
  const uint32_t kp = k + p.reader->preview().levels();
  ASSERT_GT(kp, k);
  for (uint32_t l = 0; l <= level; ++l)
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) {
        const float want = l <= kp ? local.depth(l, x, y) : local.depth(kp, x >> (l - kp), y >> (l - kp));
        ASSERT_EQ(bits(map.depth(l, x, y)), bits(want)) << "level " << l << " (" << x << ", " << y << ")";
      }
  EXPECT_GT(map.stats().coarse_answers, 0u);
  EXPECT_GT(map.stats().cache.misses, 0u);
  EXPECT_FALSE(map.region_resident(level, 0, 0, side, side));
  gate->open = true;
  map.request_region(level, 0, 0, side, side, 1);
  ASSERT_TRUE(wait_until([&] { return map.region_resident(level, 0, 0, side, side); }));
  EXPECT_EQ(first_difference(client::evaluator(map), local), "");
}

TEST(RemoteMap, CorruptPayloadIsCaughtByTheCrcAndRefetched) {
  const auto encodings = looptest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t level = test_level(), side = 1u << level;
  auto p = build_pack("corrupt_once", level, 11, encodings[0], 3, 1024);
  // Every tile's first send has one byte flipped (after pread, so the server's own CRC
  // check on read passes and only the client can notice).
  auto seen = std::make_shared<std::pair<std::mutex, std::set<uint64_t>>>();
  server::ServerOptions so;
  so.tile_source = std::make_shared<looptest::WatchedTiles>([seen](uint64_t id, std::span<uint8_t> bytes) {
    std::lock_guard lock(seen->first);
    if (seen->second.insert(id).second && !bytes.empty()) bytes[bytes.size() / 2] ^= 0x40;
  });
  auto srv = start_server({p.path}, so);
  ClientOptions o = quick_options();
  o.cache_slots = uint32_t(p.reader->tiles().size()) + 4;
  Client client({"127.0.0.1", srv.port}, o);
  Map map = client.open("corrupt_once");
  map.request_region(level, 0, 0, side, side, 3);
  ASSERT_TRUE(wait_until([&] { return map.region_resident(level, 0, 0, side, side); }));
  PackEvaluator local(p.reader);
  EXPECT_EQ(first_difference(client::evaluator(map), local), "");
  const MapStats s = map.stats();
  EXPECT_EQ(s.crc_errors, p.reader->tiles().size());
  EXPECT_EQ(s.tiles_received, p.reader->tiles().size());
  EXPECT_EQ(s.tiles_failed, 0u);
}

// A pack without index tiles and its first tile, which sits at the skip level.
struct GivenUpCase {
  looptest::TestPack pack;
  uint32_t level, k = 3;
  uint64_t bad = 0;
};

GivenUpCase given_up_case(const std::string& name, uint64_t seed) {
  const auto encodings = looptest::available_encodings();
  ST_CHECK(!encodings.empty());
  GivenUpCase c;
  c.level = test_level();
  c.pack = build_pack(name, c.level, seed, encodings[0], c.k, 1 << 20);  // no index tiles
  ST_CHECK(!c.pack.reader->tiles().empty());
  c.bad = c.pack.reader->tiles().front().id;
  ST_CHECK(tile_address(c.bad).level == c.k);
  return c;
}

// Fetches the whole map with `max_tile_retries` 2 until every tile but c.bad arrived and
// c.bad was given up; then its texels answer from level k and the rest exactly.
MapStats expect_given_up(const GivenUpCase& c, uint16_t port) {
  const uint32_t side = 1u << c.level;
  const size_t total = c.pack.reader->tiles().size();
  ClientOptions o = quick_options();
  o.cache_slots = uint32_t(total) + 4;
  o.max_tile_retries = 2;
  Client client({"127.0.0.1", port}, o);
  Map map = client.open(std::filesystem::path(c.pack.path).stem().string());
  map.request_region(c.level, 0, 0, side, side, 3);
  EXPECT_TRUE(wait_until([&] {
    MapStats s = map.stats();
    return s.tiles_failed == 1 && s.tiles_received + 1 == total;
  }));
  PackEvaluator local(c.pack.reader);
  const TileAddress a = tile_address(c.bad);
  const uint32_t s = c.level - c.k;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const bool under_bad = (x >> s) == a.x && (y >> s) == a.y;
      const float want = under_bad ? local.depth(c.k, a.x, a.y) : local.depth(c.level, x, y);
      if (bits(map.depth(c.level, x, y)) != bits(want)) {
        ADD_FAILURE() << "(" << x << ", " << y << "): got " << map.depth(c.level, x, y) << ", want " << want;
        return map.stats();
      }
    }
  const MapStats after = map.stats();
  EXPECT_EQ(after.tiles_failed, 1u);  // lookups did not ask for it again
  return after;
}

TEST(RemoteMap, AlwaysCorruptTileIsGivenUpAndItsTexelsStayCoarse) {
  const GivenUpCase c = given_up_case("corrupt_always", 13);
  server::ServerOptions so;
  so.tile_source = std::make_shared<looptest::WatchedTiles>([bad = c.bad](uint64_t id, std::span<uint8_t> bytes) {
    if (id == bad && !bytes.empty()) bytes[0] ^= 0x01;
  });
  auto srv = start_server({c.pack.path}, so);
  const MapStats s = expect_given_up(c, srv.port);
  EXPECT_EQ(s.crc_errors, 3u);  // the first try and two retries
  EXPECT_EQ(s.decode_errors, 0u);
}

// `stored` with a few bits of its last 5 bytes flipped such that its CRC-32 is unchanged
// (CRC is linear: 40 single-bit flips span at most 32 dimensions, so some nonzero set of
// them cancels out). The last 4 bytes are the zlib stream's Adler-32.
std::vector<uint8_t> same_crc_other_bytes(std::vector<uint8_t> stored) {
  ST_CHECK(stored.size() >= 5);
  const size_t base = stored.size() - 5;
  const uint32_t crc = crc32_of(stored);
  auto delta_of_bit = [&](unsigned k) {
    stored[base + k / 8] ^= uint8_t(1u << (k % 8));
    const uint32_t d = crc32_of(stored) ^ crc;
    stored[base + k / 8] ^= uint8_t(1u << (k % 8));
    return d;
  };
  struct Row {
    uint32_t delta = 0;
    uint64_t bits = 0;  // which of the 40 flips make it up
  };
  Row basis[32];  // by highest set bit of delta
  for (unsigned k = 0; k < 40; ++k) {
    Row r{delta_of_bit(k), uint64_t(1) << k};
    for (int b = 31; b >= 0 && r.delta; --b)
      if ((r.delta >> b & 1) && basis[b].bits) r.delta ^= basis[b].delta, r.bits ^= basis[b].bits;
    if (r.delta == 0) {
      for (unsigned j = 0; j < 40; ++j)
        if (r.bits >> j & 1) stored[base + j / 8] ^= uint8_t(1u << (j % 8));
      ST_CHECK(crc32_of(stored) == crc);
      return stored;
    }
    basis[31 - std::countl_zero(r.delta)] = r;
  }
  ST_CHECK(false);  // unreachable: 40 vectors in a 32-dimensional space are dependent
  return stored;
}

TEST(RemoteMap, TileMatchingItsCrcButNotDecodingIsRetriedThenGivenUp) {
  const GivenUpCase c = given_up_case("undecodable", 17);
  const std::vector<uint8_t> good = c.pack.reader->read_stored(c.bad);
  const std::vector<uint8_t> forged = same_crc_other_bytes(good);
  ASSERT_NE(forged, good);
  ASSERT_EQ(crc32_of(forged), crc32_of(good));
  ASSERT_THROW(zlib_decompress(forged, c.pack.reader->find(c.bad)->raw_size, "forged"), Error);
  server::ServerOptions so;
  so.tile_source = std::make_shared<looptest::WatchedTiles>([bad = c.bad, forged](uint64_t id, std::span<uint8_t> bytes) {
    if (id == bad && bytes.size() == forged.size()) std::copy(forged.begin(), forged.end(), bytes.begin());
  });
  auto srv = start_server({c.pack.path}, so);
  const MapStats s = expect_given_up(c, srv.port);
  EXPECT_EQ(s.crc_errors, 0u);      // the end-to-end CRC passed every time
  EXPECT_EQ(s.decode_errors, 3u);   // the first try and two retries, then given up
  EXPECT_EQ(s.cache.resident, c.pack.reader->tiles().size() - 1) << "the failed slot was given back";
}

}  // namespace remote_map_test
}  // namespace st::client

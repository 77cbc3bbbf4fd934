// Loopback tests of the client against an in-process server: every tile fetched answers
// bit-exactly like the local PackEvaluator; a tiny cache evicts, refetches and stays
// exact; answers before a tile arrives come from the coarser level; corrupt payloads
// are caught by the end-to-end CRC and refetched or given up.
#include <gtest/gtest.h>

#include <atomic>
#include <bit>
#include <mutex>
#include <set>
#include <thread>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::start_server;
using looptest::wait_until;

uint32_t test_level() { return looptest::small_scale() ? 6 : 7; }
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
  }
  const MapStats s = map.stats();
  EXPECT_GT(s.cache.evictions, 0u);
  EXPECT_LE(s.cache.resident, 4u);
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
  so.tile_hook = [gate](uint64_t, std::span<uint8_t>) { gate->wait(); };
  auto srv = start_server({p.path}, so);
  Client client({"127.0.0.1", srv.port}, quick_options());
  Map map = client.open("coarse");
  PackEvaluator local(p.reader);
  // Nothing resident: every level answers, levels < K exactly, finer levels with the
  // value of their skip-grid entry (the level-K node above them).
  for (uint32_t l = 0; l <= level; ++l)
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) {
        const float want = l <= k ? local.depth(l, x, y) : local.depth(k, x >> (l - k), y >> (l - k));
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
  so.tile_hook = [seen](uint64_t id, std::span<uint8_t> bytes) {
    std::lock_guard lock(seen->first);
    if (seen->second.insert(id).second && !bytes.empty()) bytes[bytes.size() / 2] ^= 0x40;
  };
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

TEST(RemoteMap, AlwaysCorruptTileIsGivenUpAndItsTexelsStayCoarse) {
  const auto encodings = looptest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t level = test_level(), side = 1u << level, k = 3;
  auto p = build_pack("corrupt_always", level, 13, encodings[0], k, 1 << 20);  // no index tiles
  ASSERT_FALSE(p.reader->tiles().empty());
  const uint64_t bad = p.reader->tiles().front().id;
  const TileAddress a = tile_address(bad);
  ASSERT_EQ(a.level, k);
  server::ServerOptions so;
  so.tile_hook = [bad](uint64_t id, std::span<uint8_t> bytes) {
    if (id == bad && !bytes.empty()) bytes[0] ^= 0x01;
  };
  auto srv = start_server({p.path}, so);
  ClientOptions o = quick_options();
  o.cache_slots = uint32_t(p.reader->tiles().size()) + 4;
  o.max_tile_retries = 2;
  Client client({"127.0.0.1", srv.port}, o);
  Map map = client.open("corrupt_always");
  map.request_region(level, 0, 0, side, side, 3);
  ASSERT_TRUE(wait_until([&] {
    MapStats s = map.stats();
    return s.tiles_failed == 1 && s.tiles_received + 1 == p.reader->tiles().size();
  }));
  EXPECT_EQ(map.stats().crc_errors, 3u);  // the first try and two retries
  PackEvaluator local(p.reader);
  const uint32_t s = level - k;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const bool under_bad = (x >> s) == a.x && (y >> s) == a.y;
      const float want = under_bad ? local.depth(k, a.x, a.y) : local.depth(level, x, y);
      ASSERT_EQ(bits(map.depth(level, x, y)), bits(want)) << "(" << x << ", " << y << ")";
    }
  EXPECT_EQ(map.stats().tiles_failed, 1u);  // lookups did not ask for it again
}

}  // namespace
}  // namespace st::client

// A RemoteMap's request bookkeeping driven directly, without a network: what the
// fetcher takes (priority order, FIFO among equals, raises), how answers are matched to
// the GetTiles that carried them, retries then giving up, cancel_outside (queued ones
// dropped, sent ones cancelled once), connection_lost and the want_capacity bound.
#include <gtest/gtest.h>

#include <bit>

#include "client/remote_map.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace {

struct Fixture {
  looptest::TestPack pack;
  uint32_t level = 0, k = 3;
  std::vector<uint64_t> tiles;  // encoded tiles right below the skip grid
  std::unique_ptr<RemoteMap> map;

  // Queues `tile` through the region of its first finest-level texel.
  size_t want(uint64_t tile, uint16_t priority) const {
    const TileAddress a = tile_address(tile);
    const uint32_t s = level - a.level;
    return map->request_region(level, uint64_t(a.x) << s, uint64_t(a.y) << s, 1, 1, priority);
  }
  std::vector<proto::TileRequest> take(uint32_t request_id, size_t max = 64) const {
    std::vector<proto::TileRequest> out;
    map->take_wanted(max, request_id, out);
    return out;
  }
  proto::TileMeta meta_of(uint64_t tile) const {
    const TileIndexEntry e = *pack.reader->find(tile);
    proto::TileMeta m;
    m.tile_id = tile;
    m.map_id = 1;
    m.flags = proto::kTileFlagZlib;
    m.uncompressed_size = e.raw_size;
    m.payload_crc32 = e.crc;
    return m;
  }
  void deliver(uint64_t tile, uint32_t request_id) const {
    const std::vector<uint8_t> stored = pack.reader->read_stored(tile);
    map->tile_arrived(meta_of(tile), request_id, stored);
  }
  void deliver_corrupt(uint64_t tile, uint32_t request_id) const {
    std::vector<uint8_t> stored = pack.reader->read_stored(tile);
    stored[stored.size() / 2] ^= 0x20;
    map->tile_arrived(meta_of(tile), request_id, stored);
  }
  bool resident(uint64_t tile) const {
    const TileAddress a = tile_address(tile);
    const uint32_t s = level - a.level;
    return map->region_resident(level, uint64_t(a.x) << s, uint64_t(a.y) << s, 1, 1);
  }
};

// tile_bytes 1 MiB: no index tiles (every tile sits right below the skip grid); 512: index
// tiles with encoded tiles below them.
// level 0: 6 under SHADOWTILE_TEST_SCALE=small, else 7.
Fixture make_fixture(const std::string& name, ClientOptions o = looptest::quick_options(),
                     uint32_t tile_bytes = 1 << 20, uint32_t level = 0) {
  Fixture f;
  f.level = level ? level : looptest::small_scale() ? 6 : 7;
  f.pack = looptest::build_pack(name, f.level, 29, looptest::first_encoding(), f.k, tile_bytes);
  for (const TileIndexEntry& e : f.pack.reader->tiles())
    if (tile_address(e.id).level == f.k) f.tiles.push_back(e.id);
  ST_CHECK(f.tiles.size() >= 4);
  o.cache_slots = uint32_t(f.pack.reader->tiles().size()) + 4;  // nothing evicted
  const auto h = f.pack.reader->header_bytes();
  const auto g = f.pack.reader->grid_bytes();
  f.map = std::make_unique<RemoteMap>(name, std::vector<uint8_t>(h.begin(), h.end()),
                                      std::vector<uint8_t>(g.begin(), g.end()), o, std::make_shared<Notifier>());
  return f;
}

std::vector<uint64_t> ids(const std::vector<proto::TileRequest>& r) {
  std::vector<uint64_t> out;
  for (const auto& t : r) out.push_back(t.tile_id);
  return out;
}

TEST(RemoteMapRequests, TakenHighestPriorityFirstFifoAmongEqualsAndRaisesCount) {
  Fixture f = make_fixture("req_order");
  const auto& t = f.tiles;
  EXPECT_EQ(f.want(t[0], 1), 1u);
  EXPECT_EQ(f.want(t[1], 5), 1u);
  EXPECT_EQ(f.want(t[2], 1), 1u);
  EXPECT_EQ(f.want(t[3], 5), 1u);
  EXPECT_EQ(f.want(t[0], 1), 0u) << "already queued at that priority";
  EXPECT_EQ(f.want(t[2], 5), 1u) << "raised: behind the ones already at 5";
  const auto taken = f.take(100);
  EXPECT_EQ(ids(taken), (std::vector<uint64_t>{t[1], t[3], t[2], t[0]}));
  EXPECT_EQ(taken[2].priority, 5);
  EXPECT_EQ(f.map->sent_count(), 4u);
  EXPECT_EQ(f.want(t[0], 9), 0u) << "sent: nothing to raise";
  EXPECT_EQ(f.map->stats().tiles_requested, 4u);
}

TEST(RemoteMapRequests, AnswersCountOnlyForTheRequestThatCarriedTheTile) {
  Fixture f = make_fixture("req_match");
  const uint64_t tile = f.tiles[0];
  f.want(tile, 1);
  ASSERT_EQ(f.take(7).size(), 1u);
  f.deliver(tile, 8);  // another request id: a stray answer
  EXPECT_FALSE(f.resident(tile));
  EXPECT_EQ(f.map->sent_count(), 1u);
  f.deliver(tile, 7);
  EXPECT_TRUE(f.resident(tile));
  EXPECT_EQ(f.map->sent_count(), 0u);
  f.deliver(tile, 7);  // a late duplicate changes nothing
  const MapStats s = f.map->stats();
  EXPECT_EQ(s.tiles_received, 1u);
  EXPECT_EQ(s.cache.resident, 1u);
  PackEvaluator local(f.pack.reader);
  const TileAddress a = tile_address(tile);
  const uint32_t sh = f.level - f.k;
  for (uint64_t y = uint64_t(a.y) << sh; y < uint64_t(a.y + 1) << sh; ++y)
    for (uint64_t x = uint64_t(a.x) << sh; x < uint64_t(a.x + 1) << sh; ++x)
      ASSERT_EQ(std::bit_cast<uint32_t>(f.map->depth(f.level, x, y)),
                std::bit_cast<uint32_t>(local.depth(f.level, x, y)));
}

TEST(RemoteMapRequests, FailedDeliveriesAreRetriedThenGivenUpAnsweringTheEntryValue) {
  ClientOptions o = looptest::quick_options();
  o.max_tile_retries = 2;
  Fixture f = make_fixture("req_retry", o);
  const uint64_t tile = f.tiles[1];
  f.want(tile, 4);
  for (uint32_t attempt = 0; attempt <= o.max_tile_retries; ++attempt) {
    const auto taken = f.take(10 + attempt);
    ASSERT_EQ(ids(taken), std::vector<uint64_t>{tile}) << "attempt " << attempt;
    EXPECT_EQ(taken[0].priority, 4) << "retried at its own priority";
    f.deliver_corrupt(tile, 10 + attempt);
  }
  EXPECT_TRUE(f.take(20).empty());
  MapStats s = f.map->stats();
  EXPECT_EQ(s.crc_errors, 3u);
  EXPECT_EQ(s.tiles_failed, 1u);
  EXPECT_EQ(f.map->sent_count(), 0u);
  // Given up: a constant page answering the entry's value (the level-k node's depth).
  PackEvaluator local(f.pack.reader);
  const TileAddress a = tile_address(tile);
  const uint32_t sh = f.level - f.k;
  EXPECT_EQ(std::bit_cast<uint32_t>(f.map->depth(f.level, uint64_t(a.x) << sh, uint64_t(a.y) << sh)),
            std::bit_cast<uint32_t>(local.depth(f.k, a.x, a.y)));
  EXPECT_EQ(f.want(tile, 9), 0u) << "never asked for again";
  EXPECT_TRUE(f.take(21).empty());
}

TEST(RemoteMapRequests, CancelOutsideDropsQueuedAndCancelsSentOnce) {
  Fixture f = make_fixture("req_cancel");
  const auto& t = f.tiles;
  f.want(t[0], 1);
  f.want(t[1], 1);
  ASSERT_EQ(f.take(30, 1).size(), 1u);  // t[0] sent, t[1] still queued
  f.want(t[2], 1);
  // Keep only t[2]'s texel.
  const TileAddress keep = tile_address(t[2]);
  const uint32_t sh = f.level - f.k;
  auto cancel = [&] { return f.map->cancel_outside(f.level, uint64_t(keep.x) << sh, uint64_t(keep.y) << sh, 1, 1); };
  EXPECT_EQ(cancel(), 2u);
  std::vector<uint64_t> cancels;
  f.map->take_cancels(cancels);
  EXPECT_EQ(cancels, std::vector<uint64_t>{t[0]});
  EXPECT_EQ(cancel(), 0u) << "one Cancel per sent tile";
  cancels.clear();
  f.map->take_cancels(cancels);
  EXPECT_TRUE(cancels.empty());
  EXPECT_EQ(ids(f.take(31)), std::vector<uint64_t>{t[2]}) << "t[1] was dropped from the queue";
  f.map->tile_refused(t[0], 30, proto::ErrorCode::cancelled);
  EXPECT_EQ(f.map->stats().tiles_cancelled, 1u);
  EXPECT_EQ(f.map->sent_count(), 1u);  // t[2]
  EXPECT_EQ(f.want(t[0], 1), 1u) << "cancelled: absent again, so it can be wanted again";
  EXPECT_EQ(f.want(t[1], 1), 1u);
}

TEST(RemoteMapRequests, ConnectionLostQueuesSentTilesAgainButNotCancelledOnes) {
  Fixture f = make_fixture("req_lost");
  const auto& t = f.tiles;
  f.want(t[0], 2);
  f.want(t[1], 7);
  f.want(t[2], 2);
  ASSERT_EQ(f.take(40).size(), 3u);
  const TileAddress keep = tile_address(t[1]);
  const uint32_t sh = f.level - f.k;
  // t[1] stays; t[0] and t[2] get a Cancel, then the connection drops.
  EXPECT_EQ(f.map->cancel_outside(f.level, uint64_t(keep.x) << sh, uint64_t(keep.y) << sh, 1, 1), 2u);
  f.want(t[3], 1);
  f.map->connection_lost();
  std::vector<uint64_t> cancels;
  f.map->take_cancels(cancels);
  EXPECT_TRUE(cancels.empty()) << "Cancels belong to the connection that is gone";
  EXPECT_EQ(f.map->sent_count(), 0u);
  EXPECT_EQ(ids(f.take(41)), (std::vector<uint64_t>{t[1], t[3]}));
  f.deliver(t[1], 40);  // an answer from the old connection's request: ignored
  EXPECT_FALSE(f.resident(t[1]));
  f.deliver(t[1], 41);
  EXPECT_TRUE(f.resident(t[1]));
}

TEST(RemoteMapRequests, WantCapacityBoundsTheQueueNotTheTilesInFlight) {
  ClientOptions o = looptest::quick_options();
  o.want_capacity = 2;
  o.max_in_flight = 1;
  o.tiles_per_request = 2;
  Fixture f = make_fixture("req_bound", o);
  const auto& t = f.tiles;
  EXPECT_EQ(f.want(t[0], 1), 1u);
  EXPECT_EQ(f.want(t[1], 1), 1u);
  EXPECT_EQ(f.want(t[2], 1), 0u);
  EXPECT_EQ(f.map->stats().queue_full, 1u);
  ASSERT_EQ(f.take(50, 2).size(), 2u);  // in flight: the queue has room again
  EXPECT_EQ(f.want(t[2], 1), 1u);
  // Both sent ones come back, but only one fits beside t[2]; the other is dropped
  // (absent again) until it is wanted again.
  f.map->connection_lost();
  EXPECT_EQ(f.map->sent_count(), 0u);
  const auto again = ids(f.take(52));
  ASSERT_EQ(again.size(), 2u);
  EXPECT_EQ(again[0], t[2]) << "queued before the connection dropped";
  ASSERT_TRUE(again[1] == t[0] || again[1] == t[1]);
  EXPECT_EQ(f.want(again[1] == t[0] ? t[1] : t[0], 1), 1u);
}

// A region asked for while its index tile is on the way gets the index tile's children when
// it arrives, however many other regions were asked for meanwhile (the client keeps the
// regions not yet resident, not the newest N asked for: a report's cut asks for hundreds).
TEST(RemoteMapRequests, ChildrenOfALateIndexTileFollowAfterManyOtherRegions) {
  ClientOptions o = looptest::quick_options();
  o.want_capacity = 1u << 12;
  Fixture f = make_fixture("req_late_index", o, 512, 7);  // level 7 at every scale: index tiles below the grid
  uint64_t index = kInvalidTile;
  for (const TileIndexEntry& e : f.pack.reader->tiles())
    if (e.kind == TileKind::index && tile_address(e.id).level == f.k) index = e.id;
  ASSERT_NE(index, kInvalidTile) << "no index tile below the skip grid";
  const TileAddress a = tile_address(index);
  const uint32_t s = f.level - a.level;
  const uint64_t x0 = uint64_t(a.x) << s, y0 = uint64_t(a.y) << s, side = uint64_t(1) << s;
  EXPECT_EQ(f.map->request_region(f.level, x0, y0, side, side, 3), 1u) << "the index tile only: its children unknown";
  ASSERT_EQ(ids(f.take(1, 1u << 12)), std::vector<uint64_t>{index});
  // 1,500 single texels elsewhere, each delivered before the next is asked for.
  uint32_t request_id = 2;
  size_t asked = 0;
  const uint64_t n = uint64_t(1) << f.level;
  for (uint64_t i = 0; i < n * n && asked < 1500; i += 3) {
    const uint64_t x = i % n, y = i / n;
    if (x >= x0 && x < x0 + side && y >= y0 && y < y0 + side) continue;
    f.map->request_region(f.level, x, y, 1, 1, 1);
    ++asked;
    for (auto t = f.take(request_id, 1u << 12); !t.empty(); t = f.take(++request_id, 1u << 12))
      for (const auto& r : t) f.deliver(r.tile_id, request_id);
    ++request_id;
  }
  ASSERT_EQ(asked, 1500u);
  ASSERT_FALSE(f.map->region_resident(f.level, x0, y0, side, side));
  f.deliver(index, 1);  // its children are wanted now, nobody asked again
  size_t delivered = 0;
  for (auto t = f.take(request_id, 1u << 12); !t.empty(); t = f.take(++request_id, 1u << 12))
    for (const auto& r : t) {
      f.deliver(r.tile_id, request_id);
      ++delivered;
    }
  EXPECT_GT(delivered, 0u);
  EXPECT_TRUE(f.map->region_resident(f.level, x0, y0, side, side));
}

}  // namespace
}  // namespace st::client

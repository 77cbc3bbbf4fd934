// The per-connection tile queue: priority order, FIFO ties, FINAL detection, bounded
// capacity and cancellation; checked against a sorted reference on random sequences.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "server/server_stats.hpp"
#include "server/tile_queue.hpp"

namespace st::server {
namespace {

PendingTile tile(uint32_t req, uint64_t id, uint32_t prio) {
  PendingTile t;
  t.request_id = req;
  t.tile = id;
  t.priority = prio;
  return t;
}

TEST(TileQueue, HigherPriorityFirstFifoWithinPriorityAndFinalOnLast) {
  TileQueue q(10);
  ASSERT_TRUE(q.push(tile(1, 10, 1)));
  ASSERT_TRUE(q.push(tile(1, 11, 5)));
  ASSERT_TRUE(q.push(tile(2, 20, 5)));
  ASSERT_TRUE(q.push(tile(2, 21, 0)));
  std::vector<uint64_t> order;
  std::vector<bool> finals;
  while (auto p = q.pop()) order.push_back(p->tile.tile), finals.push_back(p->last_of_request);
  EXPECT_EQ(order, (std::vector<uint64_t>{11, 20, 10, 21}));
  EXPECT_EQ(finals, (std::vector<bool>{false, false, true, true}));
}

TEST(TileQueue, BoundedAndCancelledTilesAnsweredFirst) {
  TileQueue q(3);
  PendingTile a = tile(1, 1, 0), b = tile(1, 2, 9), c = tile(2, 3, 5);
  a.map_id = b.map_id = c.map_id = 7;
  EXPECT_TRUE(q.push(a));
  EXPECT_TRUE(q.push(b));
  EXPECT_TRUE(q.push(c));
  EXPECT_FALSE(q.push(tile(2, 4, 0)));
  uint64_t one[] = {1};
  EXPECT_EQ(q.cancel_tiles(8, one), 0u);  // other map
  EXPECT_EQ(q.cancel_tiles(7, one), 1u);
  EXPECT_EQ(q.cancel_tiles(7, one), 0u);  // already cancelled
  EXPECT_EQ(q.pending(1), 2u);            // still owed an answer
  auto p = q.pop();
  ASSERT_TRUE(p);
  EXPECT_EQ(p->tile.tile, 1u);
  EXPECT_TRUE(p->tile.cancelled);
  EXPECT_FALSE(p->last_of_request);
  EXPECT_EQ(q.cancel_request(2), 1u);
  p = q.pop();
  EXPECT_EQ(p->tile.tile, 3u);
  EXPECT_TRUE(p->tile.cancelled);
  EXPECT_TRUE(p->last_of_request);
  p = q.pop();
  EXPECT_EQ(p->tile.tile, 2u);
  EXPECT_FALSE(p->tile.cancelled);
  EXPECT_TRUE(p->last_of_request);
  EXPECT_FALSE(q.pop());
}

TEST(TileQueueProperty, MatchesSortedReference) {
  std::mt19937 rng(7);
  for (int round = 0; round < 200; ++round) {
    TileQueue q(64);
    struct Ref { bool cancelled; uint32_t prio; uint64_t seq; PendingTile t; };
    std::vector<Ref> ref;
    uint64_t seq = 0;
    for (int step = 0; step < 400; ++step) {
      uint32_t op = rng() % 10;
      if (op < 5) {
        PendingTile t = tile(1 + rng() % 4, rng() % 16, rng() % 4);
        t.map_id = 1 + rng() % 2;
        bool ok = q.push(t);
        EXPECT_EQ(ok, ref.size() < 64);
        if (ok) ref.push_back({false, t.priority, seq++, t});
      } else if (op < 9) {
        auto p = q.pop();
        ASSERT_EQ(bool(p), !ref.empty());
        if (!p) continue;
        auto best = std::min_element(ref.begin(), ref.end(), [](const Ref& a, const Ref& b) {
          if (a.cancelled != b.cancelled) return a.cancelled;
          if (a.cancelled) return a.seq < b.seq;  // cancelled: in cancellation order
          return a.prio != b.prio ? a.prio > b.prio : a.seq < b.seq;
        });
        EXPECT_EQ(p->tile.tile, best->t.tile);
        EXPECT_EQ(p->tile.request_id, best->t.request_id);
        EXPECT_EQ(p->tile.cancelled, best->cancelled);
        uint32_t req = best->t.request_id;
        ref.erase(best);
        bool last = std::none_of(ref.begin(), ref.end(), [&](const Ref& r) { return r.t.request_id == req; });
        EXPECT_EQ(p->last_of_request, last);
      } else if (rng() % 2) {  // by tile: a few ids of map 1 or 2, duplicates included
        const uint32_t map = 1 + rng() % 2;
        std::vector<uint64_t> ids;
        for (uint32_t i = 0, n = rng() % 6; i < n; ++i) ids.push_back(rng() % 16);
        std::vector<Ref*> hit;
        for (Ref& r : ref)
          if (r.t.map_id == map && !r.cancelled && std::find(ids.begin(), ids.end(), r.t.tile) != ids.end())
            hit.push_back(&r);
        std::sort(hit.begin(), hit.end(), [](const Ref* a, const Ref* b) {
          return a->prio != b->prio ? a->prio > b->prio : a->seq < b->seq;
        });
        for (Ref* r : hit) r->cancelled = true, r->seq = seq++;
        EXPECT_EQ(q.cancel_tiles(map, ids), hit.size());
      } else {
        uint32_t req = 1 + rng() % 4;
        // Newly cancelled tiles keep their relative queue order (priority, then age).
        std::vector<Ref*> hit;
        for (Ref& r : ref)
          if (r.t.request_id == req && !r.cancelled) hit.push_back(&r);
        std::sort(hit.begin(), hit.end(), [](const Ref* a, const Ref* b) {
          return a->prio != b->prio ? a->prio > b->prio : a->seq < b->seq;
        });
        for (Ref* r : hit) r->cancelled = true, r->seq = seq++;
        size_t want = hit.size();
        EXPECT_EQ(q.cancel_request(req), want);
      }
      ASSERT_EQ(q.size(), ref.size());
    }
  }
}

TEST(ServerStats, LatencyQuantilesAndNamedCounters) {
  ServerStats s;
  for (int i = 0; i < 99; ++i) s.latency(100);  // bucket [64, 128)
  s.latency(5000);                              // bucket [4096, 8192)
  s.tile_sent(1000);
  s.connection_opened();
  auto snap = s.snapshot();
  EXPECT_EQ(snap.latency_quantile_us(0.5), 128u);
  EXPECT_EQ(snap.latency_quantile_us(1.0), 8192u);
  EXPECT_EQ(snap.tiles_sent, 1u);
  EXPECT_EQ(snap.tile_bytes_sent, 1000u);
  EXPECT_EQ(snap.connections_open, 1u);
  EXPECT_NE(snap.line().find("tiles 1 (1000 B)"), std::string::npos);
  EXPECT_EQ(snap.named().front().first, "connections_total");
}

}  // namespace
}  // namespace st::server

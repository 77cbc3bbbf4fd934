// The client's tile request table (client/tile_requests.hpp): one record per tile id,
// bounded by its capacity and queue capacity, popped highest priority first with FIFO
// among equals, stale queue items skipped and compacted away; plus random operations
// checked against a plain reference model.
#include <gtest/gtest.h>

#include <map>
#include <optional>
#include <random>
#include <vector>

#include "client/tile_requests.hpp"

namespace st::client {
namespace {

GridEntry entry_of(float v) {
  GridEntry e;
  e.value = v;
  e.kind = EntryKind::tile;
  return e;
}

// Pops everything queued; returns the tiles in pop order.
std::vector<TileId> drain(TileRequests& t, uint32_t request_id = 7) {
  std::vector<TileId> out;
  while (RequestRecord* r = t.pop(request_id)) out.push_back(r->tile);
  return out;
}

TEST(ClientTileRequests, InsertFindErase) {
  TileRequests t(8, 8);
  EXPECT_EQ(t.find(5), nullptr);
  RequestRecord* r = t.insert(5, entry_of(0.25f), 3);
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->tile, 5u);
  EXPECT_EQ(r->priority, 3);
  EXPECT_EQ(r->state, RequestState::queued);
  EXPECT_EQ(r->retries, 0u);
  EXPECT_EQ(r->entry, entry_of(0.25f));
  EXPECT_EQ(t.find(5), r);
  EXPECT_EQ(t.insert(5, entry_of(1), 9), nullptr) << "one record per tile id";
  EXPECT_EQ(t.size(), 1u);
  EXPECT_EQ(t.queued(), 1u);
  t.erase(*r);
  EXPECT_EQ(t.find(5), nullptr);
  EXPECT_EQ(t.size(), 0u);
  EXPECT_EQ(t.queued(), 0u);
  EXPECT_EQ(t.pop(1), nullptr) << "the erased record's queue item is stale";
  EXPECT_EQ(t.insert(kInvalidTile, entry_of(0), 1), nullptr);
}

TEST(ClientTileRequests, CapacityAndQueueCapacityBound) {
  TileRequests t(4, 2);
  ASSERT_NE(t.insert(1, entry_of(0), 1), nullptr);
  ASSERT_NE(t.insert(2, entry_of(0), 1), nullptr);
  EXPECT_EQ(t.insert(3, entry_of(0), 1), nullptr) << "queue full";
  // Sent records leave the queue but keep their place in the table.
  ASSERT_NE(t.pop(10), nullptr);
  ASSERT_NE(t.pop(10), nullptr);
  EXPECT_EQ(t.in_flight(), 2u);
  ASSERT_NE(t.insert(3, entry_of(0), 1), nullptr);
  ASSERT_NE(t.insert(4, entry_of(0), 1), nullptr);
  EXPECT_EQ(t.insert(5, entry_of(0), 1), nullptr) << "table full";
  EXPECT_FALSE(t.requeue(*t.find(1))) << "no room in the queue to send it again";
  EXPECT_EQ(t.find(1)->state, RequestState::sent);
  t.erase(*t.find(3));
  EXPECT_TRUE(t.requeue(*t.find(1)));
  EXPECT_EQ(t.find(1)->state, RequestState::queued);
  EXPECT_EQ(t.find(1)->request_id, 0u);
  EXPECT_THROW(TileRequests(0, 0), Error);
  EXPECT_THROW(TileRequests(2, 3), Error);
}

TEST(ClientTileRequests, PriorityOrderWithFifoAmongEquals) {
  TileRequests t(16, 16);
  const std::vector<std::pair<TileId, uint16_t>> in = {{10, 1}, {11, 5}, {12, 1}, {13, 5}, {14, 3}, {15, 1}};
  for (auto [tile, p] : in) ASSERT_NE(t.insert(tile, entry_of(0), p), nullptr);
  EXPECT_EQ(drain(t), (std::vector<TileId>{11, 13, 14, 10, 12, 15}));
  for (TileId tile : {11, 13, 14, 10, 12, 15}) {
    EXPECT_EQ(t.find(tile)->state, RequestState::sent);
    EXPECT_EQ(t.find(tile)->request_id, 7u);
  }
}

TEST(ClientTileRequests, RaiseMovesUpBehindItsNewEqualsAndOnlyUp) {
  TileRequests t(8, 8);
  t.insert(1, entry_of(0), 4);
  t.insert(2, entry_of(0), 2);
  t.insert(3, entry_of(0), 2);
  EXPECT_FALSE(t.raise(*t.find(3), 2)) << "not higher";
  EXPECT_FALSE(t.raise(*t.find(3), 1)) << "lower";
  EXPECT_TRUE(t.raise(*t.find(3), 4));
  EXPECT_EQ(t.find(3)->priority, 4);
  EXPECT_EQ(t.queued(), 3u);
  EXPECT_EQ(drain(t), (std::vector<TileId>{1, 3, 2}));  // 3 after 1, which was at 4 first
  EXPECT_FALSE(t.raise(*t.find(2), 9)) << "sent: nothing to raise";
}

TEST(ClientTileRequests, StaleItemsAreSkipped) {
  TileRequests t(8, 8);
  for (TileId tile = 1; tile <= 5; ++tile) t.insert(tile, entry_of(0), uint16_t(tile));
  t.raise(*t.find(1), 9);  // its first item is stale now
  t.erase(*t.find(4));     // erased: its item is stale
  RequestRecord* one = t.pop(3);
  ASSERT_EQ(one->tile, 1u);  // raised to 9
  ASSERT_TRUE(t.requeue(*one));  // queued again: only the newest item counts
  // A new record in a freed slab slot must not be popped through the old tenant's item.
  t.insert(6, entry_of(0), 0);
  EXPECT_EQ(drain(t), (std::vector<TileId>{1, 5, 3, 2, 6}));
  EXPECT_EQ(t.order_items(), 0u);
  EXPECT_EQ(t.queued(), 0u);
}

TEST(ClientTileRequests, FullHeapIsCompactedInPlaceAndKeepsItsOrder) {
  const size_t queue = 4;
  TileRequests t(queue, queue);
  for (TileId tile = 0; tile < queue; ++tile) t.insert(tile, entry_of(0), 0);
  // Every raise leaves a stale item behind: far more raises than the heap holds.
  for (uint16_t p = 1; p <= 100; ++p)
    for (TileId tile = 0; tile < queue; ++tile) ASSERT_TRUE(t.raise(*t.find(tile), uint16_t(p + (tile & 1))));
  EXPECT_GT(t.compactions(), 0u);
  EXPECT_LE(t.order_items(), 2 * queue);
  // Odd tiles were raised last to 101, the even ones to 100; FIFO within each.
  EXPECT_EQ(drain(t), (std::vector<TileId>{1, 3, 0, 2}));
}

// ---------------------------------------------------------------- reference model

struct RefRecord {
  RequestState state = RequestState::queued;
  uint16_t priority = 0;
  uint64_t order = 0;  // queue position: FIFO among equal priorities
  uint32_t request_id = 0;
  float value = 0;
};

struct RefTable {
  size_t capacity, queue_capacity;
  std::map<TileId, RefRecord> records;
  uint64_t clock = 0;

  size_t queued() const {
    size_t n = 0;
    for (auto& [t, r] : records) n += r.state == RequestState::queued;
    return n;
  }
  std::optional<TileId> top() const {
    std::optional<TileId> best;
    for (auto& [t, r] : records) {
      if (r.state != RequestState::queued) continue;
      const RefRecord* b = best ? &records.at(*best) : nullptr;
      if (!b || r.priority > b->priority || (r.priority == b->priority && r.order < b->order)) best = t;
    }
    return best;
  }
};

TEST(ClientTileRequestsProperty, RandomOperationsMatchReferenceModel) {
  for (uint32_t seed = 1; seed <= 40; ++seed) {
    std::mt19937_64 rng(seed);
    const size_t queue = 1 + rng() % 12, capacity = queue + rng() % 8;
    TileRequests t(capacity, queue);
    RefTable m{capacity, queue, {}, 0};
    // Ids spread over 64 bits, some adjacent, to exercise probing and backward shifts.
    std::vector<TileId> universe;
    for (int i = 0; i < 24; ++i) universe.push_back(i < 12 ? TileId(i) : rng() >> 1);
    for (int step = 0; step < 3000; ++step) {
      const TileId tile = universe[rng() % universe.size()];
      auto it = m.records.find(tile);
      const uint16_t p = uint16_t(rng() % 5);
      switch (rng() % 7) {
        case 0:
        case 1: {  // insert
          const bool want = it == m.records.end() && m.records.size() < capacity && m.queued() < queue;
          RequestRecord* r = t.insert(tile, entry_of(float(step)), p);
          ASSERT_EQ(r != nullptr, want) << "seed " << seed << " step " << step;
          if (want) m.records[tile] = RefRecord{RequestState::queued, p, m.clock++, 0, float(step)};
          break;
        }
        case 2: {  // raise
          if (it == m.records.end()) break;
          const bool want = it->second.state == RequestState::queued && p > it->second.priority;
          ASSERT_EQ(t.raise(*t.find(tile), p), want) << "seed " << seed << " step " << step;
          if (want) it->second.priority = p, it->second.order = m.clock++;
          break;
        }
        case 3: {  // pop
          const auto want = m.top();
          RequestRecord* r = t.pop(uint32_t(step + 1));
          ASSERT_EQ(r != nullptr, want.has_value()) << "seed " << seed << " step " << step;
          if (!r) break;
          ASSERT_EQ(r->tile, *want) << "seed " << seed << " step " << step;
          m.records[*want].state = RequestState::sent;
          m.records[*want].request_id = uint32_t(step + 1);
          break;
        }
        case 4: {  // requeue a sent one, or mark it cancel_sent
          if (it == m.records.end() || it->second.state == RequestState::queued) break;
          if (rng() & 1) {
            t.find(tile)->state = RequestState::cancel_sent;
            it->second.state = RequestState::cancel_sent;
            break;
          }
          const bool want = m.queued() < queue;
          ASSERT_EQ(t.requeue(*t.find(tile)), want) << "seed " << seed << " step " << step;
          if (want) it->second = RefRecord{RequestState::queued, it->second.priority, m.clock++, 0, it->second.value};
          break;
        }
        case 5:  // erase
          if (it == m.records.end()) break;
          t.erase(*t.find(tile));
          m.records.erase(it);
          break;
        default:  // erase every second record through for_each (what cancel_outside does)
          if (rng() % 8) break;
          t.for_each([&](RequestRecord& r) {
            if (r.tile & 1) {
              m.records.erase(r.tile);
              t.erase(r);
            }
          });
      }
      // Every record is found with the model's fields; nothing else is.
      for (TileId u : universe) {
        const RequestRecord* r = t.find(u);
        auto ref = m.records.find(u);
        ASSERT_EQ(r != nullptr, ref != m.records.end()) << "seed " << seed << " step " << step << " tile " << u;
        if (!r) continue;
        ASSERT_EQ(r->tile, u);
        ASSERT_EQ(r->state, ref->second.state);
        ASSERT_EQ(r->priority, ref->second.priority);
        ASSERT_EQ(r->request_id, ref->second.request_id);
        ASSERT_EQ(r->entry.value, ref->second.value);
      }
      ASSERT_EQ(t.size(), m.records.size());
      ASSERT_EQ(t.queued(), m.queued());
      ASSERT_LE(t.order_items(), 2 * queue);
    }
    // What is left pops in the model's order.
    std::vector<TileId> want;
    while (auto top = m.top()) {
      want.push_back(*top);
      m.records[*top].state = RequestState::sent;
    }
    ASSERT_EQ(drain(t), want) << "seed " << seed;
  }
}

}  // namespace
}  // namespace st::client

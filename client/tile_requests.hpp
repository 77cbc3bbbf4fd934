// One map's tile requests (internal to client/): one record per tile id that is queued,
// sent, or sent and then cancelled, holding everything about that request, plus the
// priority order in which queued records leave for the network.
//
// The tile cache stays the authority for the page itself (absent / constant / requested
// / resident, slots, LRU); a tile has a record here exactly while its page is
// `requested`, and the record is the authority for the request: its state, priority,
// retries, queue order, the GetTiles request id carrying it and the page-table entry
// naming it (whose value answers for the tile if it is given up).
//
// Storage is fixed at construction, so that lookups which queue a miss never allocate:
//   records   a slab of `capacity` records with stable indices and a free list;
//   buckets   an open-addressing index (linear probing, backward-shift deletion) from
//             tile id to slab index, at most half full;
//   order     a binary max-heap of (priority, seq, index) items. Raising a priority or
//             re-queueing pushes a new item with a new seq instead of moving the old one;
//             an item whose record is gone, no longer queued or carries another seq is
//             stale and skipped when popped. When the heap is full the stale items are
//             removed in place; it holds 2 * queue_capacity items, and live items never
//             exceed the queued records, so there is always room after compaction.
//
// Thread safety: none. RemoteMap serializes access with its mutex.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tiles/core/tile_cache.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::client {

enum class RequestState : uint8_t {
  queued,       // waiting in the priority order
  sent,         // in a GetTiles, unanswered
  cancel_sent,  // in a GetTiles and cancelled (one Cancel is sent); still owed an answer
};

struct RequestRecord {
  TileId tile = kInvalidTile;
  GridEntry entry;           // the page-table entry naming the tile (value = coarse answer)
  uint64_t seq = 0;          // queue order: FIFO among equal priorities
  uint32_t request_id = 0;   // the GetTiles carrying it (sent, cancel_sent)
  uint32_t retries = 0;      // failed deliveries so far (CRC, decode, open)
  uint16_t priority = 0;     // the highest asked for
  RequestState state = RequestState::queued;
};

class TileRequests {
 public:
  // At most `capacity` records, of which at most `queue_capacity` queued. st::Error if
  // capacity is 0, below queue_capacity, or above 2^31.
  TileRequests(size_t capacity, size_t queue_capacity);

  size_t capacity() const noexcept { return capacity_; }
  size_t queue_capacity() const noexcept { return queue_capacity_; }
  size_t size() const noexcept { return size_; }
  size_t queued() const noexcept { return queued_; }
  size_t in_flight() const noexcept { return size_ - queued_; }  // sent or cancel_sent

  RequestRecord* find(TileId tile) noexcept;
  const RequestRecord* find(TileId tile) const noexcept;

  // A new queued record. Null (nothing changed) if `tile` has one, the table is full, or
  // the queue is (queued() == queue_capacity()).
  RequestRecord* insert(TileId tile, const GridEntry& entry, uint16_t priority) noexcept;
  // Forgets a record (its queue item, if any, turns stale).
  void erase(RequestRecord& r) noexcept;
  // A queued record asked for at a higher priority: it moves up, behind the records
  // already queued at that priority. False (nothing changed) otherwise.
  bool raise(RequestRecord& r, uint16_t priority) noexcept;
  // A sent (or cancel_sent) record queued again at its priority, behind its equals.
  // False (nothing changed) when the queue is full.
  bool requeue(RequestRecord& r) noexcept;
  // The queued record of highest priority (the oldest among equals), now sent under
  // `request_id`; null when nothing is queued.
  RequestRecord* pop(uint32_t request_id) noexcept;

  // fn(RequestRecord&) for every record, in slab order; fn may erase the record it is
  // given (and no other).
  template <class Fn>
  void for_each(Fn&& fn) {
    for (size_t i = 0; i < records_.size(); ++i)
      if (records_[i].tile != kInvalidTile) fn(records_[i]);
  }

  // Test hooks: heap items (live and stale) and how often the heap was compacted.
  size_t order_items() const noexcept { return order_.size(); }
  uint64_t compactions() const noexcept { return compactions_; }

 private:
  struct Item {
    uint64_t seq;
    uint32_t index;  // into records_
    uint16_t priority;
  };
  static constexpr uint32_t kEmpty = ~uint32_t(0);

  static bool item_less(const Item& a, const Item& b) noexcept;
  bool live(const Item& it) const noexcept;
  size_t home(TileId tile) const noexcept;
  size_t bucket_of(TileId tile) const noexcept;  // index into buckets_, or npos
  uint32_t index_of(const RequestRecord& r) const noexcept;
  void push_item(RequestRecord& r) noexcept;  // new seq, then an item for it
  void compact() noexcept;

  size_t capacity_, queue_capacity_;
  std::vector<RequestRecord> records_;  // reserved to capacity_; grows only within it
  std::vector<uint32_t> free_;          // freed slab indices (reserved to capacity_)
  std::vector<uint32_t> buckets_;       // power of two >= 2 * capacity_
  std::vector<Item> order_;             // reserved to 2 * queue_capacity_
  size_t size_ = 0, queued_ = 0;
  uint64_t next_seq_ = 0, compactions_ = 0;
};

}  // namespace st::client

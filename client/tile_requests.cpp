#include "client/tile_requests.hpp"

#include <algorithm>
#include <bit>
#include <string>

#include "common/error.hpp"
#include "common/hash.hpp"

namespace st::client {
namespace {
constexpr size_t kNpos = ~size_t(0);
constexpr size_t kMaxCapacity = size_t(1) << 31;  // slab indices fit 32 bits with room for kEmpty
}  // namespace

TileRequests::TileRequests(size_t capacity, size_t queue_capacity)
    : capacity_(capacity), queue_capacity_(queue_capacity) {
  if (capacity == 0 || queue_capacity > capacity || capacity > kMaxCapacity)
    throw Error("client: tile request table of " + std::to_string(capacity) + " records (" +
                std::to_string(queue_capacity) + " queued) is empty, too small for its queue, or above 2^31");
  records_.reserve(capacity);
  free_.reserve(capacity);
  buckets_.assign(std::bit_ceil(2 * capacity), kEmpty);
  order_.reserve(2 * queue_capacity);
}

// ---------------------------------------------------------------- the index

size_t TileRequests::home(TileId tile) const noexcept { return mix64(tile) & (buckets_.size() - 1); }

size_t TileRequests::bucket_of(TileId tile) const noexcept {
  const size_t mask = buckets_.size() - 1;
  for (size_t i = home(tile);; i = (i + 1) & mask) {
    if (buckets_[i] == kEmpty) return kNpos;
    if (records_[buckets_[i]].tile == tile) return i;
  }
}

uint32_t TileRequests::index_of(const RequestRecord& r) const noexcept {
  return uint32_t(&r - records_.data());
}

RequestRecord* TileRequests::find(TileId tile) noexcept {
  const size_t b = bucket_of(tile);
  return b == kNpos ? nullptr : &records_[buckets_[b]];
}

const RequestRecord* TileRequests::find(TileId tile) const noexcept {
  const size_t b = bucket_of(tile);
  return b == kNpos ? nullptr : &records_[buckets_[b]];
}

RequestRecord* TileRequests::insert(TileId tile, const GridEntry& entry, uint16_t priority) noexcept {
  if (tile == kInvalidTile || size_ == capacity_ || queued_ == queue_capacity_ || bucket_of(tile) != kNpos)
    return nullptr;
  uint32_t index;
  if (!free_.empty()) {
    index = free_.back();
    free_.pop_back();  // never allocates
  } else {
    index = uint32_t(records_.size());
    records_.emplace_back();  // within the reserved capacity: never allocates
  }
  RequestRecord& r = records_[index];
  r = RequestRecord{};
  r.tile = tile;
  r.entry = entry;
  r.priority = priority;
  const size_t mask = buckets_.size() - 1;
  size_t b = home(tile);
  while (buckets_[b] != kEmpty) b = (b + 1) & mask;
  buckets_[b] = index;
  ++size_;
  ++queued_;
  push_item(r);
  return &r;
}

// Backward-shift deletion keeps every probe chain unbroken without tombstones.
void TileRequests::erase(RequestRecord& r) noexcept {
  size_t i = bucket_of(r.tile);
  if (i == kNpos) return;
  const size_t mask = buckets_.size() - 1;
  for (size_t j = (i + 1) & mask; buckets_[j] != kEmpty; j = (j + 1) & mask) {
    const size_t h = home(records_[buckets_[j]].tile);
    // Move j into the hole at i unless its home lies cyclically in (i, j].
    const bool home_in_range = i < j ? (h > i && h <= j) : (h > i || h <= j);
    if (!home_in_range) {
      buckets_[i] = buckets_[j];
      i = j;
    }
  }
  buckets_[i] = kEmpty;
  if (r.state == RequestState::queued) --queued_;
  --size_;
  r = RequestRecord{};  // tile = kInvalidTile: free, and any queue item of it is stale
  free_.push_back(index_of(r));  // reserved to capacity: never allocates
}

// ---------------------------------------------------------------- the order

// Max-heap order: higher priority first, then older (smaller seq) first.
bool TileRequests::item_less(const Item& a, const Item& b) noexcept {
  return a.priority != b.priority ? a.priority < b.priority : a.seq > b.seq;
}

bool TileRequests::live(const Item& it) const noexcept {
  const RequestRecord& r = records_[it.index];
  return r.tile != kInvalidTile && r.state == RequestState::queued && r.seq == it.seq;
}

void TileRequests::compact() noexcept {
  std::erase_if(order_, [this](const Item& it) { return !live(it); });
  std::make_heap(order_.begin(), order_.end(), item_less);
  ++compactions_;
}

void TileRequests::push_item(RequestRecord& r) noexcept {
  r.seq = next_seq_++;  // any older item of r turns stale
  if (order_.size() == order_.capacity()) compact();
  // Live items <= queued records - 1 (r's own is not pushed yet) < 2 * queue_capacity:
  // after compaction there is room, so this push never allocates.
  order_.push_back(Item{r.seq, index_of(r), r.priority});
  std::push_heap(order_.begin(), order_.end(), item_less);
}

bool TileRequests::raise(RequestRecord& r, uint16_t priority) noexcept {
  if (r.state != RequestState::queued || priority <= r.priority) return false;
  r.priority = priority;
  push_item(r);
  return true;
}

bool TileRequests::requeue(RequestRecord& r) noexcept {
  if (r.state == RequestState::queued) return true;
  if (queued_ == queue_capacity_) return false;
  r.state = RequestState::queued;
  r.request_id = 0;
  ++queued_;
  push_item(r);
  return true;
}

RequestRecord* TileRequests::pop(uint32_t request_id) noexcept {
  while (!order_.empty()) {
    std::pop_heap(order_.begin(), order_.end(), item_less);
    const Item top = order_.back();
    order_.pop_back();
    if (!live(top)) continue;  // erased, sent, raised or re-queued since it was pushed
    RequestRecord& r = records_[top.index];
    r.state = RequestState::sent;
    r.request_id = request_id;
    --queued_;
    return &r;
  }
  return nullptr;
}

}  // namespace st::client

#include "server/tile_queue.hpp"

#include <algorithm>

namespace st::server {

bool TileQueue::push(const PendingTile& t) {
  if (order_.size() >= capacity_) return false;
  order_.emplace(Key{~t.priority, next_seq_++}, t);
  ++per_request_[t.request_id];
  return true;
}

std::optional<PoppedTile> TileQueue::pop() {
  if (order_.empty()) return std::nullopt;
  auto it = order_.begin();
  PoppedTile p{it->second, false};
  order_.erase(it);
  auto r = per_request_.find(p.tile.request_id);
  if (--r->second == 0) {
    per_request_.erase(r);
    p.last_of_request = true;
  }
  return p;
}

size_t TileQueue::pending(uint32_t request_id) const {
  auto r = per_request_.find(request_id);
  return r == per_request_.end() ? 0 : r->second;
}

void TileQueue::forget(uint32_t request_id) {
  auto r = per_request_.find(request_id);
  if (r != per_request_.end() && --r->second == 0) per_request_.erase(r);
}

// Linear in the queue size, which is bounded by the capacity (max in flight x tiles per
// batch); cancellation is rare next to pops.
size_t TileQueue::cancel_request(uint32_t request_id) {
  if (pending(request_id) == 0) return 0;
  size_t n = 0;
  for (auto it = order_.begin(); it != order_.end();) {
    if (it->second.request_id == request_id) {
      it = order_.erase(it);
      ++n;
    } else {
      ++it;
    }
  }
  per_request_.erase(request_id);
  return n;
}

size_t TileQueue::cancel_tiles(uint32_t request_id, std::span<const uint64_t> tiles) {
  size_t n = 0;
  for (auto it = order_.begin(); it != order_.end();) {
    const PendingTile& t = it->second;
    if ((request_id == 0 || t.request_id == request_id) &&
        std::find(tiles.begin(), tiles.end(), t.tile) != tiles.end()) {
      forget(t.request_id);
      it = order_.erase(it);
      ++n;
    } else {
      ++it;
    }
  }
  return n;
}

}  // namespace st::server

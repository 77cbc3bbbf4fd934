#include "server/tile_queue.hpp"

#include <algorithm>

namespace st::server {

bool TileQueue::push(const PendingTile& t) {
  if (order_.size() >= capacity_) return false;
  order_.emplace(Key{uint8_t(t.cancelled ? 0 : 1), ~t.priority, next_seq_++}, t);
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

// Linear in the queue size, which is bounded by the capacity (max in flight x tiles per
// batch); cancellation is rare next to pops.
template <class Pred>
size_t TileQueue::cancel_if(Pred pred) {
  size_t n = 0;
  for (auto it = order_.begin(); it != order_.end();) {
    if (it->first.normal && pred(it->second)) {
      PendingTile t = it->second;
      t.cancelled = true;
      it = order_.erase(it);
      order_.emplace(Key{0, 0, next_seq_++}, t);  // behind `it`: cancelled keys sort first
      ++n;
    } else {
      ++it;
    }
  }
  return n;
}

size_t TileQueue::cancel_request(uint32_t request_id) {
  if (pending(request_id) == 0) return 0;
  return cancel_if([&](const PendingTile& t) { return t.request_id == request_id; });
}

size_t TileQueue::cancel_tiles(uint32_t map_id, std::span<const uint64_t> tiles) {
  return cancel_if([&](const PendingTile& t) {
    return t.map_id == map_id && std::find(tiles.begin(), tiles.end(), t.tile) != tiles.end();
  });
}

}  // namespace st::server

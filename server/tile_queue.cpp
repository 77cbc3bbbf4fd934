#include "server/tile_queue.hpp"

#include <algorithm>

namespace st::server {

bool TileQueue::push(const PendingTile& t) {
  if (order_.size() >= capacity_) return false;
  const Key k{uint8_t(t.cancelled ? 0 : 1), ~t.priority, next_seq_++};
  order_.emplace(k, t);
  Request& r = per_request_[t.request_id];
  ++r.pending;
  r.keys.push_back(k);
  by_tile_.emplace(tile_key(t.map_id, t.tile), k);
  return true;
}

std::optional<PoppedTile> TileQueue::pop() {
  if (order_.empty()) return std::nullopt;
  auto it = order_.begin();
  PoppedTile p{it->second, false};
  const Key k = it->first;
  order_.erase(it);
  auto [b, e] = by_tile_.equal_range(tile_key(p.tile.map_id, p.tile.tile));
  for (; b != e; ++b)
    if (b->second.seq == k.seq) {
      by_tile_.erase(b);
      break;
    }
  auto r = per_request_.find(p.tile.request_id);
  if (--r->second.pending == 0) {
    per_request_.erase(r);
    p.last_of_request = true;
  }
  return p;
}

size_t TileQueue::pending(uint32_t request_id) const {
  auto r = per_request_.find(request_id);
  return r == per_request_.end() ? 0 : r->second.pending;
}

TileQueue::Key TileQueue::cancel_at(std::map<Key, PendingTile>::iterator it) {
  PendingTile t = it->second;
  const uint64_t old_seq = it->first.seq;
  t.cancelled = true;
  order_.erase(it);
  const Key k{0, 0, next_seq_++};  // cancelled keys sort first, FIFO among themselves
  order_.emplace(k, t);
  auto [b, e] = by_tile_.equal_range(tile_key(t.map_id, t.tile));
  for (; b != e; ++b)
    if (b->second.seq == old_seq) {
      b->second = k;
      break;
    }
  per_request_[t.request_id].keys.push_back(k);  // the old key goes stale
  return k;
}

size_t TileQueue::cancel_request(uint32_t request_id) {
  auto r = per_request_.find(request_id);
  if (r == per_request_.end()) return 0;
  std::vector<Key>& keys = r->second.keys;
  std::vector<Key> hit, kept;
  for (const Key& k : keys) {
    if (!order_.count(k)) continue;  // popped, or moved by an earlier cancel: stale
    (k.normal ? hit : kept).push_back(k);
  }
  keys = std::move(kept);  // cancel_at appends the new keys of the ones cancelled now
  return cancel_keys(hit);
}

size_t TileQueue::cancel_tiles(uint32_t map_id, std::span<const uint64_t> tiles) {
  std::vector<Key> hit;
  for (uint64_t tile : tiles) {
    auto [b, e] = by_tile_.equal_range(tile_key(map_id, tile));
    for (; b != e; ++b) {
      if (!b->second.normal) continue;
      auto it = order_.find(b->second);
      if (it != order_.end() && it->second.map_id == map_id && it->second.tile == tile) hit.push_back(b->second);
    }
  }
  return cancel_keys(hit);
}

size_t TileQueue::cancel_keys(std::vector<Key>& hit) {
  // In queue order (priority, then age), as a scan of the queue would have met them; a
  // tile named twice is cancelled once.
  std::sort(hit.begin(), hit.end());
  hit.erase(std::unique(hit.begin(), hit.end(), [](const Key& a, const Key& b) { return a.seq == b.seq; }), hit.end());
  for (const Key& k : hit) cancel_at(order_.find(k));
  return hit.size();
}

}  // namespace st::server

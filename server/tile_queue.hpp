// One connection's pending tile answers, served highest priority first (FIFO within a
// priority), with cancellation by request or by tile. A cancelled tile is not dropped:
// PROTOCOL.md has every tile answered exactly once (TileError(cancelled) for these) and
// every request end with FINAL, so cancelling re-queues it ahead of everything (its
// answer is tiny and frees the client's in-flight slot soonest). Bounded: push() refuses past the
// capacity (the connection answers `overloaded`), so a greedy client cannot make the
// server hold unbounded work. Not thread-safe: one queue per connection, used from that
// connection's coroutines only.
#pragma once
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

namespace st::server {

struct PendingTile {
  uint32_t request_id = 0;
  uint32_t map_id = 0;
  uint64_t tile = 0;
  uint32_t priority = 0;  // larger = sooner
  bool cancelled = false;  // answer with TileError(cancelled)
  std::chrono::steady_clock::time_point received{};
};

struct PoppedTile {
  PendingTile tile;
  bool last_of_request = false;  // no other tile of its request is pending: send FINAL
};

class TileQueue {
 public:
  explicit TileQueue(size_t capacity) : capacity_(capacity) {}

  size_t size() const { return order_.size(); }
  bool empty() const { return order_.empty(); }
  size_t capacity() const { return capacity_; }
  size_t free_space() const { return capacity_ - order_.size(); }

  // false (nothing queued) when full.
  bool push(const PendingTile& t);
  std::optional<PoppedTile> pop();

  // Tiles of `request_id` still queued.
  size_t pending(uint32_t request_id) const;
  // Marks every queued tile of the request cancelled; returns how many were newly marked.
  // O(tiles of that request x log queue).
  size_t cancel_request(uint32_t request_id);
  // Marks the listed tiles of map `map_id` cancelled, whatever their request.
  // O(listed tiles x log queue).
  size_t cancel_tiles(uint32_t map_id, std::span<const uint64_t> tiles);

 private:
  struct Key {
    uint8_t normal;         // 0 cancelled (first), 1 normal
    uint32_t inv_priority;  // ~priority: std::map orders ascending
    uint64_t seq;
    bool operator<(const Key& o) const {
      if (normal != o.normal) return normal < o.normal;
      return inv_priority != o.inv_priority ? inv_priority < o.inv_priority : seq < o.seq;
    }
  };
  // Moves the tile at `key` (a normal one) behind the cancelled ones; returns its new key.
  Key cancel_at(std::map<Key, PendingTile>::iterator it);
  size_t cancel_keys(std::vector<Key>& queued_normal_keys);
  static uint64_t tile_key(uint32_t map_id, uint64_t tile) {
    return tile * 0x9E3779B97F4A7C15ull ^ map_id;  // hashed by unordered_multimap
  }

  size_t capacity_;
  uint64_t next_seq_ = 0;
  std::map<Key, PendingTile> order_;
  // Cancel costs what it names, not the queue: each request's keys (popped ones go stale
  // and are skipped; the list goes with the request's last tile), and each queued tile's
  // key by (map, tile).
  struct Request {
    size_t pending = 0;
    std::vector<Key> keys;
  };
  std::unordered_map<uint32_t, Request> per_request_;
  std::unordered_multimap<uint64_t, Key> by_tile_;
};

}  // namespace st::server

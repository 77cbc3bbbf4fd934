// The server's cache of stored (zlib) tile payloads, shared by every connection: a hot
// tile is read from its pack (pread, CRC checked against the pack index) once, then sent
// to any number of clients from the same immutable buffer (a refcounted
// shared_ptr<const vector>, referenced by the gathered write, never copied).
//
// Bounded by a byte budget (each entry costs its payload plus kEntryOverhead), least
// recently used first out; a payload larger than budget / kMaxEntryShare is never cached
// (one big tile must not flush the rest). An evicted payload still being written lives
// until that write ends (its bytes then count in the server's queued answer bytes).
// Only bytes whose CRC matched the pack index are inserted, so the cache never holds
// anything the index would not vouch for; a pack changed on disk later keeps being
// served, for the tiles cached, with the bytes its index describes.
//
// Thread safety: every member may be called from any thread (one mutex, held for a hash
// lookup and a list splice).
#pragma once
#include <cstddef>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

namespace st::server {

class PayloadCache {
 public:
  using Bytes = std::shared_ptr<const std::vector<uint8_t>>;
  static constexpr size_t kEntryOverhead = 128;  // list + hash nodes, control block
  static constexpr size_t kMaxEntryShare = 16;

  explicit PayloadCache(size_t budget_bytes = 0) : budget_(budget_bytes) {}
  // Call before use from several threads; drops everything cached.
  void set_budget(size_t budget_bytes);

  // The cached payload of (map, tile), now the most recently used; null on a miss.
  // `map` is any stable identity of the pack (the server passes its CatalogMap).
  Bytes find(const void* map, uint64_t tile);
  // Caches a verified payload, evicting the least recently used past the budget; a
  // payload too big for the budget (or a zero budget) is not cached. Re-inserting a key
  // keeps the entry already there.
  void insert(const void* map, uint64_t tile, Bytes bytes);

  size_t budget() const { return budget_; }
  size_t bytes() const;    // payloads + overhead held now (<= budget)
  size_t entries() const;
  uint64_t hits() const;
  uint64_t misses() const;

 private:
  struct Key {
    const void* map;
    uint64_t tile;
    bool operator==(const Key& o) const { return map == o.map && tile == o.tile; }
  };
  struct KeyHash {
    size_t operator()(const Key& k) const {
      return size_t((k.tile * 0x9E3779B97F4A7C15ull) ^ reinterpret_cast<uintptr_t>(k.map));
    }
  };
  struct Entry {
    Key key;
    Bytes bytes;
    size_t cost;
  };

  mutable std::mutex mu_;
  size_t budget_;
  size_t bytes_ = 0;
  uint64_t hits_ = 0, misses_ = 0;
  std::list<Entry> lru_;  // most recently used first
  std::unordered_map<Key, std::list<Entry>::iterator, KeyHash> index_;
};

}  // namespace st::server

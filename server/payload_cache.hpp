// The server's cache of stored (zlib) tile payloads, shared by every connection: a hot
// tile is read from its pack (pread, CRC checked against the pack index) once, then sent
// to any number of clients from the same immutable buffer (a refcounted
// shared_ptr<const vector>, referenced by the gathered write, never copied).
//
// Addressed densely, by catalog map index and the tile's position in that pack's sorted
// tile index: a lookup is two array reads, no hashing. Slots come in pages of
// kPageSlots, allocated when a tile of theirs is first cached and freed when their last
// one leaves; pages count against the budget like payloads.
// Bounded by a byte budget (each entry costs its payload plus kEntryOverhead), evicted
// by CLOCK (second chance: a payload sent since the hand last passed it stays one more
// round; a new one gets a full round before its first test); a payload larger than budget / kMaxEntryShare is never cached (one big tile
// must not flush the rest). An evicted payload still being written lives until that
// write ends (its bytes then count in the server's queued answer bytes).
// Only bytes whose CRC matched the pack index are inserted, so the cache never holds
// anything the index would not vouch for; a pack changed on disk later keeps being
// served, for the tiles cached, with the bytes its index describes.
//
// Thread safety: configure() first, alone; then find/insert/stats from any thread (one
// mutex, held for two array reads, or for an insertion and its evictions).
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

namespace st::server {

class PayloadCache {
 public:
  using Bytes = std::shared_ptr<const std::vector<uint8_t>>;
  static constexpr size_t kEntryOverhead = 64;  // control block, vector, ring entry
  static constexpr size_t kMaxEntryShare = 16;
  static constexpr size_t kPageSlots = 256;

  PayloadCache() = default;
  // `tiles_per_map[m]`: the tile count of map m; drops everything cached.
  void configure(size_t budget_bytes, std::span<const size_t> tiles_per_map);

  // The cached payload of tile position `tile` of map `map` (null on a miss or out of
  // range), marked recently used.
  Bytes find(uint32_t map, uint32_t tile);
  // Caches a verified payload, evicting past the budget; a payload too big for its share
  // of the budget (or a zero budget, or an out-of-range address) is not cached.
  // Re-inserting an address keeps the entry already there.
  void insert(uint32_t map, uint32_t tile, Bytes bytes);

  size_t budget() const { return budget_; }
  size_t bytes() const;    // payloads + overheads + pages held now (<= budget)
  size_t entries() const;
  uint64_t hits() const;
  uint64_t misses() const;

 private:
  struct Slot {
    Bytes bytes;
    bool referenced = false;
  };
  struct Page {
    std::array<Slot, kPageSlots> slots;
    size_t resident = 0;
  };
  struct Map {
    size_t tiles = 0;
    std::vector<std::unique_ptr<Page>> pages;
  };
  struct Resident {
    uint32_t map, tile;
  };
  static size_t cost_of(const Bytes& b) { return b->size() + kEntryOverhead; }
  // Evicts the CLOCK hand's victim; false if nothing is cached.
  bool evict_one();

  mutable std::mutex mu_;
  size_t budget_ = 0;
  size_t bytes_ = 0;
  uint64_t hits_ = 0, misses_ = 0;
  std::vector<Map> maps_;
  static constexpr uint32_t kHole = UINT32_MAX;
  // What is cached, in CLOCK order; evicted entries leave holes (map == kHole) that the
  // next insertions fill, so the ring never outgrows the most entries ever cached at
  // once (at most budget / kEntryOverhead).
  std::vector<Resident> ring_;
  std::vector<size_t> holes_;
  size_t hand_ = 0;
};

}  // namespace st::server

// The tile cache: a fixed number of fixed-size slots in one flat pool, an O(1) LRU slot
// allocator with pinning, and a page table from tile id to page state. The one cache of
// the project: the client's maps (client/remote_map.hpp) page streamed tiles into it, and
// the pack evaluator (pack_evaluator.hpp) pages tiles read from disk.
//
// Deep shadow maps §5.4 cache tiles in "a fixed number of tile slots" and resize a slot
// on a tile fault when the incoming tile is larger. A GPU buffer cannot resize one slot,
// so here every slot has the same size and the pack bounds every tile's encoded size
// instead (the pack header's tile_bytes, tiles/PACK.md); a tile larger than a slot is
// refused with st::Error, never truncated.
//
// Pool layout (what a renderer uploads unchanged, so offsets only, no pointers):
//
//   byte offset                     size         holds
//   0                               slot_bytes   slot 0: tile bytes, then unused tail
//   slot_bytes                      slot_bytes   slot 1
//   ...
//   i * slot_bytes                  slot_bytes   slot i   (i < slot_count)
//
// A slot's tile occupies its first used(i) bytes; the rest of the slot is zero. A tile
// committed with commit_held keeps its bytes with the owner (RemoteMap's tile arena,
// client/tile_arena.hpp): tile_bytes() gives the owner's bytes and the slot stays zero.
//
// The pool is mapped, not filled: its pages are the system's zero pages until a slot is
// written, so a cache of many 64 KiB slots costs nothing up front, and a slot whose tile
// is held elsewhere never costs its bytes. The cache remembers how far each slot was
// written (zeroed again on commit and drop, so the rest stays zero without clearing a
// whole slot) and how far it was ever written (written_bytes(): the pool's memory in
// use); release_pages gives a slot's pages back.
//
// Page table: tile id -> PageState. `constant` pages carry a value that answers for the
// whole tile (nothing to fetch); `requested` pages are on their way; `resident` pages
// name a slot; tile ids not in the table are `absent`. The table is an open-addressing
// hash table: lookups never allocate; only inserting new ids may grow it.
//
// Slots are free, filling (reserved by a fetch, pinned), or resident. Resident slots with
// pin count 0 sit on an intrusive doubly linked LRU list over slot indices; pinning
// removes a slot from the list, so eviction (taking the list's tail) is O(1) and never
// touches a pinned slot. When every slot is pinned, reserve() throws CacheFullError.
//
// Change journal: every time a slot's resident tile changes (a commit makes it resident,
// an eviction, drop or abort frees it), the slot's index is appended to a ring of
// journal_capacity() entries, numbered by a count that only grows (journal_end()). A
// mirror of the pool (the GPU's, client::CacheView) remembers the count it last read and
// visits only the slots named since: O(changes), not O(slots). A slot may be named more
// than once; a reader more than journal_capacity() changes behind has lost its place and
// compares every slot instead (no dearer then: the capacity is at least slot_count).
//
// Thread safety: none. The owner (RemoteMap, PackEvaluator) serializes access with its mutex.
#pragma once
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "common/error.hpp"

namespace st {

using TileId = uint64_t;
inline constexpr TileId kInvalidTile = ~TileId(0);  // never a valid tile id (table's empty key)
inline constexpr uint32_t kNoSlot = ~uint32_t(0);

enum class PageState : uint8_t { absent = 0, constant = 1, requested = 2, resident = 3 };

struct PageEntry {
  PageState state = PageState::absent;
  uint32_t slot = kNoSlot;  // resident only
  float value = 0;          // constant only
};

struct CacheStats {
  uint64_t hits = 0;       // access() found the tile resident
  uint64_t misses = 0;     // access() found it absent or requested
  uint64_t evictions = 0;  // resident tiles dropped to make room
  uint64_t inserts = 0;    // tiles made resident
  uint32_t resident = 0, pinned = 0, free = 0;
};

// Every slot is pinned: nothing can be evicted to make room.
class CacheFullError : public Error {
 public:
  using Error::Error;
};

class TileCache {
 public:
  // Throws st::Error if slot_count or slot_bytes is 0 or the pool would exceed 2^40 bytes
  // (or cannot be mapped).
  TileCache(uint32_t slot_count, uint32_t slot_bytes);

  // ---- the pool ----
  uint32_t slot_count() const { return slot_count_; }
  uint32_t slot_bytes() const { return slot_bytes_; }
  std::span<const uint8_t> pool() const { return {pool_.data, pool_.size}; }
  uint64_t slot_offset(uint32_t slot) const { return uint64_t(slot) * slot_bytes_; }
  // The tile bytes of a resident or filling slot (the first used(slot) bytes), or the
  // owner's bytes of a tile committed with commit_held.
  std::span<const uint8_t> tile_bytes(uint32_t slot) const;
  // The slot's first `bytes` (at most slot_bytes), writable: a fetch decompresses into
  // it between reserve and commit. Only the slot's own entry changes (the owner may call
  // it without its lock on a slot it reserved). Without `bytes`: the whole slot.
  std::span<uint8_t> slot_span(uint32_t slot, uint32_t bytes);
  std::span<uint8_t> slot_span(uint32_t slot) { return slot_span(slot, slot_bytes_); }
  // Gives the pages of a reserved slot, which must hold no written bytes (a filling slot
  // nobody wrote since reserve), back to the system. True when none of the slot's bytes
  // are in use now (written_bytes counts none of it): its pages were given back, or the
  // slot was never written. False when part of it shares a page with a neighbour (a slot
  // size that is not a multiple of the page size).
  bool release_pages(uint32_t slot) noexcept;
  // Pool bytes in use: the sum over slots of how far each was written since its pages
  // were last given back (a slot whose tile is held elsewhere adds nothing).
  uint64_t written_bytes() const { return written_total_; }
  uint32_t used(uint32_t slot) const { return slots_[slot].used; }
  TileId slot_tile(uint32_t slot) const { return slots_[slot].tile; }
  // The slot holds its tile resident (committed, not dropped): exactly when
  // lookup(slot_tile(slot)) is resident in this slot, without the page-table probe.
  bool slot_resident(uint32_t slot) const { return slots_[slot].state == SlotState::resident; }
  // Starts loading the slot's record (what slot_tile, slot_resident and tile_bytes read),
  // for a reader that visits many slots from cold caches (client::CacheView) a few ahead.
  void prefetch_slot(uint32_t slot) const {
    __builtin_prefetch(&slots_[slot].tile);
    __builtin_prefetch(&slots_[slot].state);
  }

  // ---- the page table ----
  // The page's state, without counting or touching anything.
  PageEntry lookup(TileId tile) const noexcept;
  // The page's state for a lookup that wants the tile: counts a hit (resident) or a miss
  // (absent or requested) and marks a resident slot most recently used.
  PageEntry access(TileId tile) noexcept;
  // Marks resident slot `slot` most recently used without counting anything (an owner
  // that counts its lookups itself and replays their use in batches: RemoteMap).
  void touch(uint32_t slot) noexcept;
  // A tile that stores nothing finer: `value` answers for all of it. Drops a resident copy.
  void set_constant(TileId tile, float value);
  // absent -> requested. Returns false (and changes nothing) in any other state. The
  // request itself (priority, retries, ...) is the owner's business: the client keeps it
  // in its request table (client/tile_requests.hpp).
  bool request(TileId tile);
  // Sizes the page table for `pages` entries, so that no later request() allocates.
  void reserve_pages(size_t pages);
  // requested -> absent (a cancelled or failed fetch). Other states are left alone.
  void cancel_request(TileId tile);

  // ---- filling a slot (two phases, so the bytes can be written outside a lock) ----
  // Takes a free slot, else evicts the least recently used unpinned tile. The slot is
  // pinned once and belongs to `tile`; the page stays `requested` until commit.
  // Throws CacheFullError when every slot is pinned.
  uint32_t reserve(TileId tile);
  // The slot's first `used_bytes` hold the tile: the page becomes resident(slot), the slot
  // is unpinned once and becomes most recently used. Throws st::Error if used_bytes >
  // slot_bytes. If the page was cancelled meanwhile it still becomes resident (the bytes
  // are good). Returns false (and frees the slot, as abort) if the page became constant
  // or resident in another slot meanwhile.
  bool commit(uint32_t slot, uint32_t used_bytes);
  // commit for a tile whose bytes the owner holds (client/tile_arena.hpp): tile_bytes()
  // is `bytes` until the slot is dropped, evicted or reserved again, and the slot's own
  // bytes stay as they are (zero where nothing was written). The owner keeps `bytes`
  // valid that long.
  bool commit_held(uint32_t slot, std::span<const uint8_t> bytes);
  // Gives a reserved slot back (fetch failed): slot free, page absent.
  void abort(uint32_t slot);
  // reserve + copy + commit. Throws st::Error if bytes exceed a slot.
  uint32_t insert(TileId tile, std::span<const uint8_t> bytes);

  // ---- pinning and eviction ----
  void pin(uint32_t slot);
  void unpin(uint32_t slot);  // contract: pin_count(slot) > 0
  uint32_t pin_count(uint32_t slot) const { return slots_[slot].pins; }
  // Drops a resident, unpinned tile (page -> absent). Returns false otherwise.
  bool evict(TileId tile);
  // Least recently used unpinned resident slot (the next victim), or kNoSlot.
  uint32_t lru_victim() const { return lru_tail_; }

  CacheStats stats() const;

  // ---- the change journal (see the top of the file) ----
  // Changes recorded so far: the journal's end.
  uint64_t journal_end() const { return journal_end_; }
  uint64_t journal_capacity() const { return journal_.size(); }
  // Calls fn(slot) for each change in [from, journal_end()), oldest first, and returns
  // true; returns false (calling nothing) when the ring no longer holds them all
  // (from + journal_capacity() < journal_end()) or from is past the end.
  template <class Fn>
  bool changes_since(uint64_t from, Fn&& fn) const {
    if (from > journal_end_ || journal_end_ - from > journal_.size()) return false;
    const uint64_t mask = journal_.size() - 1;
    for (uint64_t i = from; i < journal_end_; ++i) fn(journal_[i & mask]);
    return true;
  }

 private:
  enum class SlotState : uint8_t { free, filling, resident };
  struct Slot {
    TileId tile = kInvalidTile;
    const uint8_t* held = nullptr;  // commit_held's bytes (null: the tile is in the slot)
    uint32_t used = 0, pins = 0;
    // Bytes that may be non-zero (the rest of the slot is zero), and how far the slot was
    // written since its pages were last given back (written_bytes).
    uint32_t written = 0, touched = 0;
    uint32_t prev = kNoSlot, next = kNoSlot;  // LRU list (resident, unpinned) or free list
    SlotState state = SlotState::free;
    bool on_lru = false;
  };
  struct Bucket {
    TileId key = kInvalidTile;
    PageEntry entry;
  };

  void lru_unlink(uint32_t s);
  void lru_push_front(uint32_t s);
  void free_push(uint32_t s);
  uint32_t free_pop();
  void drop_slot(uint32_t s);  // resident/filling -> free, clears bytes
  void note_touched(Slot& n);  // folds n.written into n.touched and written_total_
  void journal(uint32_t s) { journal_[journal_end_++ & (journal_.size() - 1)] = s; }

  size_t find_bucket(TileId key) const noexcept;  // bucket index or npos
  PageEntry& upsert(TileId key);
  void erase(TileId key);
  void grow();

  // The pool's mapping (anonymous, zero until written; unmapped on destruction).
  struct Pool {
    uint8_t* data = nullptr;
    size_t size = 0;
    Pool() = default;
    explicit Pool(size_t bytes);
    Pool(Pool&& o) noexcept : data(std::exchange(o.data, nullptr)), size(std::exchange(o.size, 0)) {}
    Pool& operator=(Pool&& o) noexcept {
      std::swap(data, o.data);
      std::swap(size, o.size);
      return *this;
    }
    ~Pool();
  };

  uint32_t slot_count_, slot_bytes_;
  Pool pool_;
  uint64_t written_total_ = 0;
  std::vector<Slot> slots_;
  uint32_t lru_head_ = kNoSlot, lru_tail_ = kNoSlot;  // head = most recently used
  uint32_t free_head_ = kNoSlot;
  uint32_t free_count_ = 0, pinned_count_ = 0, resident_count_ = 0;

  std::vector<Bucket> table_;  // power-of-two size, linear probing, backward-shift deletion
  size_t table_used_ = 0;

  uint64_t hits_ = 0, misses_ = 0, evictions_ = 0, inserts_ = 0;

  std::vector<uint32_t> journal_;  // power-of-two ring of changed slots, >= slot_count_
  uint64_t journal_end_ = 0;
};

}  // namespace st

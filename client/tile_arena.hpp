#pragma once
// Where a 2D map's resident tiles live on the CPU: packed tightly, not in their slots.
//
// The tile cache's slots are `slot_bytes` apart (the pack's tile bound, 64 KiB in most
// packs), so that a GPU mirror can address slot i at i * slot_bytes. A real level's tiles
// are a few hundred bytes: opened in place, every tile's header and first records sit at
// the same offset of its own page, i.e. in the same few L1/L2 cache sets, and each tile a
// lookup enters is another page (another TLB entry). So an arriving map tile is inflated
// here, one after another in chunks (64-byte aligned), and its evaluator reads it here:
// the tiles a frame walks share lines' sets and pages like any small array (oa_dm1 8K^2,
// one thread: the render's taps 34.5 -> 28.7 ns each, bench_client_lookups --profile-map).
// The slot itself is committed with these bytes (TileCache::commit_held) and never
// written: a GPU mirror reads a tile through the cache (CacheView's SlotChange bytes),
// which gives these, and places it at slot i in its own buffer.
//
//   chunk: [tile a | pad to 64][tile b | pad to 64] ... [unused tail]   chunk_bytes in all
//
// A chunk's bump pointer only rewinds when its last tile is released, and a chunk with
// no live tile is freed (the one being filled too, once nothing is being placed in it).
// So the arena never holds more chunks than live tiles: with each tile here and not in
// its slot, the tiles' bytes stay within slots x chunk_bytes (the cache's budget,
// RemoteMap). A ceiling of chunks, `max_chunks`, may be set lower: a tile that would need
// a chunk past it is not placed and its owner keeps it in its slot.
//
// Thread safety: reserve, place and release may be called from any thread (an internal
// mutex); the returned bytes stay valid until the slot's next reserve, place or release.

#include <cstdint>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

namespace st::client {

class TileArena {
 public:
  // chunk_bytes: at least the largest tile placed (the cache's slot size); max_chunks: the
  // most chunks held at once (at least 1).
  TileArena(uint32_t slot_count, uint32_t chunk_bytes, uint32_t max_chunks = ~0u);

  // Room for `bytes` bytes as `slot`'s tile (its previous one released first), for the
  // caller to write (inflate) into; a span without data (data() == nullptr) when it would
  // need a chunk past max_chunks, or for 0 bytes: nothing is placed. Throws
  // std::bad_alloc, or st::Error when bytes exceed a chunk.
  std::span<uint8_t> reserve(uint32_t slot, size_t bytes);
  // reserve, then a copy of `bytes` into it (the copy returned; no data: none made).
  std::span<const uint8_t> place(uint32_t slot, std::span<const uint8_t> bytes);
  // Drops `slot`'s copy (none: nothing happens).
  void release(uint32_t slot) noexcept;

  // Bytes of the chunks held now (for stats and tests).
  uint64_t held_bytes() const noexcept;
  uint32_t chunk_bytes() const noexcept { return chunk_bytes_; }

  static constexpr uint32_t kAlign = 64;  // one cache line: a tile starts on its own line

 private:
  static constexpr uint32_t kNone = ~0u;
  struct Free {
    void operator()(uint8_t* p) const noexcept { std::free(p); }
  };
  struct Chunk {
    std::unique_ptr<uint8_t, Free> data;  // null: this id is free
    uint32_t used = 0;                    // bytes handed out (the bump pointer)
    uint32_t live = 0;                    // tiles placed here and not released
  };
  struct Home {
    uint32_t chunk = kNone;
  };
  // keep_current: a chunk being filled that empties is kept (reserve fills it next).
  void release_locked(uint32_t slot, bool keep_current) noexcept;
  void free_chunk_locked(uint32_t id) noexcept;
  uint32_t new_chunk_locked();

  mutable std::mutex mu_;
  uint32_t chunk_bytes_;
  uint32_t max_chunks_;
  std::vector<Chunk> chunks_;
  std::vector<uint32_t> free_ids_;  // chunks_ entries without data
  uint32_t current_ = kNone;        // the chunk being filled
  uint32_t held_ = 0;               // chunks with data
  std::vector<Home> homes_;         // per slot
};

}  // namespace st::client

#pragma once
// The CPU lookups' copies of the resident map tiles' bytes, packed tightly.
//
// The tile cache's slots are `slot_bytes` apart (the pack's tile bound, 64 KiB in most
// packs), so that a GPU mirror can address slot i at i * slot_bytes. A real level's tiles
// are a few hundred bytes: opened in place, every tile's header and first records sit at
// the same offset of its own page, i.e. in the same few L1/L2 cache sets, and each tile a
// lookup enters is another page (another TLB entry). The evaluators therefore read a copy
// of each tile placed here, one after another in chunks (64-byte aligned), so that the
// tiles a frame walks share lines' sets and pages like any small array (oa_dm1 8K^2,
// one thread: the render's taps 34.5 -> 28.7 ns each, bench_client_lookups --profile-map).
// The slot keeps its bytes (the GPU mirror's copy).
//
//   chunk: [tile a | pad to 64][tile b | pad to 64] ... [unused tail]   chunk_bytes in all
//
// A chunk's bump pointer only rewinds when its last tile is released; a chunk with no
// live tile (other than the one being filled) is freed. So the arena holds at most
// (live tiles + 1) chunks, and in a steady state about the live tiles' bytes. Under heavy
// eviction a chunk may keep a single live tile, so the arena also has a ceiling,
// `max_chunks` (RemoteMap: an eighth of the pool's bytes): a copy that would need a chunk
// past it is not made, and that tile is read in its slot as before (slower, never more
// memory than the cache's budget plus that eighth).
//
// Thread safety: place and release may be called from any thread (an internal mutex);
// the returned bytes stay valid until the slot's next place or release.

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

  // Copies `bytes` into the arena as `slot`'s tile (its previous copy released first) and
  // returns the copy; a span without data (data() == nullptr) when the copy would need a
  // chunk past max_chunks: nothing is placed, the caller reads its own bytes. Throws
  // std::bad_alloc, or st::Error when bytes exceed a chunk.
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
  void release_locked(uint32_t slot) noexcept;
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

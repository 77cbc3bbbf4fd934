// TileSlotTable: GpuMap's tile -> device slot hash (gpu_map.cpp), internal to gpu/; a header
// of its own so the tests can churn it against a reference map.
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <string>
#include <vector>

#include "gpu/shaders/st_layout.h"
#include "shadowtile/gpu.hpp"
#include "tiles/core/tile_cache.hpp"

namespace st::gpu {

// Tile -> the slot holding it on the device: open addressing, linear probing, backward-shift
// deletion, sized once for at most slot_count keys (load <= 1/2), so linking and unlinking
// tiles on the frame path never allocates. A bucket is 8 bytes, eight a cache line: the
// slot and 32 bits of the key's hash (its home and a filter); the key itself is the tile
// its slot's record holds (GpuMap::Impl::SlotRec), read only when the hash bits match, and
// that record is what the caller reads next anyway. A slot sits in at most one bucket, and
// only while its record's tile is that bucket's key (set() moves a tile's bucket to its
// new slot, erase() removes a slot's bucket): so erase needs no key and a shift no record.
class TileSlotTable {
 public:
  void init(uint32_t max_keys) {
    mask_ = std::bit_ceil(std::max<uint64_t>(16, uint64_t(max_keys) * 2)) - 1;
    buckets_.assign(mask_ + 1, Bucket{});
  }
  // key_of(slot): the tile slot's record holds.
  template <typename KeyOf>
  uint32_t find(TileId t, const KeyOf& key_of) const {
    return buckets_[probe_key(hash(t), t, key_of)].slot;
  }
  // The slot find(t) most likely answers, from the buckets alone (no record read), or
  // kNoSlot: for prefetching the record before find runs.
  uint32_t guess(TileId t) const {
    const uint32_t h = hash(t);
    return buckets_[probe(h, [&](const Bucket& b) { return b.slot == layout::kNoSlot || b.hash == h; })].slot;
  }
  // Starts loading the line find(t) / set / erase will read first.
  void prefetch(TileId t) const { __builtin_prefetch(&buckets_[hash(t) & mask_]); }
  // t is now in `slot` (whose record already or soon holds t; a bucket of t's
  // earlier slot moves here).
  template <typename KeyOf>
  void set(TileId t, uint32_t slot, const KeyOf& key_of) {
    const uint32_t h = hash(t);
    buckets_[probe_key(h, t, key_of)] = {h, slot};
  }
  // Removes `slot`'s bucket (key t), if it has one: a tile since moved to another slot
  // keeps that mapping.
  void erase(TileId t, uint32_t slot) {
    const uint32_t h = hash(t);
    uint64_t i = probe(h, [&](const Bucket& b) { return b.slot == layout::kNoSlot || (b.slot == slot && b.hash == h); });
    if (buckets_[i].slot == layout::kNoSlot) return;
    for (uint64_t j = i, n = 0;;) {  // shift later keys of the run back over the hole
      j = (j + 1) & mask_;
      if (buckets_[j].slot == layout::kNoSlot) break;
      if (++n > mask_) broken();
      const uint64_t home = buckets_[j].hash & mask_;
      if (((j - home) & mask_) < ((j - i) & mask_)) continue;  // its home lies after the hole: stays
      buckets_[i] = buckets_[j];
      i = j;
    }
    buckets_[i] = Bucket{};
  }

 private:
  struct Bucket {
    uint32_t hash = 0;
    uint32_t slot = layout::kNoSlot;  // kNoSlot: empty
  };
  // 32 bits of the old 64-bit mix: a table has at most 2^24 buckets (2^23 slots).
  static uint32_t hash(TileId t) { return uint32_t((t ^ (t >> 29)) * 0x9E3779B97F4A7C15ull >> 17); }
  // The buckets from hash h's home on, in probe order, to the first that stop(bucket)
  // accepts: its index. find, guess, set and erase differ only in the stop test. The table
  // always keeps an empty bucket (load <= 1/2), so every probe ends within a lap; one that
  // does not (nor a shift that finds no end) means a broken invariant (a deletion that left
  // duplicates, a full table): it throws instead of spinning forever on the frame path.
  template <typename Stop>
  uint64_t probe(uint32_t h, const Stop& stop) const {
    uint64_t i = h & mask_;
    for (uint64_t n = 0; n <= mask_; ++n, i = (i + 1) & mask_)
      if (stop(buckets_[i])) return i;
    broken();
  }
  // The bucket of key t (hash h), or the empty one that ends its run: where find reads
  // and set writes.
  template <typename KeyOf>
  uint64_t probe_key(uint32_t h, TileId t, const KeyOf& key_of) const {
    return probe(h, [&](const Bucket& b) { return b.slot == layout::kNoSlot || (b.hash == h && key_of(b.slot) == t); });
  }
  [[noreturn]] void broken() const {
    throw GpuError("GpuMap: the tile -> slot table has no empty bucket left (" + std::to_string(mask_ + 1) +
                   " buckets): a deletion broke its runs");
  }
  uint64_t mask_ = 0;
  std::vector<Bucket> buckets_;
};

}  // namespace st::gpu

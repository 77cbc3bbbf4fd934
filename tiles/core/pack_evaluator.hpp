// An Evaluator over a pack file: levels < K from the skip grid's coarse pyramid, level K
// from its entries, finer levels from the tiles, read, decompressed straight into a slot
// of a TileCache (tile_cache.hpp, the same cache the client uses) and opened there on
// demand. The page-table walk is page_table.hpp's. Answers depth(l, x, y) like
// Hierarchy::depth_at of the hierarchy that was cut (bit-exactly with MH tiles; inside
// MMH/DAG-MH tiles what their encoding answers), with integer texel addressing up to
// level 20 (tiles/PACK.md "Meaning").
//
// Memory: `cache_tiles` slots of the pack's largest raw tile each.
// Thread safety: depth()/pcf() may be called from many threads. One mutex guards the
// cache; a tile is read and opened outside it (its slot reserved and pinned meanwhile),
// and a lookup pins the slot it evaluates, so eviction never pulls bytes from under a
// reader. Two threads missing the same tile may each read it; one copy stays.
// Errors: a missing or corrupt tile throws st::FormatError naming the pack, tile id and
// byte offset (the slot is given back). A texel outside the map is lit (the one rule of
// page_table.hpp).
#pragma once
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "tiles/core/pack_reader.hpp"
#include "tiles/core/tile_cache.hpp"

namespace st {

class PackEvaluator : public Evaluator {
 public:
  // `open_tile` opens one encoded tile's bytes; empty: the reader's tile_opener().
  explicit PackEvaluator(std::shared_ptr<const PackReader> reader, size_t cache_tiles = 256,
                         PackReader::TileOpener open_tile = {});

  uint32_t finest_level() const override { return reader_->map_level(); }
  float depth(uint32_t level, uint64_t x, uint64_t y) const override;
  // The same answers as pcf() per query, single taps answered by tile: in Morton order
  // (tap_order.hpp), a run of taps in one tile takes the lock, the page-table walk and the
  // pin once, and walks the tile's tree from the last walk's path (TapWalks::tap_run) with
  // the last answer's region kept; kernels (r > 1) go to pcf() one by one.
  void pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const override;
  // A kernel inside one tile: that tile's own pcf_on_plane (its shared walk, the plane in
  // the tile's coordinates), one lock and pin; others tap by tap through depth().
  float pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const override;

  const PackReader& reader() const { return *reader_; }
  uint64_t tiles_opened() const;  // cache misses so far
  // Slot bytes written so far (TileCache::written_bytes): each opened tile's raw bytes,
  // never a whole slot, so a commit clears no tail past the tile.
  uint64_t slot_bytes_written() const;

 private:
  // The slot holding tile `id` (resident; read and opened first if needed). Called and
  // returns with `lock` held; releases it while reading.
  uint32_t resident_slot(uint64_t id, const GridEntry& entry, std::unique_lock<std::mutex>& lock) const;

  // Re-takes `lock` and releases `slot` (TileCache::unpin after a lookup, ::abort after a
  // failed read), waking lookups that wait for a slot.
  void give_back(std::unique_lock<std::mutex>& lock, uint32_t slot, void (TileCache::*release)(uint32_t)) const;

  std::shared_ptr<const PackReader> reader_;
  PackReader::TileOpener open_tile_;
  mutable std::mutex mu_;
  mutable std::condition_variable unpinned_;  // a slot was unpinned or given back
  mutable TileCache cache_;
  mutable std::vector<std::unique_ptr<Evaluator>> slot_eval_;  // encoded tiles, per slot
  mutable std::vector<CutGrid> slot_grid_;                     // index tiles, per slot
  mutable uint64_t opened_ = 0;
};

}  // namespace st

// An Evaluator over a pack file (DESIGN.md "Tiles, skip list and pack files"): levels
// < K from the skip grid's coarse pyramid, level K from its entries, finer levels from
// the tiles, read, decompressed and opened on demand and kept in a small LRU cache.
// Answers depth(l, x, y) like Hierarchy::depth_at of the hierarchy that was cut (bit-exactly
// with MH tiles; inside MMH/DAG-MH tiles what their encoding answers), with integer texel
// addressing up to level 20 (tiles/PACK.md "Meaning").
//
// Thread safety: depth()/pcf() may be called from many threads (the cache is locked; a
// tile is opened outside the lock, so two threads may open the same tile once each).
// Errors: a missing or corrupt tile throws st::FormatError naming the pack, tile id and
// byte offset. A texel outside the map is lit (the one rule of page_table.hpp).
#pragma once
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>

#include "tiles/core/pack_reader.hpp"

namespace st {

class PackEvaluator : public Evaluator {
 public:
  // `open_tile` opens one encoded tile's bytes; empty: open_encoded(reader's encoding).
  explicit PackEvaluator(std::shared_ptr<const PackReader> reader, size_t cache_tiles = 256,
                         PackReader::TileOpener open_tile = {});

  uint32_t finest_level() const override { return reader_->map_level(); }
  float depth(uint32_t level, uint64_t x, uint64_t y) const override;

  const PackReader& reader() const { return *reader_; }
  uint64_t tiles_opened() const;  // cache misses so far

 private:
  struct Loaded {
    std::vector<uint8_t> raw;          // encoded tile bytes (the evaluator reads them)
    std::unique_ptr<Evaluator> eval;   // encoded tiles
    CutGrid grid;                      // index tiles
  };
  std::shared_ptr<const Loaded> load(uint64_t id, const GridEntry& entry) const;
  // load() behind a tiny per-thread cache of the last tiles used (no lock on a hit).
  const Loaded& tile(uint64_t id, const GridEntry& entry) const;

  std::shared_ptr<const PackReader> reader_;
  size_t capacity_;
  PackReader::TileOpener open_tile_;
  mutable std::mutex mu_;
  mutable std::list<uint64_t> lru_;  // front = most recent
  struct Slot {
    std::shared_ptr<const Loaded> tile;
    std::list<uint64_t>::iterator pos;
  };
  mutable std::unordered_map<uint64_t, Slot> cache_;
  mutable uint64_t opened_ = 0;
  const uint64_t serial_;  // tells this evaluator's entries in the per-thread cache apart
};

}  // namespace st

#include "tiles/core/pack_evaluator.hpp"

#include <atomic>
#include <cstring>

#include "common/error.hpp"
#include "tiles/core/page_table.hpp"

namespace st {

namespace {
std::atomic<uint64_t> next_serial{0};

// The last few tiles each thread used, across evaluators (keyed by serial, never by
// address). Entries hold shared_ptrs: a tile evicted from the shared cache stays valid
// here until replaced, so a hit needs no lock.
struct ThreadTiles {
  static constexpr size_t kSlots = 4;
  uint64_t serial[kSlots] = {};
  uint64_t id[kSlots] = {};
  std::shared_ptr<const void> tile[kSlots];
  size_t next = 0;
};
thread_local ThreadTiles thread_tiles;
}  // namespace

PackEvaluator::PackEvaluator(std::shared_ptr<const PackReader> reader, size_t cache_tiles,
                             PackReader::TileOpener open_tile)
    : reader_(std::move(reader)),
      capacity_(std::max<size_t>(cache_tiles, 1)),
      open_tile_(std::move(open_tile)),
      serial_(next_serial.fetch_add(1) + 1) {
  if (!open_tile_) {
    Encoding e = reader_->encoding();
    open_tile_ = [e](std::span<const uint8_t> bytes) { return open_encoded(e, bytes); };
  }
}

uint64_t PackEvaluator::tiles_opened() const {
  std::lock_guard lock(mu_);
  return opened_;
}

std::shared_ptr<const PackEvaluator::Loaded> PackEvaluator::load(uint64_t id, const GridEntry& entry) const {
  {
    std::lock_guard lock(mu_);
    auto it = cache_.find(id);
    if (it != cache_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second.pos);
      return it->second.tile;
    }
  }
  auto t = std::make_shared<Loaded>();
  if (entry.kind == EntryKind::index) {
    t->grid = reader_->read_index_tile(id, entry);
  } else {
    t->raw = reader_->read_raw(id);
    const TileAddress a = tile_address(id);
    const std::string what = reader_->name() + ": " + describe_tile(id);
    try {
      t->eval = open_tile_(t->raw);
    } catch (const FormatError&) {
      throw;
    } catch (const Error& err) {
      throw FormatError(what + ": " + err.what());
    }
    if (t->eval->finest_level() != reader_->map_level() - a.level)
      throw FormatError(what + ": finest level " + std::to_string(t->eval->finest_level()) + ", expected " +
                        std::to_string(reader_->map_level() - a.level));
  }
  std::lock_guard lock(mu_);
  ++opened_;
  auto it = cache_.find(id);
  if (it != cache_.end()) return it->second.tile;  // another thread won the race
  lru_.push_front(id);
  cache_[id] = Slot{t, lru_.begin()};
  while (cache_.size() > capacity_) {
    cache_.erase(lru_.back());
    lru_.pop_back();
  }
  return t;
}

const PackEvaluator::Loaded& PackEvaluator::tile(uint64_t id, const GridEntry& entry) const {
  ThreadTiles& tt = thread_tiles;
  for (size_t i = 0; i < ThreadTiles::kSlots; ++i)
    if (tt.id[i] == id && tt.serial[i] == serial_) return *static_cast<const Loaded*>(tt.tile[i].get());
  std::shared_ptr<const Loaded> t = load(id, entry);
  size_t slot = tt.next++ % ThreadTiles::kSlots;
  tt.serial[slot] = serial_;
  tt.id[slot] = id;
  tt.tile[slot] = t;
  return *t;
}

float PackEvaluator::depth(uint32_t level, uint64_t x, uint64_t y) const {
  if (!texel_in_map(reader_->map_level(), level, x, y)) return kLitDepth;  // page_table.hpp's rule
  const PageHit hit = walk_page_table(reader_->grid(), level, x, y, [&](uint64_t id, const GridEntry& e) {
    return &tile(id, e).grid;
  });
  if (hit.kind != PageHit::Kind::tile) return hit.value;
  return tile(hit.tile, hit.entry).eval->depth(hit.rel, hit.tx, hit.ty);
}

}  // namespace st

#include "tiles/core/pack_evaluator.hpp"

#include <algorithm>
#include <optional>

#include "common/error.hpp"
#include "tiles/core/page_table.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/tap_batch.hpp"
#include "tiles/core/tap_order.hpp"

namespace st {

namespace {
// Slots hold the largest raw tile of this pack (at least 1 byte: a pack may have none).
uint32_t largest_raw_tile(const PackReader& r) {
  uint32_t most = 1;
  for (const TileIndexEntry& e : r.tiles()) most = std::max(most, e.raw_size);
  return most;
}
}  // namespace

PackEvaluator::PackEvaluator(std::shared_ptr<const PackReader> reader, size_t cache_tiles,
                             PackReader::TileOpener open_tile)
    : reader_(std::move(reader)),
      open_tile_(std::move(open_tile)),
      cache_(uint32_t(std::clamp<size_t>(cache_tiles, 1, 1u << 20)), largest_raw_tile(*reader_)),
      slot_eval_(cache_.slot_count()),
      slot_grid_(cache_.slot_count()) {
  // A stack pack has no 2D skip grid: its lookups are StackMap's (stack_map.hpp).
  if (reader_->stack())
    throw Error(reader_->name() + ": a stack pack (feature stack): look it up by slice, time or light sample, not as one map");
  if (!open_tile_) open_tile_ = reader_->tile_opener();  // with the pack's DAG-MH dictionary, if any
  cache_.reserve_pages(reader_->tiles().size());
}

uint64_t PackEvaluator::tiles_opened() const {
  std::lock_guard lock(mu_);
  return opened_;
}

uint64_t PackEvaluator::slot_bytes_written() const {
  std::lock_guard lock(mu_);
  return cache_.written_bytes();
}

void PackEvaluator::give_back(std::unique_lock<std::mutex>& lock, uint32_t slot,
                              void (TileCache::*release)(uint32_t)) const {
  lock.lock();
  (cache_.*release)(slot);
  unpinned_.notify_all();  // a lookup may be waiting for a slot to reserve
}

uint32_t PackEvaluator::resident_slot(uint64_t id, const GridEntry& entry, std::unique_lock<std::mutex>& lock) const {
  const PageEntry page = cache_.access(id);
  if (page.state == PageState::resident) return page.slot;
  cache_.request(id);  // absent -> requested (already requested: another thread reads it too)
  uint32_t slot;
  for (;;) {  // every slot pinned by other threads' lookups: wait until one lets go
    try {
      slot = cache_.reserve(id);
      break;
    } catch (const CacheFullError&) {
      unpinned_.wait(lock);
    }
  }
  lock.unlock();
  std::unique_ptr<Evaluator> eval;
  CutGrid grid;
  size_t used = 0;
  try {
    if (entry.kind == EntryKind::index) {
      grid = reader_->read_index_tile(id, entry);  // parsed apart: the slot stays unwritten
    } else {
      // Only the tile's raw bytes of the slot (the slot's own entry: no lock needed), so
      // that commit clears nothing past them. A tile larger than the slot gets the whole
      // slot, and read_raw_into refuses it naming both sizes; an unknown id is refused there.
      const std::optional<TileIndexEntry> t = reader_->find(id);
      const std::span<uint8_t> into =
          cache_.slot_span(slot, t ? std::min(t->raw_size, cache_.slot_bytes()) : 0);
      used = reader_->read_raw_into(id, into);
      const std::string what = reader_->name() + ": " + describe_tile(id);
      try {
        eval = open_tile_(into.first(used));
      } catch (const FormatError&) {
        throw;
      } catch (const Error& err) {
        throw FormatError(what + ": " + err.what());
      }
      const TileAddress a = tile_address(id);
      if (eval->finest_level() != reader_->map_level() - a.level)
        throw FormatError(what + ": finest level " + std::to_string(eval->finest_level()) + ", expected " +
                          std::to_string(reader_->map_level() - a.level));
    }
  } catch (...) {
    give_back(lock, slot, &TileCache::abort);
    throw;
  }
  lock.lock();
  ++opened_;
  slot_eval_[slot] = std::move(eval);
  slot_grid_[slot] = std::move(grid);
  const bool committed = cache_.commit(slot, uint32_t(used));
  unpinned_.notify_all();
  if (committed) return slot;
  // Another thread made the tile resident meanwhile (commit gave this slot back).
  slot_eval_[slot].reset();
  const PageEntry now = cache_.access(id);
  ST_CHECK(now.state == PageState::resident);
  return now.slot;
}

float PackEvaluator::depth(uint32_t level, uint64_t x, uint64_t y) const {
  if (!texel_in_map(reader_->map_level(), level, x, y)) return kLitDepth;  // page_table.hpp's rule
  std::unique_lock lock(mu_);
  const PageHit hit = walk_page_table(reader_->grid(), level, x, y, [&](uint64_t id, const GridEntry& e) {
    return &slot_grid_[resident_slot(id, e, lock)];
  });
  if (hit.kind != PageHit::Kind::tile) return hit.value;
  const uint32_t slot = resident_slot(hit.tile, hit.entry, lock);
  cache_.pin(slot);  // evaluated outside the lock: nothing may evict it meanwhile
  lock.unlock();
  float v;
  try {
    v = slot_eval_[slot]->depth(hit.rel, hit.tx, hit.ty);
  } catch (...) {
    give_back(lock, slot, &TileCache::unpin);
    throw;
  }
  give_back(lock, slot, &TileCache::unpin);
  return v;
}

void PackEvaluator::pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const {
  const size_t n = std::min(queries.size(), out.size());
  const uint32_t map_level = reader_->map_level();
  uint16_t order[kTapOrderMax];
  TapPath path;  // the last run's walk (a path resumes only in the tile it was walked in)
  for (size_t b0 = 0; b0 < n; b0 += kTapOrderMax) {
    const size_t bn = std::min(kTapOrderMax, n - b0);
    const PcfQuery* const base = queries.data() + b0;
    float* const base_out = out.data() + b0;
    tap_order_or_identity(std::span(base, bn), map_level, order);
    for (size_t k = 0; k < bn;) {
      const size_t i = order[k];
      const PcfQuery& q = base[i];
      if (q.r > 1 || q.level > map_level) {
        base_out[i] = pcf(q.level, q.x, q.y, q.r, q.receiver);
        ++k;
        continue;
      }
      const uint64_t top = (uint64_t(1) << q.level) - 1;  // pcf_tap's clamp of one tap
      const uint64_t x = std::min(q.x, top), y = std::min(q.y, top);
      std::unique_lock lock(mu_);
      const PageHit hit = walk_page_table(reader_->grid(), q.level, x, y, [&](uint64_t id, const GridEntry& e) {
        return &slot_grid_[resident_slot(id, e, lock)];
      });
      if (hit.kind != PageHit::Kind::tile) {
        lock.unlock();
        base_out[i] = tap_lit(q.receiver, hit.value);
        ++k;
        continue;
      }
      const uint32_t slot = resident_slot(hit.tile, hit.entry, lock);
      cache_.pin(slot);  // evaluated outside the lock: nothing may evict it meanwhile
      lock.unlock();
      // The run: this tap and the single taps after it in the same tile, which the run's
      // own loop finds (TapRun::side).
      const uint64_t x0 = x - hit.tx, y0 = y - hit.ty, side = uint64_t(1) << hit.rel;
      const Evaluator* ev = slot_eval_[slot].get();
      const TapRun run{base, order + k, bn - k, q.level, hit.rel, x0, y0, base_out, side};
      path.owner = nullptr;  // the slot's evaluator may stand at a freed one's address
      TapRunEnd end;
      try {
        if (const auto* walks = dynamic_cast<const TapWalks*>(ev)) {
          end = walks->tap_run(run, path);
        } else {
          end = tap_run_loop(run, [&](uint32_t l, uint64_t tx, uint64_t ty) { return ev->depth_region(l, tx, ty); });
        }
      } catch (...) {
        give_back(lock, slot, &TileCache::unpin);
        throw;
      }
      give_back(lock, slot, &TileCache::unpin);
      // A run that ended at once (its first tap outside it: a broken run): this tap answered
      // singly, so such a run costs time, never a loop that does not advance.
      if (end.count == 0) {
        lock.unlock();  // give_back took the lock again; pcf takes it itself
        base_out[i] = pcf(q.level, q.x, q.y, 1, q.receiver);
        end.count = 1;
      }
      k += end.count;
    }
  }
}

float PackEvaluator::pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const {
  r = std::clamp<uint32_t>(r, 1, kMaxPcf);
  const uint64_t side = uint64_t(1) << level;
  if (level > reader_->map_level() || x >= side || y >= side) return pcf_plane_by_taps(*this, level, x, y, r, p);
  const uint64_t x0 = pcf_tap(x, 0, r, side), x1 = pcf_tap(x, r - 1, r, side);
  const uint64_t y0 = pcf_tap(y, 0, r, side), y1 = pcf_tap(y, r - 1, r, side);
  std::unique_lock lock(mu_);
  const PageHit hit = walk_page_table(reader_->grid(), level, x0, y0, [&](uint64_t id, const GridEntry& e) {
    return &slot_grid_[resident_slot(id, e, lock)];
  });
  if (hit.kind == PageHit::Kind::value && x1 - x0 == r - 1 && y1 - y0 == r - 1 &&
      (x0 >> hit.region_shift) == (x1 >> hit.region_shift) && (y0 >> hit.region_shift) == (y1 >> hit.region_shift)) {
    lock.unlock();  // one value answers the whole window (no tap clamped: each texel once)
    return pcf_fraction(PlaneTaps{p, level}.count(hit.value, x0, y0, x1, y1), r);
  }
  // The kernel's window inside the tile of its first texel: the tile answers every texel
  // of it (its square at this level), and clamps its taps where the map does (a map edge
  // is a tile edge; the centre lies in the window).
  const uint64_t tx0 = x0 - hit.tx, ty0 = y0 - hit.ty;
  if (hit.kind != PageHit::Kind::tile || x1 - tx0 >= (uint64_t(1) << hit.rel) ||
      y1 - ty0 >= (uint64_t(1) << hit.rel)) {
    lock.unlock();
    return pcf_plane_by_taps(*this, level, x, y, r, p);
  }
  const uint32_t slot = resident_slot(hit.tile, hit.entry, lock);
  cache_.pin(slot);  // evaluated outside the lock: nothing may evict it meanwhile
  lock.unlock();
  float v;
  try {
    v = slot_eval_[slot]->pcf_on_plane(hit.rel, x - tx0, y - ty0, r, plane_in_tree(p, level, hit.rel, tx0, ty0));
  } catch (...) {
    give_back(lock, slot, &TileCache::unpin);
    throw;
  }
  give_back(lock, slot, &TileCache::unpin);
  return v;
}

}  // namespace st

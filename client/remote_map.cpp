#include "client/remote_map.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "tiles/core/encoding.hpp"
#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st::client {

// ---------------------------------------------------------------- Notifier

Notifier::Notifier() {
  fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (fd_ < 0) throw Error(std::string("client: eventfd: ") + std::strerror(errno));
}
Notifier::~Notifier() {
  if (fd_ >= 0) ::close(fd_);
}
void Notifier::notify() noexcept {
  if (pending_.exchange(true, std::memory_order_acq_rel)) return;
  uint64_t one = 1;
  [[maybe_unused]] ssize_t n = ::write(fd_, &one, sizeof one);  // EAGAIN only at 2^64-1
}
void Notifier::clear() noexcept {
  pending_.store(false, std::memory_order_release);
  uint64_t v;
  [[maybe_unused]] ssize_t n = ::read(fd_, &v, sizeof v);
}

// ---------------------------------------------------------------- construction

namespace {

// Heap order: higher priority first, then older (smaller seq) first.
bool heap_less(const WantedTile& a, const WantedTile& b) {
  return a.priority != b.priority ? a.priority < b.priority : a.seq > b.seq;
}

uint32_t slot_size_for(const PackHeader& h) {
  // Index tiles (CutGrids of <= kMaxIndexLevels levels) share the slots of encoded tiles.
  return std::max<uint32_t>(h.tile_bytes, uint32_t(CutGrid::serialized_size(kMaxIndexLevels)));
}

}  // namespace

RemoteMap::RemoteMap(std::string name, std::vector<uint8_t> header_bytes, std::vector<uint8_t> grid_bytes,
                     const ClientOptions& options, std::shared_ptr<Notifier> notifier)
    : name_(std::move(name)),
      options_(options),
      notifier_(std::move(notifier)),
      header_bytes_(std::move(header_bytes)),
      header_(PackHeader::parse(header_bytes_, "map '" + name_ + "' header")),
      grid_(CutGrid::parse(grid_bytes, "map '" + name_ + "' skip grid")),
      light_(LightSpace::from_array(header_.light_kind, header_.light)),
      cache_(options.cache_slots, slot_size_for(header_)) {
  const std::string what = "map '" + name_ + "'";
  if (header_.state != PackState::complete) throw FormatError(what + ": pack is not complete");
  if (header_.map_level > kMaxLevel || grid_.levels != header_.skip_level || header_.skip_level > header_.map_level)
    throw FormatError(what + ": skip grid has " + std::to_string(grid_.levels) + " levels, header says K=" +
                      std::to_string(header_.skip_level) + " L=" + std::to_string(header_.map_level));
  if (slot_size_for(header_) > options.max_slot_bytes)
    throw Error(what + ": tiles of up to " + std::to_string(header_.tile_bytes) +
                " bytes exceed ClientOptions::max_slot_bytes " + std::to_string(options.max_slot_bytes));
  slot_eval_.resize(cache_.slot_count());
  slot_grid_.resize(cache_.slot_count());
  heap_.reserve(options.want_capacity);
  cache_.reserve_pages(std::min<uint64_t>(header_.tile_count, uint64_t(options.want_capacity) + cache_.slot_count() + 4096));
  sent_.reserve(size_t(options.max_in_flight) * options.tiles_per_request);
}

// ---------------------------------------------------------------- lookups

bool RemoteMap::want_locked(uint64_t tile, const GridEntry& e, uint16_t priority) const noexcept {
  const PageEntry p = cache_.lookup(tile);
  if (p.state == PageState::absent) {
    if (heap_.size() >= options_.want_capacity) {
      ++stats_.queue_full;
      return false;
    }
    cache_.request(tile, priority);  // the page table was sized up front: no allocation
  } else if (p.state == PageState::requested && priority > p.priority && !sent_.count(tile)) {
    if (heap_.size() >= options_.want_capacity) {
      ++stats_.queue_full;
      return false;
    }
    cache_.raise_priority(tile, priority);  // the old, lower entry is skipped when popped
  } else {
    return false;
  }
  heap_.push_back(WantedTile{tile, priority, next_seq_++, e});
  std::push_heap(heap_.begin(), heap_.end(), heap_less);
  notifier_->notify();
  return true;
}

// The page-table walk of PackEvaluator::depth, over the cache: where a tile is missing,
// the entry's own value answers (the node's value stands for all its descendants).
float RemoteMap::depth_locked(uint32_t level, uint64_t x, uint64_t y) const noexcept {
  if (!texel_in_map(header_.map_level, level, x, y)) return kLitDepth;  // page_table.hpp's rule
  PageEntry page;  // the cache's answer for the last tile the walk asked about
  auto resident_index = [&](uint64_t id, const GridEntry&) -> const CutGrid* {
    page = cache_.access(id);
    return page.state == PageState::resident ? &slot_grid_[page.slot] : nullptr;
  };
  const PageHit hit = walk_page_table(grid_, level, x, y, resident_index);
  if (hit.kind == PageHit::Kind::value) return hit.value;
  if (hit.kind == PageHit::Kind::tile) page = cache_.access(hit.tile);
  if (page.state == PageState::constant) return page.value;  // given up: coarse for good
  if (page.state != PageState::resident) {
    want_locked(hit.tile, hit.entry, options_.miss_priority);
    ++stats_.coarse_answers;
    return hit.value;
  }
  try {
    return slot_eval_[page.slot]->depth(hit.rel, hit.tx, hit.ty);
  } catch (...) {  // an opened tile does not throw; if one did, stay coarse and alive
    return hit.value;
  }
}

float RemoteMap::depth(uint32_t level, uint64_t x, uint64_t y) const noexcept {
  std::lock_guard lock(mu_);
  return depth_locked(level, x, y);
}

float RemoteMap::pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const noexcept {
  r = std::clamp<uint32_t>(r, 1, kMaxPcf);
  if (level > header_.map_level) return 1.0f;
  const uint64_t side = uint64_t(1) << level;
  uint32_t lit_taps = 0;
  std::lock_guard lock(mu_);  // one lock for the whole kernel
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i)
      lit_taps += receiver <= depth_locked(level, pcf_tap(x, i, r, side), pcf_tap(y, j, r, side));
  return float(lit_taps) / float(r * r);
}

float RemoteMap::visibility(const Vec3d& world, uint32_t pcf_radius) const noexcept {
  const LightPoint p = light_.to_light(world);
  if (!(p.u >= 0 && p.u < 1 && p.v >= 0 && p.v < 1 && p.d >= 0 && p.d <= 1)) return 1.0f;
  const uint32_t level = header_.map_level;
  const auto t = LightSpace::texel_of(level, p.u, p.v);
  return pcf(level, t[0], t[1], 2 * std::min<uint32_t>(pcf_radius, (kMaxPcf - 1) / 2) + 1, float(p.d));
}

// ---------------------------------------------------------------- regions

template <class Fn>
bool RemoteMap::walk_region(uint32_t level, uint64_t x0, uint64_t y0, uint64_t x1, uint64_t y1, Fn&& fn) const {
  if (level > header_.map_level) return true;
  auto resident_index = [&](uint64_t id, const GridEntry&) -> const CutGrid* {
    const PageEntry p = cache_.lookup(id);
    return p.state == PageState::resident ? &slot_grid_[p.slot] : nullptr;
  };
  return visit_page_tiles(grid_, level, x0, y0, x1, y1, resident_index,
                          [&](uint64_t id, const GridEntry& e, uint32_t, uint64_t, uint64_t) {
                            const PageState state = cache_.lookup(id).state;
                            return state == PageState::resident || state == PageState::constant || fn(id, e);
                          });
}

namespace {
struct Clamped {
  bool empty;
  uint64_t x0, y0, x1, y1;
};
Clamped clamp_region(uint32_t level, uint32_t map_level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) {
  if (level > map_level) return {true, 0, 0, 0, 0};
  const uint64_t side = uint64_t(1) << level;
  const uint64_t x1 = x0 >= side ? side : std::min(side, x0 + std::min(w, side));
  const uint64_t y1 = y0 >= side ? side : std::min(side, y0 + std::min(h, side));
  return {x0 >= x1 || y0 >= y1, x0, y0, x1, y1};
}
}  // namespace

size_t RemoteMap::request_region(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h,
                                 uint16_t priority) noexcept {
  const Clamped c = clamp_region(level, header_.map_level, x0, y0, w, h);
  if (c.empty) return 0;
  std::lock_guard lock(mu_);
  // Remember the region so that the children of index tiles arriving later follow.
  Region r{level, c.x0, c.y0, c.x1, c.y1, priority};
  if (region_count_ == kMaxRegions) {
    std::move(regions_.begin() + 1, regions_.end(), regions_.begin());
    --region_count_;
  }
  regions_[region_count_++] = r;
  size_t queued = 0;
  walk_region(level, c.x0, c.y0, c.x1, c.y1, [&](uint64_t id, const GridEntry& e) {
    queued += want_locked(id, e, priority);
    return true;
  });
  return queued;
}

void RemoteMap::rerequest_regions_locked() {
  for (size_t i = 0; i < region_count_; ++i) {
    const Region& r = regions_[i];
    walk_region(r.level, r.x0, r.y0, r.x1, r.y1, [&](uint64_t id, const GridEntry& e) {
      want_locked(id, e, r.priority);
      return true;
    });
  }
}

bool RemoteMap::region_resident(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) const noexcept {
  const Clamped c = clamp_region(level, header_.map_level, x0, y0, w, h);
  if (c.empty) return true;
  std::lock_guard lock(mu_);
  return walk_region(level, c.x0, c.y0, c.x1, c.y1, [](uint64_t, const GridEntry&) { return false; });
}

size_t RemoteMap::cancel_outside(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) noexcept {
  const Clamped c = clamp_region(level, header_.map_level, x0, y0, w, h);
  const uint32_t L = header_.map_level;
  // Compare footprints at the finest level (exact integers up to 2^20).
  const uint32_t up = c.empty ? 0 : L - level;
  const uint64_t fx0 = c.x0 << up, fx1 = c.x1 << up, fy0 = c.y0 << up, fy1 = c.y1 << up;
  auto outside = [&](uint64_t id) {
    if (c.empty) return true;
    const TileAddress a = tile_address(id);
    const uint32_t s = L - a.level;
    const uint64_t tx0 = uint64_t(a.x) << s, tx1 = uint64_t(a.x + 1) << s;
    const uint64_t ty0 = uint64_t(a.y) << s, ty1 = uint64_t(a.y + 1) << s;
    return tx1 <= fx0 || tx0 >= fx1 || ty1 <= fy0 || ty0 >= fy1;
  };
  std::lock_guard lock(mu_);
  size_t n = 0;
  try {
    auto keep_end = std::partition(heap_.begin(), heap_.end(), [&](const WantedTile& w) { return !outside(w.tile); });
    for (auto it = keep_end; it != heap_.end(); ++it)
      if (!sent_.count(it->tile) && cache_.lookup(it->tile).state == PageState::requested) {
        cache_.cancel_request(it->tile);
        ++n;
      }
    heap_.erase(keep_end, heap_.end());
    std::make_heap(heap_.begin(), heap_.end(), heap_less);
    for (auto& [id, w] : sent_)
      if (outside(id) && w.seq != ~uint64_t(0)) {
        cancels_.push_back(id);  // may allocate: an API call, not a lookup
        w.seq = ~uint64_t(0);    // marks "Cancel sent"
        ++n;
      }
    size_t kept = 0;
    for (size_t i = 0; i < region_count_; ++i) {
      const Region& r = regions_[i];
      const uint32_t ru = L - r.level;
      const bool meets = !c.empty && !((r.x1 << ru) <= fx0 || (r.x0 << ru) >= fx1 ||
                                       (r.y1 << ru) <= fy0 || (r.y0 << ru) >= fy1);
      if (meets) regions_[kept++] = r;
    }
    region_count_ = kept;
  } catch (...) {
    // Only cancels_.push_back can throw (bad_alloc): the cancel is then just not sent.
  }
  if (!cancels_.empty()) notifier_->notify();
  return n;
}

MapStats RemoteMap::stats() const noexcept {
  std::lock_guard lock(mu_);
  MapStats s = stats_;
  const CacheStats c = cache_.stats();
  s.cache = CacheCounters{c.hits, c.misses, c.evictions, c.inserts, c.resident, c.pinned, c.free};
  return s;
}

// ---------------------------------------------------------------- fetcher side

void RemoteMap::take_wanted(size_t max, std::vector<WantedTile>& out) {
  std::lock_guard lock(mu_);
  while (out.size() < max && !heap_.empty()) {
    std::pop_heap(heap_.begin(), heap_.end(), heap_less);
    WantedTile w = heap_.back();
    heap_.pop_back();
    const PageEntry p = cache_.lookup(w.tile);
    // Stale entries: answered, cancelled, already sent, or superseded by a raise.
    if (p.state != PageState::requested || sent_.count(w.tile) || w.priority < p.priority) continue;
    sent_.emplace(w.tile, w);
    out.push_back(w);
    ++stats_.tiles_requested;
  }
}

void RemoteMap::take_cancels(std::vector<uint64_t>& out) {
  std::lock_guard lock(mu_);
  out.insert(out.end(), cancels_.begin(), cancels_.end());
  cancels_.clear();
}

bool RemoteMap::has_work() const {
  std::lock_guard lock(mu_);
  return !heap_.empty() || !cancels_.empty();
}

size_t RemoteMap::sent_count() const {
  std::lock_guard lock(mu_);
  return sent_.size();
}

void RemoteMap::give_up_locked(uint64_t tile, float value) {
  ++stats_.tiles_failed;
  retries_.erase(tile);
  // A constant page: lookups answer with the entry's value and never ask again.
  cache_.set_constant(tile, value);
}

void RemoteMap::retry_or_give_up(uint64_t tile, const char* /*why*/, uint64_t MapStats::*counter) noexcept {
  std::lock_guard lock(mu_);
  ++(stats_.*counter);
  auto it = sent_.find(tile);
  if (it == sent_.end()) return;
  WantedTile w = it->second;
  sent_.erase(it);
  try {
    if (++retries_[tile] > options_.max_tile_retries) return give_up_locked(tile, w.entry.value);
  } catch (...) {
    return;
  }
  // Refetch: the page is still `requested`; queue it again at its priority.
  if (cache_.lookup(tile).state != PageState::requested && !cache_.request(tile, w.priority)) return;
  if (heap_.size() >= options_.want_capacity) {
    cache_.cancel_request(tile);
    return;
  }
  w.seq = next_seq_++;
  heap_.push_back(w);
  std::push_heap(heap_.begin(), heap_.end(), heap_less);
  notifier_->notify();
}

void RemoteMap::tile_arrived(const proto::TileMeta& meta, std::span<const uint8_t> stored) noexcept {
  const uint64_t tile = meta.tile_id;
  WantedTile w;
  {
    std::lock_guard lock(mu_);
    auto it = sent_.find(tile);
    if (it == sent_.end()) return;  // not asked for (late duplicate): ignore
    w = it->second;
  }
  // End to end: the stored bytes must be the bytes the pack builder wrote (the frame CRC
  // only covers the hop). A mismatch is refetched.
  if (!proto::tile_crc_matches(meta, stored)) return retry_or_give_up(tile, "crc", &MapStats::crc_errors);
  const std::string what = "map '" + name_ + "': " + describe_tile(tile);
  std::vector<uint8_t> raw;
  try {
    if (meta.uncompressed_size > cache_.slot_bytes())
      throw FormatError(what + ": " + std::to_string(meta.uncompressed_size) + " bytes exceed the slot size");
    if (meta.flags & proto::kTileFlagZlib) raw = zlib_decompress(stored, meta.uncompressed_size, what);
    else if (stored.size() == meta.uncompressed_size) raw.assign(stored.begin(), stored.end());
    else throw FormatError(what + ": raw tile size differs from uncompressed_size");
  } catch (...) {
    return retry_or_give_up(tile, "decode", &MapStats::decode_errors);
  }
  uint32_t slot = kNoSlot;
  {
    std::lock_guard lock(mu_);
    const PageEntry p = cache_.lookup(tile);
    if (p.state == PageState::resident || p.state == PageState::constant) {
      sent_.erase(tile);
      return;
    }
    try {
      slot = cache_.reserve(tile);  // evicts the least recently used unpinned tile
    } catch (...) {
      ++stats_.cache_full;
      sent_.erase(tile);
      cache_.cancel_request(tile);
      return;
    }
    stats_.bytes_received += stored.size();
  }
  // The slot is pinned and unpublished: fill and open it without the lock.
  std::span<uint8_t> dst = cache_.slot_span(slot);
  if (!raw.empty()) std::memcpy(dst.data(), raw.data(), raw.size());
  const std::span<const uint8_t> bytes(dst.data(), raw.size());
  std::unique_ptr<Evaluator> ev;
  CutGrid g;
  bool ok = false;
  try {
    const TileAddress a = tile_address(tile);
    if (w.entry.kind == EntryKind::tile) {
      ev = open_encoded(header_.encoding, bytes);
      ok = ev && ev->finest_level() == header_.map_level - a.level;
    } else {
      g = CutGrid::parse(bytes, what, kMaxIndexLevels);
      ok = g.levels == w.entry.index_levels && a.level + g.levels <= header_.map_level &&
           std::memcmp(&g.coarse[0], &w.entry.value, sizeof(float)) == 0;
    }
  } catch (...) {
    ok = false;
  }
  bool index_arrived = false;
  {
    std::lock_guard lock(mu_);
    if (!ok) {
      // Retried below like a CRC failure (a corrupt stream that still matched its CRC
      // is a bad pack; after the retries the tile is given up).
      cache_.abort(slot);
      cache_.request(tile, w.priority);
    } else {
      slot_eval_[slot] = std::move(ev);
      slot_grid_[slot] = std::move(g);
      sent_.erase(tile);
      if (cache_.commit(slot, uint32_t(raw.size()))) {
        ++stats_.tiles_received;
        retries_.erase(tile);
        index_arrived = w.entry.kind == EntryKind::index;
      }
      if (index_arrived) rerequest_regions_locked();
    }
  }
  if (!ok) retry_or_give_up(tile, "open", &MapStats::decode_errors);
}

void RemoteMap::tile_refused(uint64_t tile, proto::ErrorCode code) noexcept {
  std::lock_guard lock(mu_);
  auto it = sent_.find(tile);
  if (it == sent_.end()) return;
  const float value = it->second.entry.value;
  sent_.erase(it);
  if (code == proto::ErrorCode::cancelled) {
    ++stats_.tiles_cancelled;
    cache_.cancel_request(tile);
  } else {
    give_up_locked(tile, value);
  }
}

void RemoteMap::connection_lost() noexcept {
  std::lock_guard lock(mu_);
  for (auto& [id, w] : sent_) {
    const PageEntry p = cache_.lookup(id);
    if (p.state != PageState::requested) continue;
    if (w.seq == ~uint64_t(0) || heap_.size() >= options_.want_capacity) {  // cancelled or no room
      cache_.cancel_request(id);
      continue;
    }
    WantedTile again = w;
    again.priority = p.priority;
    again.seq = next_seq_++;
    heap_.push_back(again);
    std::push_heap(heap_.begin(), heap_.end(), heap_less);
  }
  sent_.clear();
  cancels_.clear();
  if (!heap_.empty()) notifier_->notify();
}

}  // namespace st::client

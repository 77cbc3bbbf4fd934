// RemoteMap's residency (client/remote_map.hpp): construction and the cache's budget,
// regions asked for and cancelled, stats, and the fetcher side (requests taken, tiles
// arriving, refused or lost). The lookups are remote_map_lookups.cpp.
#include "client/remote_map.hpp"

#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <shared_mutex>

#include "common/error.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "tiles/core/pack_light_check.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/stack_slices.hpp"

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

uint32_t slot_size_for(const PackHeader& h) {
  // Index tiles (CutGrids of <= kMaxIndexLevels levels) share the slots of encoded tiles.
  return std::max<uint32_t>(h.tile_bytes, uint32_t(CutGrid::serialized_size(kMaxIndexLevels)));
}

// The grid section's parts (pack_dictionary.hpp); a stack pack's section is its stack grid.
GridSectionParts grid_parts(const PackHeader& h, std::span<const uint8_t> grid_bytes, const std::string& name) {
  return split_grid_section(grid_bytes, h.skip_level, h.flags & kFeatureDagmhDictionary,
                            "map '" + name + "': grid section");
}

std::shared_ptr<const dagmh::Dictionary> dictionary_of(const PackHeader& h, std::span<const uint8_t> grid_bytes,
                                                       const std::string& name) {
  if (!(h.flags & kFeatureDagmhDictionary)) return nullptr;
  return open_pack_dictionary(grid_parts(h, grid_bytes, name), "map '" + name + "': DAG-MH dictionary");
}

// The map's memory besides its slots (ClientOptions::cache_bytes): the grid section
// twice (as it came, then parsed: the skip grid's entries and coarse values, the
// preview's per-entry ordinals and values, or a stack grid), the dictionary inflated, the
// request table, and the page-table entries that are not a slot's (requested pages and
// remembered failures; 64 bytes each: a 24-byte bucket at a load factor >= 3/8).
uint64_t metadata_bytes(const ClientOptions& o, const PackHeader& h, size_t grid_section_bytes,
                        const dagmh::Dictionary* dict) {
  const uint64_t requests = uint64_t(o.want_capacity) + uint64_t(o.max_in_flight) * o.tiles_per_request;
  const uint64_t request_table = requests * (sizeof(RequestRecord) + 3 * sizeof(uint32_t) + sizeof(uint64_t)) +
                                 2 * uint64_t(o.want_capacity) * 16;
  return kPackHeaderBytes + 2 * uint64_t(grid_section_bytes) + (dict ? dict->memory_bytes() : 0) + request_table +
         std::min<uint64_t>(h.tile_count, requests + kPageReserve + kMaxFailedTiles) * 64;
}

// The slot count a byte budget gives (cache_bytes): the metadata (the DAG-MH dictionary
// included) first, then slots of slot size + kSlotOverheadBytes; a budget that leaves
// fewer than kMinTileSlots is refused, naming the sizes and the budget to set. Without a
// budget: cache_slots slots, all for tiles (the dictionary is held beside them).
uint32_t budget_slots(const ClientOptions& o, const PackHeader& h, const dagmh::Dictionary* dict,
                      size_t grid_section_bytes, const std::string& name) {
  if (o.cache_bytes == 0) return o.cache_slots;
  const uint64_t meta = metadata_bytes(o, h, grid_section_bytes, dict);
  const uint64_t per_slot = uint64_t(slot_size_for(h)) + kSlotOverheadBytes;
  const uint64_t need = meta + kMinTileSlots * per_slot;
  if (o.cache_bytes < need) {
    const std::string of_which =
        dict ? ", of which " + std::to_string(dict->memory_bytes()) + " are the DAG-MH dictionary" : "";
    throw Error("map '" + name + "': a cache of " + std::to_string(o.cache_bytes) + " bytes cannot hold its metadata (" +
                std::to_string(meta) + " bytes" + of_which + ") and the " + std::to_string(kMinTileSlots) +
                " tile slots a view needs at least (" + std::to_string(per_slot) + " bytes each: tiles of up to " +
                std::to_string(h.tile_bytes) + " bytes): set cache_bytes (--cache-mb) to at least " +
                std::to_string(need) + " bytes (" + std::to_string((need + 1048575) >> 20) + " MiB)");
  }
  return uint32_t(std::min<uint64_t>((o.cache_bytes - meta) / per_slot, uint64_t(1) << 24));
}

// The tile slots the dictionary displaces (MapStats::dictionary_slots): with a byte
// budget, the slots the same budget gives the same map without its dictionary (neither
// inflated nor in the grid section) less those it gives with it: the arithmetic of
// budget_slots, so exact; without a budget, 0.
uint32_t displaced_slots(const ClientOptions& o, const PackHeader& h, const dagmh::Dictionary* dict,
                         std::span<const uint8_t> grid_bytes, const std::string& name, uint32_t slots) {
  if (o.cache_bytes == 0 || !dict) return 0;
  const GridSectionParts parts = grid_parts(h, grid_bytes, name);  // the section less the dictionary's (header too)
  const size_t section = parts.skip_grid.size() + parts.preview.size();
  const uint64_t meta = metadata_bytes(o, h, section, nullptr);
  const uint64_t per_slot = uint64_t(slot_size_for(h)) + kSlotOverheadBytes;
  const uint64_t without = o.cache_bytes > meta ? std::min<uint64_t>((o.cache_bytes - meta) / per_slot, uint64_t(1) << 24) : 0;
  return uint32_t(without > slots ? without - slots : 0);
}

// A MapInfo's pack header, checked as the pack reader checks a file's (the light too).
PackHeader checked_header(std::span<const uint8_t> bytes, const std::string& name) {
  PackHeader h = PackHeader::parse(bytes, "map '" + name + "' header");
  check_header_light(h, "map '" + name + "' header");
  return h;
}

}  // namespace

RemoteMap::RemoteMap(std::string name, std::vector<uint8_t> header_bytes, std::vector<uint8_t> grid_bytes,
                     const ClientOptions& options, std::shared_ptr<Notifier> notifier)
    : name_(std::move(name)),
      options_(options),
      notifier_(std::move(notifier)),
      header_bytes_(std::move(header_bytes)),
      header_(checked_header(header_bytes_, name_)),
      grid_(header_.flags & kFeatureStack
                ? CutGrid::constant(0, kLitDepth)
                : CutGrid::parse(std::span<const uint8_t>(grid_bytes).first(
                                     std::min(grid_bytes.size(), CutGrid::serialized_size(header_.skip_level))),
                                 "map '" + name_ + "' skip grid")),
      // A stack pack's grid section is its stack grid (remote_stack.cpp): no map preview.
      preview_(header_.flags & kFeatureStack
                   ? MapPreview()
                   : MapPreview::parse(grid_parts(header_, grid_bytes, name_).preview, grid_, header_.map_level,
                                       "map '" + name_ + "'")),
      dictionary_(dictionary_of(header_, grid_bytes, name_)),
      light_(LightSpace::from_array(header_.light_kind, header_.light)),
      cache_(budget_slots(options, header_, dictionary_.get(), grid_bytes.size(), name_), slot_size_for(header_)),
      // No ceiling below the slots': a tile is in the arena or in its slot (tile_arena.hpp).
      arena_(cache_.slot_count(), cache_.slot_bytes()),
      metadata_bytes_(metadata_bytes(options, header_, grid_bytes.size(), dictionary_.get())),
      dictionary_slots_(displaced_slots(options, header_, dictionary_.get(), grid_bytes, name_, cache_.slot_count())),
      requests_(size_t(options.want_capacity) + size_t(options.max_in_flight) * options.tiles_per_request,
                options.want_capacity) {
  const std::string what = "map '" + name_ + "'";
  if (header_.state != PackState::complete) throw FormatError(what + ": pack is not complete");
  if (header_.flags & kFeatureStack) open_stack(grid_bytes);
  else if (header_.map_level > kMaxLevel || grid_.levels != header_.skip_level || header_.skip_level > header_.map_level)
    throw FormatError(what + ": skip grid has " + std::to_string(grid_.levels) + " levels, header says K=" +
                      std::to_string(header_.skip_level) + " L=" + std::to_string(header_.map_level));
  if (slot_size_for(header_) > options.max_slot_bytes)
    throw Error(what + ": tiles of up to " + std::to_string(header_.tile_bytes) +
                " bytes exceed ClientOptions::max_slot_bytes " + std::to_string(options.max_slot_bytes));
  slot_used_ = std::make_unique<std::atomic<uint32_t>[]>(cache_.slot_count());  // zero: never used
  slot_eval_.resize(cache_.slot_count());
  slot_window_.resize(cache_.slot_count());
  slot_walks_.resize(cache_.slot_count());
  slot_grid_.resize(cache_.slot_count());
  slot_in_view_.assign(cache_.slot_count(), 0);
  // Pages are requested (one per record), resident (one per slot) or constant: sized so
  // that requesting a page from a lookup does not grow the table.
  cache_.reserve_pages(std::min<uint64_t>(header_.tile_count, requests_.capacity() + cache_.slot_count() + kPageReserve));
  cancels_.reserve(requests_.capacity());
  if (header_.flags & kFeatureDeepShadow)  // the deep part (deep_part.hpp): its own small cache
    deep_ = std::make_unique<DeepPart>(name_, header_.tile_bytes,
                                       options.cache_bytes ? std::max<uint32_t>(1, cache_.slot_count() / 4)
                                                           : options.cache_slots,
                                       options.max_tile_retries,
                                       std::max<uint16_t>(options.miss_priority, 1), notifier_);
  if (!stack_grid_) {
    info_light_ = std::make_shared<const LightSpace>(light_);
    surface_ = surface_extent(light_, grid_);
  } else {
    info_light_ = std::make_shared<const LightSpace>(stack_grid_->light(0));
    surface_ = stack_surface();
  }
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
  size_t queued = 0;
  bool pending = false;
  walk_region(level, c.x0, c.y0, c.x1, c.y1, [&](uint64_t id, const GridEntry& e) {
    pending = true;
    queued += want_locked(id, e, priority);
    return true;
  });
  // Not resident yet: remembered so that the children of index tiles arriving later follow.
  if (pending) remember_region_locked(RegionRequest{level, c.x0, c.y0, c.x1, c.y1, priority});
  return queued;
}

void RemoteMap::remember_region_locked(const RegionRequest& r) {
  auto contains = [](const RegionRequest& a, const RegionRequest& b) {
    return a.level == b.level && a.x0 <= b.x0 && a.y0 <= b.y0 && b.x1 <= a.x1 && b.y1 <= a.y1;
  };
  size_t kept = 0;
  for (size_t i = 0; i < region_count_; ++i) {
    RegionRequest& q = regions_[i];
    if (contains(q, r)) {  // asked again (a view's cells every frame): one entry, the higher priority
      q.priority = std::max(q.priority, r.priority);
      return;
    }
    if (contains(r, q)) continue;  // the new one covers it
    regions_[kept++] = q;
  }
  region_count_ = kept;
  if (region_count_ == kMaxRegions) {
    rerequest_regions_locked();  // drops the complete ones
    if (region_count_ > kMaxRegions - kMaxRegions / 4) {
      const size_t drop = region_count_ - (kMaxRegions - kMaxRegions / 4);  // the oldest
      std::move(regions_.begin() + drop, regions_.begin() + region_count_, regions_.begin());
      region_count_ -= drop;
    }
  }
  regions_[region_count_++] = r;
}

void RemoteMap::rerequest_regions_locked() {
  size_t kept = 0;
  for (size_t i = 0; i < region_count_; ++i) {
    const RegionRequest r = regions_[i];
    bool pending = false;
    walk_region(r.level, r.x0, r.y0, r.x1, r.y1, [&](uint64_t id, const GridEntry& e) {
      pending = true;
      want_locked(id, e, r.priority);
      return true;
    });
    if (pending) regions_[kept++] = r;
  }
  region_count_ = kept;
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
  requests_.for_each([&](RequestRecord& r) {
    if (!outside(r.tile)) return;
    if (r.state == RequestState::queued) {
      drop_locked(r);
      ++n;
    } else if (r.state == RequestState::sent && cancels_.size() < cancels_.capacity()) {
      // Reserved for every record: never allocates. The answer is still owed; a tile that
      // arrives anyway is kept (its bytes are good).
      cancels_.push_back(r.tile);
      r.state = RequestState::cancel_sent;
      ++n;
    }
  });
  size_t kept = 0;
  for (size_t i = 0; i < region_count_; ++i) {
    const RegionRequest& r = regions_[i];
    const uint32_t ru = L - r.level;
    const bool meets = !c.empty && !((r.x1 << ru) <= fx0 || (r.x0 << ru) >= fx1 ||
                                     (r.y1 << ru) <= fy0 || (r.y0 << ru) >= fy1);
    if (meets) regions_[kept++] = r;
  }
  region_count_ = kept;
  if (!cancels_.empty()) notifier_->notify();
  return n;
}

MapStats RemoteMap::stats() const noexcept {
  std::lock_guard lock(mu_);
  MapStats s = stats_;
  s.dictionary_bytes = dictionary_ ? dictionary_->memory_bytes() : 0;
  s.accounted_bytes = metadata_bytes_ + uint64_t(cache_.slot_count()) * (cache_.slot_bytes() + kSlotOverheadBytes);
  s.tile_slots = cache_.slot_count();
  s.arena_bytes = arena_.held_bytes();
  s.slot_bytes_written = cache_.written_bytes();
  s.dictionary_slots = dictionary_slots_;
  s.views = view_count_;
  s.view_slots = view_slots();
  {
    uint64_t wanted = 0;
    for (const View& v : views_)
      if (v.used) wanted += v.wanted;
    s.view_tiles_wanted = wanted;
    s.view_tiles_over = wanted > s.view_slots ? wanted - s.view_slots : 0;
  }
  const CacheStats c = cache_.stats();
  s.cache = CacheCounters{c.hits, c.misses, c.evictions, c.inserts, c.resident, c.pinned, c.free};
  for (const CounterShard& k : counters_) {  // lookups count here, not in the cache
    s.cache.hits += k.hits.load(std::memory_order_relaxed);
    s.cache.misses += k.misses.load(std::memory_order_relaxed);
    s.coarse_answers += k.coarse.load(std::memory_order_relaxed);
  }
  return s;
}

// ---------------------------------------------------------------- fetcher side

void RemoteMap::take_wanted(size_t max, uint32_t request_id, std::vector<proto::TileRequest>& out) {
  if (deep_) {  // the deep part's wants first (few: its directory, then the tiles lookups missed)
    const size_t before = out.size();
    deep_->take_wanted(max, request_id, out);
    max -= out.size() - before;
  }
  std::lock_guard lock(mu_);
  if (failed_ >= kMaxFailedTiles) {  // the server refused too much: what is queued is not sent either
    if (requests_.queued() > 0)
      requests_.for_each([&](RequestRecord& r) {
        if (r.state == RequestState::queued) drop_locked(r);
      });
    return;
  }
  for (size_t taken = 0; taken < max; ++taken) {
    const RequestRecord* r = requests_.pop(request_id);
    if (!r) break;
    out.push_back(proto::TileRequest{r->tile, r->priority});
    ++stats_.tiles_requested;
  }
}

void RemoteMap::take_cancels(std::vector<uint64_t>& out) {
  std::lock_guard lock(mu_);
  out.insert(out.end(), cancels_.begin(), cancels_.end());
  cancels_.clear();
}

bool RemoteMap::has_work() const {
  if (deep_ && deep_->has_work()) return true;
  std::lock_guard lock(mu_);
  return requests_.queued() > 0 || !cancels_.empty();
}

size_t RemoteMap::sent_count() const {
  std::lock_guard lock(mu_);
  return requests_.in_flight();
}

RequestRecord* RemoteMap::sent_record_locked(uint64_t tile, uint32_t request_id) noexcept {
  RequestRecord* r = requests_.find(tile);
  if (!r || r->state == RequestState::queued || r->request_id != request_id) return nullptr;
  return r;
}

void RemoteMap::drop_locked(RequestRecord& r) noexcept {
  cache_.cancel_request(r.tile);  // requested -> absent: a later lookup may ask again
  requests_.erase(r);
}

void RemoteMap::give_up_locked(RequestRecord& r) noexcept {
  ++stats_.tiles_failed;
  const uint64_t tile = r.tile;
  const float value = r.entry.value;
  requests_.erase(r);
  // Remembered (a constant page: never asked again) up to kMaxFailedTiles; the one that
  // reaches it stops new requests (want_locked), so nothing is asked again either way.
  if (failed_ >= kMaxFailedTiles) return cache_.cancel_request(tile);
  ++failed_;
  try {
    cache_.set_constant(tile, value);  // the page exists (requested): nothing allocates
  } catch (...) {                      // only a pinned resident page refuses, and this one is not
    cache_.cancel_request(tile);
  }
}

void RemoteMap::request_ended(uint32_t request_id) noexcept {
  std::lock_guard lock(mu_);
  requests_.for_each([&](RequestRecord& r) {
    if (r.state == RequestState::queued || r.request_id != request_id) return;
    ++stats_.tiles_unanswered;
    if (r.state == RequestState::cancel_sent) return drop_locked(r);
    // Counted as a failed delivery: asked again up to max_tile_retries, then given up.
    if (++r.retries > options_.max_tile_retries) return give_up_locked(r);
    if (!requests_.requeue(r)) drop_locked(r);
  });
  if (requests_.queued() > 0) notifier_->notify();
}

void RemoteMap::retry_or_give_up(uint64_t tile, uint32_t request_id, uint64_t MapStats::*counter) noexcept {
  std::lock_guard lock(mu_);
  retry_or_give_up_locked(tile, request_id, counter);
}

void RemoteMap::retry_or_give_up_locked(uint64_t tile, uint32_t request_id, uint64_t MapStats::*counter) noexcept {
  ++(stats_.*counter);
  RequestRecord* r = sent_record_locked(tile, request_id);
  if (!r) return;
  // Cancelled meanwhile: nobody wants it any more, so no refetch (and no give-up either:
  // a later want may try again from scratch).
  if (r->state == RequestState::cancel_sent) return drop_locked(*r);
  if (++r->retries > options_.max_tile_retries) return give_up_locked(*r);
  // Refetch at the same priority. A slot given back (abort) left the page absent.
  try {
    cache_.request(tile);
  } catch (...) {
    return drop_locked(*r);
  }
  if (!requests_.requeue(*r)) return drop_locked(*r);  // queue full: a later want asks again
  notifier_->notify();
}

bool RemoteMap::fill_slot(uint32_t slot, const proto::TileMeta& meta, const GridEntry& entry,
                          std::span<const uint8_t> stored, bool to_arena, std::unique_ptr<Evaluator>& ev, CutGrid& grid,
                          std::span<const uint8_t>& held) noexcept {
  try {
    const std::string what = "map '" + name_ + "': " + describe_tile(meta.tile_id);
    // A map tile is inflated once, into the arena (tile_arena.hpp), where its evaluator
    // and the cache's readers (TileCache::commit_held) find it; its slot is never
    // written. Index tiles, stack cells and a tile past the arena's ceiling go in the slot.
    std::span<uint8_t> raw;
    if (to_arena) raw = arena_.reserve(slot, meta.uncompressed_size);
    else arena_.release(slot);  // nothing of the slot's last tile is kept
    if (raw.data()) held = raw;
    else raw = cache_.slot_span(slot, meta.uncompressed_size);  // the slot's own entry only: no lock needed
    if (meta.flags & proto::kTileFlagZlib) zlib_decompress_into(stored, raw, what);
    else if (!raw.empty()) std::memcpy(raw.data(), stored.data(), raw.size());  // sizes checked by the caller
    const TileAddress a = tile_address(meta.tile_id);
    if (stack_grid_) {  // an MH octree of one stack cell (remote_stack.cpp)
      if (is_grouped_slice_tiles(raw)) {  // a grouped per-slice cell: only in a pack that says so
        if (!(header_.flags & kFeatureStackGroupedTiles)) return false;
        uint32_t need = 0;  // packed plane slices: only in a pack that says so
        ungroup_slice_tiles(raw, &need);
        if ((header_.flags & need) != need) return false;
      }
      ev = open_stack_tile(*stack_grid_, meta.tile_id, raw, header_.flags);
      return bool(ev);
    }
    if (entry.kind == EntryKind::tile) {
      // A packed or version 3 plane tile: only in a pack that says so.
      const uint32_t need = plane_tile_features(raw);
      if ((header_.flags & need) != need) return false;
      if (is_packed_plane_tile(raw)) unpack_plane_tile(raw);
      ev = open_pack_tile(header_.encoding, raw, dictionary_);  // v2 DAG-MH tiles through the dictionary
      return ev && ev->finest_level() == header_.map_level - a.level;
    }
    grid = CutGrid::parse(raw, what, kMaxIndexLevels);
    return grid.levels == entry.index_levels && a.level + grid.levels <= header_.map_level &&
           std::memcmp(&grid.coarse[0], &entry.value, sizeof(float)) == 0;
  } catch (...) {
    return false;
  }
}

bool RemoteMap::tile_arrived(const proto::TileMeta& meta, uint32_t request_id,
                             std::span<const uint8_t> stored) noexcept {
  const uint64_t tile = meta.tile_id;
  if (is_deep_id(tile)) {
    if (deep_) deep_->tile_arrived(meta, request_id, stored);
    return true;
  }
  GridEntry entry;
  {
    std::lock_guard lock(mu_);
    const RequestRecord* r = sent_record_locked(tile, request_id);
    if (!r) return false;  // not asked for in this request (a late duplicate, a wrong id): ignore
    entry = r->entry;
  }
  tile_answer(meta, request_id, stored, entry);
  return true;
}

void RemoteMap::tile_answer(const proto::TileMeta& meta, uint32_t request_id, std::span<const uint8_t> stored,
                            const GridEntry& entry) noexcept {
  const uint64_t tile = meta.tile_id;
  // End to end: the stored bytes must be the bytes the pack builder wrote (the frame CRC
  // only covers the hop). A mismatch is refetched.
  if (!proto::tile_crc_matches(meta, stored)) return retry_or_give_up(tile, request_id, &MapStats::crc_errors);
  const bool zlib = (meta.flags & proto::kTileFlagZlib) != 0;
  if (meta.uncompressed_size > cache_.slot_bytes() || (!zlib && stored.size() != meta.uncompressed_size))
    return retry_or_give_up(tile, request_id, &MapStats::decode_errors);
  uint32_t slot = kNoSlot;
  bool to_arena = false;
  {
    std::lock_guard lock(mu_);
    RequestRecord* r = sent_record_locked(tile, request_id);
    if (!r) return;
    try {
      sync_lru_locked();            // the lookups' use since the last arrival, then
      slot = cache_.reserve(tile);  // evict the least recently used unpinned tile
      slot_in_view_[slot] = view_count_ && in_other_view_locked(nullptr, tile);
      // A 2D map tile goes in the arena when its slot holds no bytes then (pages an index
      // tile wrote are given back first): each tile's bytes in one place, so the slots'
      // written bytes and the arena's chunks stay within the slots' budget together.
      to_arena = !stack_grid_ && entry.kind == EntryKind::tile && cache_.release_pages(slot);
    } catch (...) {
      ++stats_.cache_full;
      drop_locked(*r);
      return;
    }
    stats_.bytes_received += stored.size();
  }
  // The slot is pinned and unpublished: inflate straight into its place (the arena or the
  // slot) and open it without the lock, so lookups never wait on decompression or validation.
  std::unique_ptr<Evaluator> ev;
  CutGrid grid;
  std::span<const uint8_t> held;  // the tile's bytes in the arena (no data: in its slot)
  const bool ok = fill_slot(slot, meta, entry, stored, to_arena, ev, grid, held);
  {
    std::lock_guard lock(mu_);
    if (!ok) {
      // The slot back (free, page absent), then under the same lock the page requested
      // again or given up, so that no lookup sees it absent in between.
      cache_.abort(slot);
      // The slot's evaluator read the evicted tile's copy: both go.
      arena_.release(slot);
      slot_eval_[slot].reset();
      slot_window_[slot] = nullptr;
      slot_walks_[slot] = nullptr;
      retry_or_give_up_locked(tile, request_id, &MapStats::decode_errors);
    } else {
      slot_eval_[slot] = std::move(ev);
      slot_window_[slot] = dynamic_cast<const WindowDepths*>(slot_eval_[slot].get());
      slot_walks_[slot] = dynamic_cast<const TapWalks*>(slot_eval_[slot].get());
      slot_grid_[slot] = std::move(grid);
      bool committed = false;
      try {
        committed = held.data() ? cache_.commit_held(slot, held)
                                : cache_.commit(slot, meta.uncompressed_size);  // size checked above
      } catch (...) {
      }
      if (!committed) arena_.release(slot);  // the slot went back free: its copy goes too
      if (RequestRecord* r = sent_record_locked(tile, request_id)) requests_.erase(*r);
      if (committed) {
        ++stats_.tiles_received;
        if (entry.kind == EntryKind::index) rerequest_regions_locked();
      }
    }
  }
}

bool RemoteMap::tile_refused(uint64_t tile, uint32_t request_id, proto::ErrorCode code) noexcept {
  if (is_deep_id(tile)) {
    if (deep_) deep_->tile_refused(tile, request_id, code);
    return true;
  }
  std::lock_guard lock(mu_);
  RequestRecord* r = sent_record_locked(tile, request_id);
  if (!r) return false;
  if (code == proto::ErrorCode::cancelled) {
    ++stats_.tiles_cancelled;
    drop_locked(*r);
  } else {
    give_up_locked(*r);
  }
  return true;
}

void RemoteMap::connection_lost() noexcept {
  if (deep_) deep_->connection_lost();
  std::lock_guard lock(mu_);
  requests_.for_each([&](RequestRecord& r) {
    if (r.state == RequestState::queued) return;
    // Cancelled ones are no longer wanted; the rest go back in the queue at their
    // priority, unless it is full (a later want asks again).
    if (r.state == RequestState::cancel_sent || !requests_.requeue(r)) drop_locked(r);
  });
  cancels_.clear();
  if (requests_.queued() > 0) notifier_->notify();
}

}  // namespace st::client

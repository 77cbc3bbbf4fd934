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
#include "tiles/core/filter_level.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/tap_order.hpp"

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

// ---------------------------------------------------------------- lookups

bool RemoteMap::want_locked(uint64_t tile, const GridEntry& e, uint16_t priority) const noexcept {
  const PageState state = cache_.lookup(tile).state;
  if (state == PageState::absent) {
    if (failed_ >= kMaxFailedTiles) return false;  // the server refused too much: ask no more
    RequestRecord* r = requests_.insert(tile, e, priority);
    if (!r) {
      ++stats_.queue_full;
      return false;
    }
    try {
      cache_.request(tile);  // the page table was sized up front: no allocation
    } catch (...) {          // only a page table that had to grow and could not
      requests_.erase(*r);
      return false;
    }
  } else if (state == PageState::requested) {
    RequestRecord* r = requests_.find(tile);
    if (!r || !requests_.raise(*r, priority)) return false;  // sent, or not higher
  } else {
    return false;
  }
  notifier_->notify();
  return true;
}

size_t RemoteMap::want_tiles(std::span<const WantedTile> tiles) const noexcept {
  size_t queued = 0;
  std::lock_guard lock(mu_);
  for (const WantedTile& w : tiles) {
    if (stack_grid_) {  // a stack map's tiles are its cells' (remote_stack.cpp)
      uint64_t cell = 0;
      if (!stack_grid_->cell_of(w.tile, cell) || stack_grid_->entries[cell].kind != 1) continue;
      queued += want_locked(w.tile, GridEntry{stack_grid_->entries[cell].value, EntryKind::tile, 0}, w.priority);
      continue;
    }
    if (!is_valid_tile_id(w.tile) || w.entry.kind == EntryKind::constant) continue;
    const uint32_t level = uint32_t(w.tile >> kTileIdLevelShift);
    if (level < grid_.levels || level >= header_.map_level) continue;
    queued += want_locked(w.tile, w.entry, w.priority);
  }
  return queued;
}

namespace {
size_t counter_shard() noexcept {
  static std::atomic<unsigned> next{0};
  thread_local const unsigned shard = next.fetch_add(1, std::memory_order_relaxed);
  return shard;
}
}  // namespace

namespace {
// How many of depth[0, n) the receiver lies at or in front of (receiver <= depth), four
// at a time with SSE2 (the same IEEE comparison as the scalar test, NaN never lit).
[[gnu::always_inline]] inline uint32_t count_lit(const float* depth, uint32_t n, float receiver) {
  uint32_t k = 0, lit = 0;
#if defined(__SSE2__)
  const __m128 rv = _mm_set1_ps(receiver);
  __m128i acc = _mm_setzero_si128();  // each lane counts down by one per lit tap (the mask is -1)
  for (; k + 4 <= n; k += 4) acc = _mm_sub_epi32(acc, _mm_castps_si128(_mm_cmple_ps(rv, _mm_loadu_ps(depth + k))));
  alignas(16) uint32_t lanes[4];
  _mm_store_si128(reinterpret_cast<__m128i*>(lanes), acc);
  lit = lanes[0] + lanes[1] + lanes[2] + lanes[3];
#endif
  for (; k < n; ++k) lit += receiver <= depth[k] ? 1u : 0u;
  return lit;
}
}  // namespace

// The page-table walk of PackEvaluator::depth, over the cache: where a tile is missing,
// the entry's own value answers (the node's value stands for all its descendants).
bool RemoteMap::enter_tile(uint32_t level, uint64_t x, uint64_t y, LookupScratch& sc, float& value) const noexcept {
  PageEntry page;  // the cache's answer for the last tile the walk asked about
  auto resident_index = [&](uint64_t id, const GridEntry&) -> const CutGrid* {
    page = cache_.lookup(id);
    if (page.state != PageState::resident) return nullptr;
    mark_used(page.slot);
    return &slot_grid_[page.slot];
  };
  const PageHit hit = walk_page_table(grid_, level, x, y, resident_index);
  value = hit.value;
  if (hit.kind == PageHit::Kind::value) {
    sc.set_region(level, x, y, hit.region_shift, value, LookupScratch::Counted::none);
    return false;
  }
  if (hit.kind == PageHit::Kind::tile) page = cache_.lookup(hit.tile);
  if (page.state == PageState::constant) {  // given up: coarse for good
    value = page.value;
    sc.set_region(level, x, y, hit.region_shift, value, LookupScratch::Counted::none);
    return false;
  }
  if (page.state != PageState::resident && level <= grid_.levels + preview_.levels()) {
    // The map preview holds this level's answer exactly (map_preview.hpp): no miss.
    value = preview_.coarse_answer(grid_.levels, hit, level, x, y);
    sc.set_region(level, x, y, preview_.coarse_region_shift(grid_.levels, hit, level), value,
                  LookupScratch::Counted::none);
    return false;
  }
  if (page.state != PageState::resident) {
    value = preview_.coarse_answer(grid_.levels, hit, level, x, y);  // the map preview's finer node
    // That answer holds for the whole preview node (or the entry's node) while the tile is away.
    sc.set_region(level, x, y, preview_.coarse_region_shift(grid_.levels, hit, level), value,
                  LookupScratch::Counted::coarse);
    ++sc.missed;
    ++sc.coarse;
    bool noted = false;
    for (size_t i = 0; i < sc.misses && !noted; ++i) noted = sc.miss_tile[i] == hit.tile;
    if (!noted && sc.misses < LookupScratch::kMaxMisses) {
      sc.miss_tile[sc.misses] = hit.tile;
      sc.miss_entry[sc.misses++] = hit.entry;
    }
    return false;
  }
  mark_used(page.slot);
  sc.ev = slot_eval_[page.slot].get();
  sc.win = slot_window_[page.slot];
  sc.walks = slot_walks_[page.slot];
  if (sc.win) sc.win->prefetch();  // the tile's walks follow (WindowDepths::prefetch)
  sc.level = level;
  sc.rel = hit.rel;
  sc.x0 = x - hit.tx;
  sc.y0 = y - hit.ty;
  sc.side = uint64_t(1) << hit.rel;
  return true;
}

void RemoteMap::prefetch_tile(uint32_t level, uint64_t x, uint64_t y) const noexcept {
  if (!texel_in_map(header_.map_level, level, x, y)) return;
  const PageHit hit = walk_page_table(grid_, level, x, y, [&](uint64_t id, const GridEntry&) -> const CutGrid* {
    const PageEntry page = cache_.lookup(id);
    return page.state == PageState::resident ? &slot_grid_[page.slot] : nullptr;
  });
  if (hit.kind != PageHit::Kind::tile) return;
  const PageEntry page = cache_.lookup(hit.tile);
  if (page.state != PageState::resident) return;
  if (const WindowDepths* w = slot_window_[page.slot]) w->prefetch();
}

float RemoteMap::depth_shared(uint32_t level, uint64_t x, uint64_t y, LookupScratch& sc) const noexcept {
  // A region lies in the map, so this test comes first.
  if (const LookupScratch::Region* g = sc.find(level, x, y)) return sc.answer(*g);
  if (!texel_in_map(header_.map_level, level, x, y)) return kLitDepth;  // page_table.hpp's rule
  if (!sc.covers(level, x, y)) {
    float value;
    if (!enter_tile(level, x, y, sc, value)) return value;
  }
  ++sc.hits;
  try {
    const DepthRegion r = sc.ev->depth_region(sc.rel, x - sc.x0, y - sc.y0);
    // The tile is aligned to its side (>= the region's), so the region holds in map texels.
    sc.set_region(level, x, y, r.shift, r.value, LookupScratch::Counted::hit);
    return r.value;
  } catch (...) {  // an opened tile does not throw; if one did, stay lit and alive
    return kLitDepth;
  }
}

bool RemoteMap::extend_ahead(uint32_t level, uint64_t kx0, uint32_t r, LookupScratch& sc) const noexcept {
  LookupScratch::Ahead& a = sc.ahead[level & 1];
  const uint32_t keep = uint32_t(a.n - (kx0 - a.x0));  // the columns it shares with the kept ones (< r)
  std::memmove(a.depth, a.depth + (kx0 - a.x0) * r, size_t(keep) * r * sizeof(float));
  a.x0 = kx0, a.n = keep;
  while (a.n < r) {
    const uint32_t got = fill_columns(level, kx0 + a.n, a.y0, a.y0 + r - 1, sc, a.depth + size_t(a.n) * r);
    if (got == 0) {
      a.n = 0;  // a tile with no window walk: pcf_general's paths
      return false;
    }
    a.n += got;
  }
  return true;
}

float RemoteMap::pcf_shared(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver,
                            LookupScratch& sc) const noexcept {
  // A kernel with no tap clamped on the rows of the columns kept ahead, overlapping them
  // or right after them (the next kernel along a screen-coherent row): its r columns are
  // r * r consecutive depths there, counted in one pass; the columns it lacks are read
  // kAhead at a time, one window walk per tile or kept region they lie in
  // (extend_ahead, fill_columns). Every depth is depth()'s, so the count is exact.
  if (r >= 2 && r <= kMaxPcf && level <= header_.map_level) {
    const uint64_t h = (r - 1) / 2;
    LookupScratch::Ahead& a = sc.ahead[level & 1];
    if (a.n && a.level == level && a.r == r && y >= h && y - h == a.y0 && x >= h &&
        x - h + r <= (uint64_t(1) << level)) {
      const uint64_t at = x - h - a.x0;  // unsigned: a kernel left of the kept columns wraps
      if (at <= a.n && (a.n - at >= r || extend_ahead(level, x - h, r, sc)))
        return pcf_fraction(count_lit(a.depth + (x - h - a.x0) * r, r * r, receiver), r);
    }
  }
  return pcf_general(level, x, y, r, receiver, sc);
}

float RemoteMap::pcf_general(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver,
                             LookupScratch& sc) const noexcept {
  r = std::clamp<uint32_t>(r, 1, kMaxPcf);
  if (level > header_.map_level) return 1.0f;
  const uint64_t side = uint64_t(1) << level;
  if (r == 1) return receiver <= depth_shared(level, pcf_tap(x, 0, 1, side), pcf_tap(y, 0, 1, side), sc) ? 1.0f : 0.0f;
  // A kernel inside one region: every tap gets its value, so the fraction is exactly 1
  // or 0 (a region is an aligned square: its corners decide). Failing that, the centre
  // tap's region (one walk) often holds the next kernels along a row.
  const uint64_t kx0 = pcf_tap(x, 0, r, side), kx1 = pcf_tap(x, r - 1, r, side);
  const uint64_t ky0 = pcf_tap(y, 0, r, side), ky1 = pcf_tap(y, r - 1, r, side);
  LookupScratch::Taps& w = sc.taps[level & 1];
  const bool same_rows = w.r == r && w.level == level && w.y == y;
  const bool interior = kx1 - kx0 == r - 1, w_rows = ky1 - ky0 == r - 1;  // r consecutive columns, rows
  // The column tx (inside the kernel's rows ky0..ky1, consecutive) into `col` without a
  // per-tap walk: from the columns fetched ahead, one kept region holding it, (inside the
  // current tile) a window walk of it and the next columns up to kAhead, whose region is
  // kept when one node holds them, or (a column across a tile border, or outside the
  // current tile) fill_columns's window walk per tile. False: none of these (a
  // tile with no window walk; the caller reads it tap by tap).
  auto read_column = [&](uint64_t tx, float* col) {
    LookupScratch::Ahead& a = sc.ahead[level & 1];
    if (a.n && a.level == level && a.r == r && a.y0 == ky0 && tx - a.x0 < a.n) {
      std::copy_n(a.depth + (tx - a.x0) * r, r, col);
      return true;
    }
    if (const LookupScratch::Region* g = sc.find(level, tx, ky0); g && g->holds(level, tx, ky1)) {
      std::fill_n(col, r, sc.answer(*g));
      return true;
    }
    if (!sc.win || !sc.covers(level, tx, ky0) || !sc.covers(level, tx, ky1)) {
      a.n = 0;  // rewritten below
      const uint32_t n = fill_columns(level, tx, ky0, ky1, sc, a.depth);
      if (n == 0) return false;
      a.level = level, a.r = r, a.n = n, a.x0 = tx, a.y0 = ky0;
      std::copy_n(a.depth, r, col);
      return true;
    }
    ++sc.hits;
    const uint32_t n = uint32_t(std::min<uint64_t>(LookupScratch::kAhead, sc.x0 + sc.side - tx));
    const uint32_t shift = sc.win->depth_window(sc.rel, tx - sc.x0, ky0 - sc.y0, n, r, a.depth);
    a.level = level, a.r = r, a.n = n, a.x0 = tx, a.y0 = ky0;
    std::copy_n(a.depth, r, col);
    if ((((tx ^ (tx + n - 1)) | (ky0 ^ ky1)) >> shift) == 0)
      sc.set_region(level, tx, ky0, shift, col[0], LookupScratch::Counted::hit);
    return true;
  };
  // Sliding right along a row by one texel, away from the map's edges: the window holds
  // this kernel's first r - 1 columns (column tx in slot tx % r); read its last, count.
  if (same_rows && w.slide == x && interior && w_rows) {
    const uint32_t slot = w.slide_slot;  // kx1 % r without a division
    if (read_column(kx1, w.depth.data() + slot * r)) {
      w.col[slot] = kx1;
      w.slide = x + 1;
      w.slide_slot = slot + 1 == r ? 0 : slot + 1;
      return pcf_fraction(count_lit(w.depth.data(), r * r, receiver), r);
    }
  }
  w.slide = ~uint64_t(0);  // set again below where the window ends up holding the kernel
  // Whether the kernel around (x, y) (in the map) lies inside sc's current tile, or leaves
  // it only across the map's edges (where the tile's clamp is the map's).
  auto kernel_in_tile = [&] {
    if (!sc.covers(level, x, y)) return false;
    const int64_t h = int64_t((r - 1) / 2), lo_x = int64_t(x) - h, lo_y = int64_t(y) - h;
    const int64_t tx0 = int64_t(sc.x0), ty0 = int64_t(sc.y0), ts = int64_t(sc.side), s = int64_t(side);
    const bool fits_x = (lo_x >= tx0 || tx0 == 0) && (lo_x + int64_t(r) <= tx0 + ts || tx0 + ts == s);
    const bool fits_y = (lo_y >= ty0 || ty0 == 0) && (lo_y + int64_t(r) <= ty0 + ts || ty0 + ts == s);
    return fits_x && fits_y;
  };
  // A window on this kernel's rows and every tap `value` (a kernel inside one region).
  auto keep_uniform = [&](float value) {
    w.level = level, w.r = r, w.y = y;
    std::fill_n(w.col.begin(), r, ~uint64_t(0));
    uint32_t slot = uint32_t(kx0 % r);  // column tx in slot tx % r, as below
    for (uint32_t i = 0; i < r; ++i) {
      const uint64_t tx = pcf_tap(x, i, r, side);
      w.col[slot] = tx;
      if (i + 1 < r && pcf_tap(x, i + 1, r, side) != tx) slot = slot + 1 == r ? 0 : slot + 1;
    }
    std::fill_n(w.depth.begin(), r * r, value);
    if (interior && w_rows) w.slide = x + 1, w.slide_slot = uint32_t((kx1 + 1) % r);
  };
  for (int attempt = 0; attempt < 2; ++attempt) {
    const LookupScratch::Region* g = sc.find(level, kx0, ky0);
    if (g && g->holds(level, kx1, ky1)) {
      const float value = sc.answer(*g);
      keep_uniform(value);
      return receiver <= value ? 1.0f : 0.0f;
    }
    if (attempt == 1) break;
    if (same_rows) {
      // Along a row of kernels: column tx lives in slot tx % r (a kernel's r columns are
      // consecutive, or repeat at a clamped edge, so they never share a slot), the
      // columns the last kernels had are kept there, the new ones read tap by tap (each
      // through the kept regions, so a column inside one region costs one walk at most).
      // Every tap's depth is depth()'s, so the count is exact.
      uint32_t lit_taps = 0;
      uint32_t slot = uint32_t(kx0 % r);
      uint64_t prev = kx0;
      // Away from the map's left and right edges the kernel's r columns fill all r slots:
      // its taps are the whole window, counted in one branch-free pass.
      for (uint32_t i = 0; i < r; ++i) {
        const uint64_t tx = pcf_tap(x, i, r, side);
        if (tx != prev) slot = slot + 1 == r ? 0 : slot + 1, prev = tx;
        float* col = w.depth.data() + slot * r;
        if (w.col[slot] != tx) {
          w.col[slot] = tx;
          // On r consecutive rows: from the columns fetched ahead, or one kept region
          // holding it gives all its taps; else it and the next columns up to kAhead in
          // one window walk per tile they lie in (shared down to their lowest common
          // node, each node once; read_column).
          // Else tap by tap, the column's taps that one region holds taking its value together.
          for (uint32_t k = w_rows && read_column(tx, col) ? r : 0; k < r;) {
            const uint64_t ty = pcf_tap(y, k, r, side);
            const float v = depth_shared(level, tx, ty, sc);
            col[k++] = v;
            const LookupScratch::Region* g = sc.last_region();
            if (g && g->holds(level, tx, ty))
              while (k < r && g->holds(level, tx, pcf_tap(y, k, r, side))) col[k++] = v;
          }
        }
        if (!interior)
          for (uint32_t k = 0; k < r; ++k) lit_taps += receiver <= col[k] ? 1u : 0u;
      }
      if (interior) {
        lit_taps = count_lit(w.depth.data(), r * r, receiver);
        if (w_rows) w.slide = x + 1, w.slide_slot = uint32_t((kx1 + 1) % r);
      }
      return pcf_fraction(lit_taps, r);
    }
    // Not on the last kernels' rows: enter the centre's tile (no walk); a kernel inside it
    // goes straight to the tile's own shared-walk pcf (MH §3.3 Fig. 5, DAG-MH §3.5), which
    // stops early where one node holds the kernel. Else the centre's region (one walk)
    // and the corners again.
    if (x < side && y < side) {
      float value;
      if (!sc.covers(level, x, y) && !enter_tile(level, x, y, sc, value)) continue;  // its region is kept
      if (kernel_in_tile()) {
        ++sc.hits;
        w.level = level, w.r = r, w.y = y;
        std::fill_n(w.col.begin(), r, ~uint64_t(0));
        try {
          return sc.ev->pcf(sc.rel, x - sc.x0, y - sc.y0, r, receiver);
        } catch (...) {
          return 1.0f;
        }
      }
    }
    // No tap clamped: one kept region may hold the kernel (attempt 1), else it is counted
    // tile by tile below.
    if (interior && w_rows) continue;
    depth_shared(level, pcf_tap(x, (r - 1) / 2, r, side), pcf_tap(y, (r - 1) / 2, r, side), sc);
  }
  // A new row of kernels: the next kernel on it fills the window (above).
  w.level = level, w.r = r, w.y = y;
  std::fill_n(w.col.begin(), r, ~uint64_t(0));
  // No tap clamped (the kernel is a window of r x r distinct texels): counted one window
  // per tile or kept region it overlaps (a kernel straddling a border or a corner reads
  // one window from each tile, WindowDepths::count_window).
  if (interior && w_rows) return pcf_fraction(count_window_shared(level, kx0, ky0, kx1, ky1, receiver, sc), r);
  // Row by row: the taps of a row that one region holds take its answer together, each
  // region found among the kept ones or by one walk (which keeps it). Every tap answers
  // like depth(), so the fraction equals the base class's exactly.
  uint32_t lit_taps = 0;
  for (uint32_t j = 0; j < r; ++j) {
    const uint64_t ty = pcf_tap(y, j, r, side);
    for (uint32_t i = 0; i < r;) {
      const uint64_t tx = pcf_tap(x, i, r, side);
      const float v = depth_shared(level, tx, ty, sc);
      const LookupScratch::Region* g = sc.last_region();
      uint32_t n = 1;
      if (g && g->holds(level, tx, ty))
        while (i + n < r && g->holds(level, pcf_tap(x, i + n, r, side), ty)) ++n;
      lit_taps += receiver <= v ? n : 0;
      i += n;
    }
  }
  return pcf_fraction(lit_taps, r);
}

uint32_t RemoteMap::fill_columns(uint32_t level, uint64_t tx, uint64_t ky0, uint64_t ky1, LookupScratch& sc,
                                 float* out) const noexcept {
  using Tile = LookupScratch::TileView;
  const uint32_t r = uint32_t(ky1 - ky0 + 1);
  uint32_t n = uint32_t(std::min<uint64_t>(LookupScratch::kAhead, (uint64_t(1) << level) - tx));
  float part[LookupScratch::kAhead * kMaxPcf];
  // Each part of the columns: rows [ty, ey], the columns [tx, tx + n) of one kept region
  // (its value) or of one tile (one window walk); n shrinks to what every part holds.
  for (uint64_t ty = ky0, ey = 0; ty <= ky1; ty = ey + 1) {
    const LookupScratch::Region* g = sc.find(level, tx, ty);
    if (!g && !sc.covers(level, tx, ty)) {
      const Tile before = sc.tile();
      if (sc.alt.covers(level, tx, ty)) {  // the tile it was in before: no page-table walk
        sc.set_tile(sc.alt);
      } else {
        float value;
        if (!enter_tile(level, tx, ty, sc, value)) g = sc.last_region();  // it keeps the answer's region
      }
      if (before.ev) sc.alt = before;
    }
    if (g) {
      const uint64_t m = (uint64_t(1) << g->shift) - 1;
      ey = std::min(ky1, ty | m);
      n = uint32_t(std::min<uint64_t>(n, (tx | m) - tx + 1));
      const float v = sc.answer(*g);
      for (uint32_t c = 0; c < n; ++c) std::fill(out + c * r + (ty - ky0), out + c * r + (ey - ky0) + 1, v);
      continue;
    }
    if (!sc.win) return 0;
    ey = std::min(ky1, sc.y0 + sc.side - 1);
    n = uint32_t(std::min<uint64_t>(n, sc.x0 + sc.side - tx));
    const uint32_t h = uint32_t(ey - ty + 1);
    ++sc.hits;
    // Straight into `out` when the part is the whole column (depth_window's layout).
    float* to = h == r ? out : part;
    const uint32_t shift = sc.win->depth_window(sc.rel, tx - sc.x0, ty - sc.y0, n, h, to);
    if (to == part)
      for (uint32_t c = 0; c < n; ++c) std::copy_n(part + c * h, h, out + c * r + (ty - ky0));
    if ((((tx ^ (tx + n - 1)) | (ty ^ ey)) >> shift) == 0)  // one node holds the part: keep its region
      sc.set_region(level, tx, ty, shift, to[0], LookupScratch::Counted::hit);
  }
  return n;
}

uint32_t RemoteMap::count_window_shared(uint32_t level, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by,
                                        float receiver, LookupScratch& sc) const noexcept {
  // The tile or region holding (ax, ay): an aligned square, so the rectangle's part in it
  // is its top-left corner up to (ex, ey); the rest is a part to the right and one below.
  const LookupScratch::Region* g = nullptr;
  if (!sc.covers(level, ax, ay)) {
    g = sc.find(level, ax, ay);
    float value;
    if ((!g || g->counted == LookupScratch::Counted::hit) && enter_tile(level, ax, ay, sc, value)) g = nullptr;
    else if (!g) g = sc.last_region();  // enter_tile kept the answer's region
  }
  uint64_t ex, ey;
  uint32_t lit;
  if (g) {
    const uint64_t s = (uint64_t(1) << g->shift) - 1;
    ex = std::min(bx, ax | s), ey = std::min(by, ay | s);
    const uint32_t area = uint32_t((ex - ax + 1) * (ey - ay + 1));
    lit = receiver <= g->value ? area : 0;
    // Counted like `area` answers of the region (depth_shared's per-tap answers).
    if (g->counted == LookupScratch::Counted::hit) sc.hits += area;
    else if (g->counted == LookupScratch::Counted::coarse) sc.missed += area, sc.coarse += area;
  } else {
    ex = std::min(bx, sc.x0 + sc.side - 1), ey = std::min(by, sc.y0 + sc.side - 1);
    const uint32_t w = uint32_t(ex - ax + 1), h = uint32_t(ey - ay + 1);
    ++sc.hits;
    try {
      if (sc.win) {
        lit = sc.win->count_window(sc.rel, ax - sc.x0, ay - sc.y0, w, h, receiver);
      } else {
        lit = 0;
        for (uint64_t tx = ax; tx <= ex; ++tx)
          for (uint64_t ty = ay; ty <= ey; ++ty) lit += receiver <= sc.ev->depth(sc.rel, tx - sc.x0, ty - sc.y0) ? 1u : 0u;
      }
    } catch (...) {  // an opened tile does not throw; if one did, stay lit and alive
      lit = receiver <= kLitDepth ? w * h : 0;
    }
  }
  if (ex < bx) lit += count_window_shared(level, ex + 1, ay, bx, ey, receiver, sc);
  if (ey < by) lit += count_window_shared(level, ax, ey + 1, bx, by, receiver, sc);
  return lit;
}

void RemoteMap::finish_lookups(const LookupScratch& sc) const noexcept {
  CounterShard& c = counters_[counter_shard() % kCounterShards];
  if (sc.hits) c.hits.fetch_add(sc.hits, std::memory_order_relaxed);
  if (sc.missed) c.misses.fetch_add(sc.missed, std::memory_order_relaxed);
  if (sc.coarse) c.coarse.fetch_add(sc.coarse, std::memory_order_relaxed);
  if (sc.misses == 0) return;
  std::lock_guard lock(mu_);
  for (size_t i = 0; i < sc.misses; ++i) want_locked(sc.miss_tile[i], sc.miss_entry[i], options_.miss_priority);
}

void RemoteMap::sync_lru_locked() noexcept {
  for (uint32_t s = 0; s < cache_.slot_count(); ++s)
    if (slot_used_[s].load(std::memory_order_relaxed) == epoch_) cache_.touch(s);
  if (view_count_)  // the views' tiles last: the most recently used (remote_views.cpp)
    for (uint32_t s = 0; s < cache_.slot_count(); ++s)
      if (slot_in_view_[s]) cache_.touch(s);
  if (++epoch_ == 0) {  // after 2^32 evictions: start over rather than confuse old stamps
    for (uint32_t s = 0; s < cache_.slot_count(); ++s) slot_used_[s].store(0, std::memory_order_relaxed);
    epoch_ = 1;
  }
}

float RemoteMap::depth(uint32_t level, uint64_t x, uint64_t y) const noexcept {
  LookupScratch sc;
  float d;
  {
    std::shared_lock lock(mu_);
    d = depth_shared(level, x, y, sc);
  }
  finish_lookups(sc);
  return d;
}

float RemoteMap::pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const noexcept {
  LookupScratch sc;
  float v;
  {
    std::shared_lock lock(mu_);  // one lock for the whole kernel
    v = pcf_shared(level, x, y, r, receiver, sc);
  }
  finish_lookups(sc);
  return v;
}

void RemoteMap::pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const noexcept {
  LookupScratch sc;
  {
    std::shared_lock lock(mu_);
    pcf_batch_shared(queries, out, sc);
  }
  finish_lookups(sc);
}

void RemoteMap::pcf_batch_shared(std::span<const PcfQuery> queries, std::span<float> out,
                                 LookupScratch& sc) const noexcept {
  const size_t n = std::min(queries.size(), out.size());
  const uint32_t map_level = header_.map_level;
  // Single taps, one tight loop (MH 2016 §3.3's last-sample cache, across tiles and
  // page-table entries alike): a tap in the region of the last answer costs one test; one
  // in another kept region a few; the others walk their tile from the last walk's path
  // there (TapWalks, tap_batch.hpp: a screen-coherent batch steps a level or two per
  // tap), the tile found among the last few walked (a screen tile's taps often straddle a
  // tile border) or entered through the page table. Every walk's region is kept.
  constexpr size_t kTiles = 4;
  struct Tile {
    const Evaluator* ev;
    const TapWalks* walks;  // null: depth_region, not resumed
    uint32_t level, rel;
    uint64_t x0, y0, side;
    bool covers(uint32_t l, uint64_t x, uint64_t y) const {
      return l == level && x - x0 < side && y - y0 < side;  // unsigned: x < x0 wraps
    }
  };
  Tile tiles[kTiles];
  TapPath paths[kTiles];  // tiles[k]'s last walk
  size_t used_tiles = 0, cur = 0, next_tile = 0;
  // The last answer's region, in registers (level ~0: none); its answers counted by kind.
  using Counted = LookupScratch::Counted;
  uint32_t g_level = ~0u, g_shift = 0;
  uint64_t g_x = 0, g_y = 0;
  float g_value = 0;
  Counted g_counted = Counted::none;
  // Answers from kept regions by kind, in registers (an array indexed by the kind would
  // be a load and a store through memory per tap).
  uint64_t counted_hit = 0, counted_coarse = 0;
  auto count = [&] {
    counted_hit += g_counted == Counted::hit;
    counted_coarse += g_counted == Counted::coarse;
  };
  auto take = [&](const LookupScratch::Region& g) {
    g_level = g.level, g_shift = g.shift, g_x = g.x, g_y = g.y, g_value = g.value, g_counted = g.counted;
  };
  if (sc.used) take(sc.regions[sc.last]);
  uint64_t walked = 0;  // taps answered by a tile's tree (in runs)
  // Single taps in Morton order of their texels, kTapOrderMax at a time (tap_order.hpp):
  // a tile's taps together, each walk resuming from a neighbour's path. Taps that follow
  // each other in one tile go to it as one run (TapWalks::tap_run): the loop below runs
  // per run, not per tap.
  uint16_t order[kTapOrderMax];
  for (size_t b0 = 0; b0 < n; b0 += kTapOrderMax) {
    const size_t bn = std::min(kTapOrderMax, n - b0);
    const PcfQuery* const base = queries.data() + b0;
    float* const base_out = out.data() + b0;
    if (!(bn >= kTapOrderMin && tap_order(std::span(base, bn), map_level, order)))
      for (size_t k = 0; k < bn; ++k) order[k] = uint16_t(k);
    for (size_t k = 0; k < bn;) {
      const size_t i = order[k];
      const PcfQuery& q = base[i];
      if (q.r > 1 || q.level > map_level) {
        base_out[i] = pcf_shared(q.level, q.x, q.y, q.r, q.receiver, sc);
        if (sc.used) take(sc.regions[sc.last]);
        ++k;
        continue;
      }
      const uint64_t top = (uint64_t(1) << q.level) - 1;  // pcf_tap's clamp of one tap
      const uint64_t x = std::min(q.x, top), y = std::min(q.y, top);
      if (q.level == g_level && (((x ^ g_x) | (y ^ g_y)) >> g_shift) == 0) {
        count();
        base_out[i] = tap_lit(q.receiver, g_value);
        ++k;
        continue;
      }
      if (const LookupScratch::Region* g = sc.find_other(q.level, x, y)) {  // another kept region
        take(*g);
        count();
        base_out[i] = tap_lit(q.receiver, g_value);
        ++k;
        continue;
      }
      size_t t = cur;
      if (!(used_tiles && tiles[t].covers(q.level, x, y))) {
        t = 0;
        while (t < used_tiles && !tiles[t].covers(q.level, x, y)) ++t;
        if (t == used_tiles) {
          float value;
          if (!enter_tile(q.level, x, y, sc, value)) {  // a page-table value: its region is kept
            take(sc.regions[sc.last]);
            base_out[i] = tap_lit(q.receiver, value);
            ++k;
            continue;
          }
          t = used_tiles < kTiles ? used_tiles++ : next_tile;
          next_tile = (t + 1) % kTiles;
          tiles[t] = Tile{sc.ev, sc.walks, sc.level, sc.rel, sc.x0, sc.y0, sc.side};
          paths[t].owner = nullptr;  // a new tile: its path starts empty
        }
        cur = t;
      }
      const Tile& tl = tiles[t];
      // The run: this tap and the single taps after it in the same tile.
      size_t e = k + 1;
      for (; e < bn; ++e) {
        const PcfQuery& nq = base[order[e]];
        if (nq.r > 1 || !tl.covers(nq.level, std::min(nq.x, top), std::min(nq.y, top))) break;
      }
      // The next run's tile, asked for now so that its bytes arrive while this run walks.
      if (e < bn) {
        const PcfQuery& nq = base[order[e]];
        if (nq.r <= 1 && nq.level <= map_level) {
          const uint64_t ntop = (uint64_t(1) << nq.level) - 1;
          prefetch_tile(nq.level, std::min(nq.x, ntop), std::min(nq.y, ntop));
        }
      }
      TapRunEnd end;
      if (tl.walks) {
        end = tl.walks->tap_run(TapRun{base, order + k, e - k, q.level, tl.rel, tl.x0, tl.y0, base_out}, paths[t]);
      } else {
        end = tap_run_loop(TapRun{base, order + k, e - k, q.level, tl.rel, tl.x0, tl.y0, base_out},
                           [&](uint32_t l, uint64_t tx, uint64_t ty) {
                             try {
                               return tl.ev->depth_region(l, tx, ty);
                             } catch (...) {  // an opened tile does not throw; if one did, stay lit and alive
                               return DepthRegion{kLitDepth, 0};
                             }
                           });
      }
      walked += e - k;
      k = e;
      // The last walk's region (the tile is aligned to its side, >= the region's, so it
      // holds in map texels).
      const uint64_t ex = end.x + tl.x0, ey = end.y + tl.y0;
      sc.set_region(q.level, ex, ey, end.region.shift, end.region.value, Counted::hit);
      g_level = q.level, g_shift = end.region.shift, g_x = ex, g_y = ey, g_value = end.region.value;
      g_counted = Counted::hit;
    }
  }
  sc.hits += walked + counted_hit;
  sc.missed += counted_coarse;
  sc.coarse += counted_coarse;
}

namespace {

// The texel of (u, v) in [0, 1)^2 at `level`: LightSpace::texel_of's answer (u * 2^level
// is exact and below 2^level, and truncating a non-negative double is its floor) without
// its two library floor calls and ldexp.
std::array<uint64_t, 2> texel_in_unit(uint32_t level, double u, double v) {
  const double r = double(uint64_t(1) << level);
  return {uint64_t(u * r), uint64_t(v * r)};
}

// LightSpace::to_light of an orthographic sun for a chunk of points, operation for operation (so the
// same IEEE doubles), as loops over arrays that the compiler vectorizes: a batch pays for
// its divisions two at a time.
constexpr size_t kTransformChunk = 64;
void sun_to_light_chunk(const LightSpace& light, const WorldPoint* w, size_t n, double* u, double* v, double* d) {
  const Vec3d o = light.origin(), au = light.axis_u(), av = light.axis_v(), f = light.forward();
  const double e = light.extent_uv(), near = light.near_plane(), depth = light.far_plane() - light.near_plane();
  for (size_t i = 0; i < n; ++i) {
    const double rx = w[i].x - o.x, ry = w[i].y - o.y, rz = w[i].z - o.z;
    u[i] = (rx * au.x + ry * au.y + rz * au.z) / e;
    v[i] = (rx * av.x + ry * av.y + rz * av.z) / e;
    d[i] = ((rx * f.x + ry * f.y + rz * f.z) - near) / depth;
  }
}

}  // namespace

namespace {
// The light's box in light space: a point outside it is lit (every lookup path's rule).
inline bool inside_light_box(const LightPoint& p) noexcept {
  return p.u >= 0 && p.u < 1 && p.v >= 0 && p.v < 1 && p.d >= 0 && p.d <= 1;
}
// The side of a PCF kernel of radius pcf_radius, capped at Evaluator::kMaxPcf.
inline uint32_t kernel_side(uint32_t pcf_radius) noexcept {
  return 2 * std::min<uint32_t>(pcf_radius, (Evaluator::kMaxPcf - 1) / 2) + 1;
}
}  // namespace

float RemoteMap::visibility_shared(const WorldPoint& world, float footprint_world, uint32_t pcf_radius,
                                   LookupScratch& sc) const noexcept {
  const Vec3d w{world.x, world.y, world.z};
  return visibility_at(light_.to_light(w), w, footprint_world, pcf_radius, sc);
}

float RemoteMap::visibility_at(const LightPoint& p, const Vec3d& w, float footprint_world, uint32_t pcf_radius,
                               LookupScratch& sc) const noexcept {
  if (!inside_light_box(p)) return 1.0f;
  const uint32_t L = header_.map_level;
  const uint32_t r = kernel_side(pcf_radius);
  const float receiver = float(p.d);
  FilterLevels f{L, L, 0.0f};
  if (footprint_world > 0) {
    // One finest-level texel's side in world units at this point (a spot's grows with
    // the distance from the eye).
    const double texel = light_.texel_size(w, L);
    f = filter_levels(L, float(double(footprint_world) / texel));
  }
  const auto tf = texel_in_unit(f.fine, p.u, p.v);
  const float a = pcf_shared(f.fine, tf[0], tf[1], r, receiver, sc);
  if (f.t == 0.0f) return a;
  const auto tc = texel_in_unit(f.coarse, p.u, p.v);
  return filter_blend(a, pcf_shared(f.coarse, tc[0], tc[1], r, receiver, sc), f.t);
}

float RemoteMap::visibility(const Vec3d& world, uint32_t pcf_radius) const noexcept {
  LookupScratch sc;
  float v;
  {
    std::shared_lock lock(mu_);
    v = visibility_shared(WorldPoint{world.x, world.y, world.z}, 0.0f, pcf_radius, sc);
  }
  finish_lookups(sc);
  return v;
}

void RemoteMap::visibility_batch(std::span<const WorldPoint> points, std::span<const float> footprints,
                                 std::span<float> out, uint32_t pcf_radius) const noexcept {
  size_t n = std::min(points.size(), out.size());
  if (!footprints.empty()) n = std::min(n, footprints.size());
  LookupScratch sc;
  const bool sun = light_.kind() == LightKind::sun;
  double u[kTransformChunk], v[kTransformChunk], d[kTransformChunk];
  // Points [i0, i0 + m) (m <= kTransformChunk) in light space: those outside the light's
  // box are answered lit, fn(i, p) is called for the others (visibility_at's first rule).
  auto for_each_in_box = [&](size_t i0, size_t m, auto&& fn) {
    if (sun) sun_to_light_chunk(light_, points.data() + i0, m, u, v, d);
    for (size_t k = 0, i = i0; k < m; ++k, ++i) {
      const LightPoint p =
          sun ? LightPoint{u[k], v[k], d[k]} : light_.to_light(Vec3d{points[i].x, points[i].y, points[i].z});
      if (inside_light_box(p)) fn(i, p);
      else out[i] = 1.0f;
    }
  };
  if (footprints.empty() && pcf_radius == 0) {
    // Single taps at the finest level: visibility_at's answer (one tap of the finest
    // level), with the taps answered by pcf_batch_shared, so a coherent batch walks each
    // tile's taps in one run.
    const uint32_t L = header_.map_level;
    constexpr size_t kQueries = 4 * kTransformChunk;
    PcfQuery queries[kQueries];
    uint32_t at[kQueries];
    float got[kQueries];
    std::shared_lock lock(mu_);
    for (size_t i0 = 0; i0 < n; i0 += kQueries) {
      const size_t m = std::min(kQueries, n - i0);
      size_t nq = 0;
      for (size_t c0 = 0; c0 < m; c0 += kTransformChunk)
        for_each_in_box(i0 + c0, std::min(kTransformChunk, m - c0), [&](size_t i, const LightPoint& p) {
          const auto t = texel_in_unit(L, p.u, p.v);
          queries[nq] = PcfQuery{t[0], t[1], L, 1, float(p.d)};
          at[nq++] = uint32_t(i - i0);
        });
      pcf_batch_shared(std::span<const PcfQuery>(queries, nq), std::span<float>(got, nq), sc);
      for (size_t q = 0; q < nq; ++q) out[i0 + at[q]] = got[q];
    }
  } else if (footprints.empty()) {
    // r x r kernels at the finest level: visibility_at's answer without a footprint
    // (pcf_shared of the finest level) in one loop.
    const uint32_t L = header_.map_level;
    const uint32_t r = kernel_side(pcf_radius);
    std::shared_lock lock(mu_);
    for (size_t i0 = 0; i0 < n; i0 += kTransformChunk)
      for_each_in_box(i0, std::min(kTransformChunk, n - i0), [&](size_t i, const LightPoint& p) {
        const auto t = texel_in_unit(L, p.u, p.v);
        out[i] = pcf_shared(L, t[0], t[1], r, float(p.d), sc);
      });
  } else {
    std::shared_lock lock(mu_);
    for (size_t i0 = 0; i0 < n; i0 += kTransformChunk)
      for_each_in_box(i0, std::min(kTransformChunk, n - i0), [&](size_t i, const LightPoint& p) {
        out[i] = visibility_at(p, Vec3d{points[i].x, points[i].y, points[i].z}, footprints[i], pcf_radius, sc);
      });
  }
  finish_lookups(sc);
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
    const Region& r = regions_[i];
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
                          std::span<const uint8_t> stored, std::unique_ptr<Evaluator>& ev, CutGrid& grid) noexcept {
  try {
    const std::string what = "map '" + name_ + "': " + describe_tile(meta.tile_id);
    const std::span<uint8_t> raw = cache_.slot_span(slot).first(meta.uncompressed_size);
    if (meta.flags & proto::kTileFlagZlib) zlib_decompress_into(stored, raw, what);
    else if (!raw.empty()) std::memcpy(raw.data(), stored.data(), raw.size());  // sizes checked by the caller
    const TileAddress a = tile_address(meta.tile_id);
    if (stack_grid_) {  // an MH octree of one stack cell (remote_stack.cpp)
      ev = open_stack_tile(*stack_grid_, meta.tile_id, raw);
      return bool(ev);
    }
    if (entry.kind == EntryKind::tile) {
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
  {
    std::lock_guard lock(mu_);
    RequestRecord* r = sent_record_locked(tile, request_id);
    if (!r) return;
    try {
      sync_lru_locked();            // the lookups' use since the last arrival, then
      slot = cache_.reserve(tile);  // evict the least recently used unpinned tile
      slot_in_view_[slot] = view_count_ && in_other_view_locked(nullptr, tile);
    } catch (...) {
      ++stats_.cache_full;
      drop_locked(*r);
      return;
    }
    stats_.bytes_received += stored.size();
  }
  // The slot is pinned and unpublished: inflate straight into it and open it without the
  // lock, so lookups never wait on decompression or validation.
  std::unique_ptr<Evaluator> ev;
  CutGrid grid;
  const bool ok = fill_slot(slot, meta, entry, stored, ev, grid);
  {
    std::lock_guard lock(mu_);
    if (!ok) {
      // The slot back (free, page absent), then under the same lock the page requested
      // again or given up, so that no lookup sees it absent in between.
      cache_.abort(slot);
      retry_or_give_up_locked(tile, request_id, &MapStats::decode_errors);
    } else {
      slot_eval_[slot] = std::move(ev);
      slot_window_[slot] = dynamic_cast<const WindowDepths*>(slot_eval_[slot].get());
      slot_walks_[slot] = dynamic_cast<const TapWalks*>(slot_eval_[slot].get());
      slot_grid_[slot] = std::move(grid);
      bool committed = false;
      try {
        committed = cache_.commit(slot, meta.uncompressed_size);  // size checked above
      } catch (...) {
      }
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

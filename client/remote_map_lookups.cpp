// RemoteMap's lookups (client/remote_map.hpp): the page-table walk over the cache, depths,
// PCF kernels and their batches, world-space visibility; a missing tile is marked wanted
// and a coarser level answers. The residency side (construction and budget, regions,
// stats, the fetcher's requests and arrivals) is remote_map_residency.cpp.
#include "client/remote_map.hpp"

#include <algorithm>
#include <atomic>
#include <memory>
#include <new>
#include <shared_mutex>

#include "tiles/core/filter_level.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/tap_order.hpp"

namespace st::client {

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
    const uint32_t level = tile_level(w.tile);
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

void RemoteMap::ResidentWalk::fill(uint32_t slot, WalkNote* note) const noexcept {
  if (!note) return;
  note->slot = slot, note->path_count = path_count;
  std::copy_n(path, std::min(path_count, kMemoPath), note->path);
}

RemoteMap::ResidentWalk RemoteMap::walk_resident(uint32_t level, uint64_t x, uint64_t y) const noexcept {
  ResidentWalk w;
  w.hit = walk_page_table(grid_, level, x, y, [&](uint64_t id, const GridEntry&) -> const CutGrid* {
    w.page = cache_.lookup(id);
    if (w.page.state != PageState::resident) return nullptr;
    mark_used(w.page.slot);
    if (w.path_count < kMemoPath) w.path[w.path_count] = w.page.slot;
    ++w.path_count;
    return &slot_grid_[w.page.slot];
  });
  if (w.hit.kind == PageHit::Kind::tile) w.page = cache_.lookup(w.hit.tile);
  return w;
}

// The page-table walk of PackEvaluator::depth, over the cache: where a tile is missing,
// the entry's own value answers (the node's value stands for all its descendants).
bool RemoteMap::enter_tile(uint32_t level, uint64_t x, uint64_t y, LookupScratch& sc, float& value,
                           WalkNote* note) const noexcept {
  const ResidentWalk w = walk_resident(level, x, y);
  const PageHit& hit = w.hit;
  PageEntry page = w.page;
  value = hit.value;
  if (hit.kind == PageHit::Kind::value) {
    sc.set_region(level, x, y, hit.region_shift, value, LookupScratch::Counted::none);
    return false;
  }
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
  w.fill(page.slot, note);
  sc.ev = slot_eval_[page.slot].get();
  sc.win = slot_window_[page.slot];
  sc.walks = slot_walks_[page.slot];
  // The tile's walks follow (WindowDepths::prefetch, TapWalks::prefetch).
  if (sc.win) sc.win->prefetch();
  else if (sc.walks) sc.walks->prefetch();
  sc.level = level;
  sc.rel = hit.rel;
  sc.x0 = x - hit.tx;
  sc.y0 = y - hit.ty;
  sc.side = uint64_t(1) << hit.rel;
  return true;
}

uint64_t RemoteMap::next_serial() noexcept {
  static std::atomic<uint64_t> next{1};  // 0: no map (an empty memo's)
  return next.fetch_add(1, std::memory_order_relaxed);
}

// Direct-mapped by the texel's 64-texel square, kSide x kSide of them (an 8192-texel
// square of the level, wrapped: the tiles a frame's view meets on a real level evict each
// other little; 32 x 32 kept 56% of oa_dm1's walks at 8K^2, 64 x 64 81%, and 128 x 128,
// the whole of that level, made its single taps ~9% cheaper again): 1 MiB per thread that
// asks batches, allocated on its first batch. A stamp marks the entries of the memo's
// current map and residency.
struct RemoteMap::TileMemo {
  static constexpr uint32_t kShift = 6, kSide = 128;
  struct alignas(64) Entry {
    const Evaluator* ev = nullptr;
    const WindowDepths* win = nullptr;
    const TapWalks* walks = nullptr;
    uint64_t x0 = 0, y0 = 0;  // the tile's texels at `level`: [x0, x0 + 2^rel)
    uint32_t stamp = 0, slot = 0;
    uint8_t level = 0, rel = 0, path_count = 0;
    uint32_t path[kMemoPath] = {};  // the index tiles' slots on the walk
  };
  static size_t index(uint64_t x, uint64_t y) noexcept {
    return size_t((y >> kShift) % kSide) * kSide + size_t((x >> kShift) % kSide);
  }
  uint64_t serial = 0, journal = 0;
  uint32_t stamp = 0;  // the entries with this stamp hold
  Entry entries[kSide * kSide];
};

RemoteMap::TileMemo* RemoteMap::tile_memo() const noexcept {
  thread_local std::unique_ptr<TileMemo> memo;
  if (!memo) {
    memo.reset(new (std::nothrow) TileMemo());
    if (!memo) return nullptr;
  }
  TileMemo& m = *memo;
  const uint64_t journal = cache_.journal_end();
  if (m.serial != serial_ || m.journal != journal) {
    m.serial = serial_, m.journal = journal;
    if (++m.stamp == 0) {  // after 2^32 changes: start over rather than trust old stamps
      for (TileMemo::Entry& e : m.entries) e.stamp = 0;
      m.stamp = 1;
    }
  }
  return &m;
}

bool RemoteMap::memo_tile(TileMemo& m, uint32_t level, uint64_t x, uint64_t y,
                          LookupScratch::TileView& tile) const noexcept {
  const TileMemo::Entry& e = m.entries[TileMemo::index(x, y)];
  const uint64_t side = uint64_t(1) << e.rel;
  if (e.stamp != m.stamp || e.level != level || x - e.x0 >= side || y - e.y0 >= side) return false;
  mark_used(e.slot);  // as the walk marks them: the index tiles on its way, the tile
  for (uint32_t i = 0; i < e.path_count; ++i) mark_used(e.path[i]);
  if (e.win) e.win->prefetch();
  else if (e.walks) e.walks->prefetch();
  tile = {e.ev, e.win, e.walks, level, e.rel, e.x0, e.y0, side};
  return true;
}

void RemoteMap::memo_keep(TileMemo& m, uint64_t x, uint64_t y, const LookupScratch::TileView& tile,
                          const WalkNote& note) noexcept {
  if (note.path_count > kMemoPath || tile.level > 255 || tile.rel > 63) return;  // not kept: walked each time
  TileMemo::Entry& e = m.entries[TileMemo::index(x, y)];
  e.ev = tile.ev, e.win = tile.win, e.walks = tile.walks;
  e.x0 = tile.x0, e.y0 = tile.y0;
  e.stamp = m.stamp, e.slot = note.slot;
  e.level = uint8_t(tile.level), e.rel = uint8_t(tile.rel), e.path_count = uint8_t(note.path_count);
  std::copy_n(note.path, note.path_count, e.path);
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
  if (interior && w_rows)
    return pcf_fraction(count_window_shared(level, kx0, ky0, kx1, ky1, FlatTaps{receiver}, sc), r);
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

namespace remote_map_lookups {

// One part inside one tile, through the tile's window walk (x0, y0: the tile's first
// texel; rel: the level in its tree).
uint32_t count_in_window(const WindowDepths& win, uint32_t rel, uint64_t x, uint64_t y, uint32_t w, uint32_t h,
                         uint64_t, uint64_t, const FlatTaps& taps) {
  return win.count_window(rel, x, y, w, h, taps.receiver);
}
uint32_t count_in_window(const WindowDepths& win, uint32_t rel, uint64_t x, uint64_t y, uint32_t w, uint32_t h,
                         uint64_t x0, uint64_t y0, const PlaneTaps& taps) {
  return win.count_window_plane(rel, x, y, w, h, plane_in_tree(taps.p, taps.level, rel, x0, y0));
}

}  // namespace remote_map_lookups

template <class Taps>
uint32_t RemoteMap::count_window_shared(uint32_t level, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by,
                                        const Taps& taps, LookupScratch& sc) const noexcept {
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
    lit = taps.count(g->value, ax, ay, ex, ey);
    // Counted like `area` answers of the region (depth_shared's per-tap answers).
    if (g->counted == LookupScratch::Counted::hit) sc.hits += area;
    else if (g->counted == LookupScratch::Counted::coarse) sc.missed += area, sc.coarse += area;
  } else {
    ex = std::min(bx, sc.x0 + sc.side - 1), ey = std::min(by, sc.y0 + sc.side - 1);
    const uint32_t w = uint32_t(ex - ax + 1), h = uint32_t(ey - ay + 1);
    ++sc.hits;
    try {
      if (sc.win) {
        lit = remote_map_lookups::count_in_window(*sc.win, sc.rel, ax - sc.x0, ay - sc.y0, w, h, sc.x0, sc.y0, taps);
      } else {
        lit = 0;
        for (uint64_t tx = ax; tx <= ex; ++tx)
          for (uint64_t ty = ay; ty <= ey; ++ty)
            lit += taps.lit(sc.ev->depth(sc.rel, tx - sc.x0, ty - sc.y0), tx, ty) ? 1u : 0u;
      }
    } catch (...) {  // an opened tile does not throw; if one did, stay lit and alive
      lit = taps.count(kLitDepth, ax, ay, ex, ey);
    }
  }
  if (ex < bx) lit += count_window_shared(level, ex + 1, ay, bx, ey, taps, sc);
  if (ey < by) lit += count_window_shared(level, ax, ey + 1, bx, by, taps, sc);
  return lit;
}

template uint32_t RemoteMap::count_window_shared<FlatTaps>(uint32_t, uint64_t, uint64_t, uint64_t, uint64_t,
                                                           const FlatTaps&, LookupScratch&) const noexcept;
template uint32_t RemoteMap::count_window_shared<PlaneTaps>(uint32_t, uint64_t, uint64_t, uint64_t, uint64_t,
                                                            const PlaneTaps&, LookupScratch&) const noexcept;

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
  TileMemo* const memo = tile_memo();  // the tiles this thread's last batches entered
  // Single taps in Morton order of their texels, kTapOrderMax at a time (tap_order.hpp):
  // a tile's taps together, each walk resuming from a neighbour's path. Taps that follow
  // each other in one tile go to it as one run (TapWalks::tap_run): the loop below runs
  // per run, not per tap.
  uint16_t order[kTapOrderMax];
  for (size_t b0 = 0; b0 < n; b0 += kTapOrderMax) {
    const size_t bn = std::min(kTapOrderMax, n - b0);
    const PcfQuery* const base = queries.data() + b0;
    float* const base_out = out.data() + b0;
    tap_order_or_identity(std::span(base, bn), map_level, order);
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
          LookupScratch::TileView v;
          if (!(memo && memo_tile(*memo, q.level, x, y, v))) {
            float value;
            WalkNote note;
            if (!enter_tile(q.level, x, y, sc, value, &note)) {  // a page-table value: its region is kept
              take(sc.regions[sc.last]);
              base_out[i] = tap_lit(q.receiver, value);
              ++k;
              continue;
            }
            v = sc.tile();
            if (memo) memo_keep(*memo, x, y, v, note);
          }
          t = used_tiles < kTiles ? used_tiles++ : next_tile;
          next_tile = (t + 1) % kTiles;
          tiles[t] = Tile{v.ev, v.walks, v.level, v.rel, v.x0, v.y0, v.side};
          paths[t].owner = nullptr;  // a new tile: its path starts empty
        }
        cur = t;
      }
      const Tile& tl = tiles[t];
      // The run: this tap and the single taps after it in the same tile, which the run's
      // own loop finds (TapRun::side): no pass of its own over the taps.
      const TapRun run{base, order + k, bn - k, q.level, tl.rel, tl.x0, tl.y0, base_out, tl.side};
      TapRunEnd end;
      if (tl.walks) {
        end = tl.walks->tap_run(run, paths[t]);
      } else {
        end = tap_run_loop(run, [&](uint32_t l, uint64_t tx, uint64_t ty) {
          try {
            return tl.ev->depth_region(l, tx, ty);
          } catch (...) {  // an opened tile does not throw; if one did, stay lit and alive
            return DepthRegion{kLitDepth, 0};
          }
        });
      }
      // A run that ended at once (its first tap outside it: a broken run): this tap answered
      // singly, so such a run costs time, never a loop that does not advance.
      if (end.count == 0) {
        base_out[i] = pcf_shared(q.level, q.x, q.y, 1, q.receiver, sc);
        if (sc.used) take(sc.regions[sc.last]);
        ++k;
        continue;
      }
      const size_t e = k + end.count;
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

}  // namespace st::client

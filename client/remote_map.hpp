// One opened remote map (internal to client/): the pack header and skip grid from
// MapInfo, the tile cache with the opened tile of every resident slot, the request
// table of wanted tiles (tile_requests.hpp), and the evaluator walking skip grid ->
// index tiles -> tiles like PackEvaluator does, answering from the deepest node reached
// when a tile is missing.
//
// Locking: one reader-writer lock (rw_lock.hpp) guards everything mutable. Lookups take
// it shared, once per call or per batch, and change nothing the lock guards: they read the
// page table with TileCache::lookup, count in per-thread-shard atomics, stamp the slots
// they used with the current epoch (an atomic per slot), and note the tiles they missed
// in a small list on their stack, queued under the exclusive lock after the shared part
// (only when something was missed). The fetcher takes it exclusive only for O(1)
// bookkeeping and writes tile bytes for a reserved (pinned, unpublished) slot outside it
// (into the tile arena, tile_arena.hpp, or the slot itself), so lookups never wait on the network, on decompression or on tile validation, and
// lookups on many threads do not wait for each other.
//
// LRU from stamps: before the fetcher evicts (reserve), it replays the use since the
// last eviction: every slot stamped with the current epoch is marked most recently used,
// then the epoch advances. Recency is therefore exact between arrivals and unordered
// within one (slots used since the last arrival go to the front in slot order).
#pragma once
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <span>
#include <string>
#include <vector>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "client/deep_part.hpp"
#include "client/rw_lock.hpp"
#include "client/tile_arena.hpp"
#include "client/tile_requests.hpp"
#include "shadowtile/client.hpp"
#include "tiles/core/tile_cache.hpp"
#include "proto/messages.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/page_table.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/tile_cut_grid.hpp"
#include "tiles/core/stack_map.hpp"
#include "tiles/core/surface_extent.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st::dagmh {
class Dictionary;
}

namespace st::client {

// Wakes the fetcher from any thread without allocating or blocking (an eventfd; the
// flag keeps it to one write per fetcher round).
class Notifier {
 public:
  Notifier();  // st::Error if no eventfd can be made
  ~Notifier();
  Notifier(const Notifier&) = delete;
  Notifier& operator=(const Notifier&) = delete;
  int fd() const { return fd_; }
  void notify() noexcept;
  void clear() noexcept;  // the fetcher, before it looks for work

 private:
  int fd_ = -1;
  std::atomic<bool> pending_{false};
};

// Page-table entries reserved beyond the request table and the slots, so that lookups
// queueing misses rarely grow it.
inline constexpr uint64_t kPageReserve = 4096;
// Tiles given up (refused by the server, or failing after retries) remembered per map as
// constant pages, so they are not asked for again; past this many the map stops asking
// the server for new tiles (failed_locked): a server refusing everything is not asked
// for every tile of the map, one after another, for ever.
inline constexpr uint64_t kMaxFailedTiles = 4096;

// A region of one level's texels, [x0, x1) x [y0, y1), asked for at `priority`
// (RemoteMap::request_region).
struct RegionRequest {
  uint32_t level;
  uint64_t x0, y0, x1, y1;
  uint16_t priority;
};

class RemoteMap final : public Evaluator {
 public:
  // Parses and checks the MapInfo blobs (st::Error naming the map otherwise).
  RemoteMap(std::string name, std::vector<uint8_t> header_bytes, std::vector<uint8_t> grid_bytes,
            const ClientOptions& options, std::shared_ptr<Notifier> notifier);

  // ---- Evaluator (noexcept; never blocks, never allocates) ----
  uint32_t finest_level() const override { return header_.map_level; }
  float depth(uint32_t level, uint64_t x, uint64_t y) const noexcept override;
  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const noexcept override;
  void pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const noexcept override;
  float visibility(const Vec3d& world, uint32_t pcf_radius) const noexcept;
  // Map::visibility's batches: min(points, out[, footprints]) answers, one shared lock.
  // footprints: the side of each receiver's footprint in world units (0: the finest level).
  void visibility_batch(std::span<const WorldPoint> points, std::span<const float> footprints, std::span<float> out,
                        uint32_t pcf_radius) const noexcept;
  // Each tap against the receiver plane (remote_map_plane.cpp): Evaluator::pcf_on_plane,
  // and Map::visibility_filtered with normals (the point, offset and plane of
  // receiver_plane_at, render's filtered path; footprints may be empty: the finest level).
  float pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const noexcept override;
  void visibility_plane_batch(std::span<const WorldPoint> points, std::span<const WorldPoint> normals,
                              std::span<const float> footprints, std::span<float> out, uint32_t pcf_radius,
                              bool closed) const noexcept;

  size_t request_region(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h,
                        uint16_t priority) noexcept;
  size_t cancel_outside(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) noexcept;
  bool region_resident(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) const noexcept;
  MapStats stats() const noexcept;
  // Cameras (remote_views.cpp; client.hpp Map::request_view).
  ViewStats request_view(uint32_t id, const double* view_projection, uint32_t width, uint32_t height,
                         const ViewOptions& options) noexcept;
  bool remove_view(uint32_t id) noexcept;
  ViewStats view_stats(uint32_t id) const noexcept;
  size_t view_samples(const double* view_projection, uint32_t width, uint32_t height, const ViewOptions& options,
                      std::span<ViewSample> out) const noexcept;
  // The light MapInfo publishes: the pack's, or a stack map's first sample's.
  const std::shared_ptr<const LightSpace>& info_light() const noexcept { return info_light_; }
  // Where the surfaces lie (surface_extent.hpp), for MapInfo::scene and views' receiver
  // plane; a stack map's from its first slice's level-a map.
  const SurfaceExtent& surface() const noexcept { return surface_; }

  const std::string& name() const { return name_; }
  const PackHeader& header() const { return header_; }
  const CutGrid& grid() const { return grid_; }
  const MapPreview& preview() const { return preview_; }
  // The DAG-MH dictionary v2 tiles reference (null: none); GpuMap uploads it once.
  const std::shared_ptr<const dagmh::Dictionary>& dictionary() const { return dictionary_; }
  const std::vector<uint8_t>& header_bytes() const { return header_bytes_; }
  uint32_t slot_bytes() const { return cache_.slot_bytes(); }
  const LightSpace& light() const { return light_; }
  // The deep part (partial occluders) of a pack with the deep_shadow feature, else null.
  const DeepPart* deep() const { return deep_.get(); }

  // Stack maps (a pack with the stack feature; remote_stack.cpp). The 2D lookups above
  // answer lit everywhere on them (their page table is one constant entry).
  bool is_stack() const { return bool(stack_grid_); }
  const StackGrid* stack_grid() const { return stack_grid_.get(); }
  float stack_visibility(const Vec3d& world, double time, uint32_t pcf_radius = 0, float footprint = 0) const noexcept;
  float stack_soft_visibility(const Vec3d& world, uint32_t pcf_radius = 0, float footprint = 0) const noexcept;
  // The same with the receiver's normal (StackMap::*_on_plane; a normal far from unit
  // length is made unit, as visibility_plane_batch does).
  float stack_visibility_plane(const Vec3d& world, const Vec3d& normal, double time, uint32_t pcf_radius,
                               float footprint, bool closed) const noexcept;
  float stack_soft_visibility_plane(const Vec3d& world, const Vec3d& normal, uint32_t pcf_radius, float footprint,
                                    bool closed) const noexcept;
  // stack_soft_visibility of each point (pcf_radius 0: StackMap's batched, interleaved walks).
  void stack_soft_visibility_batch(std::span<const WorldPoint> points, std::span<float> out,
                                   uint32_t pcf_radius) const noexcept;
  float stack_depth(uint32_t slice, uint32_t level, uint64_t x, uint64_t y) const noexcept;
  size_t request_slices(uint32_t w0, uint32_t w1, uint16_t priority) noexcept;
  bool slices_resident(uint32_t w0, uint32_t w1) const noexcept;

  // ---- fetcher side ----
  // Appends up to `max` queued tiles (highest priority first, FIFO among equals) to
  // `out` and records them as sent in the GetTiles `request_id`.
  void take_wanted(size_t max, uint32_t request_id, std::vector<proto::TileRequest>& out);
  // Tiles sent but no longer wanted (cancel_outside): the fetcher sends Cancel.
  void take_cancels(std::vector<uint64_t>& out);
  bool has_work() const;
  // A TileData answering `request_id`: end-to-end CRC, decompress into a reserved slot,
  // open, publish; refetch or give up on failure. Answers for a tile not sent in
  // `request_id` are ignored (false: not an answer to it).
  bool tile_arrived(const proto::TileMeta& meta, uint32_t request_id, std::span<const uint8_t> stored) noexcept;
  // A TileError: cancelled -> absent again; any other code -> given up (coarse answers).
  // False: no tile of this map was sent under that id (ignored).
  bool tile_refused(uint64_t tile, uint32_t request_id, proto::ErrorCode code) noexcept;
  // `request_id` ended (FINAL) with tiles of it never answered (a server breaking
  // PROTOCOL.md §7: wrong ids, missing answers): each is counted in tiles_unanswered and
  // asked again up to max_tile_retries, then given up; cancelled ones are dropped. O(the
  // request table): the fetcher calls it only when the answers fell short.
  void request_ended(uint32_t request_id) noexcept;
  // The connection dropped: every sent tile is queued again (cancelled ones dropped).
  void connection_lost() noexcept;
  // ---- the GPU mirror (gpu/gpu_map.cpp) ----
  // Runs fn(const TileCache&) under the lock taken shared, like a lookup (fn only reads,
  // so lookups on other threads go on meanwhile and only tile arrivals wait); fn must be
  // quick and must not call back into this map.
  template <class Fn>
  void inspect_cache(Fn&& fn) const {
    std::shared_lock lock(mu_);
    fn(static_cast<const TileCache&>(cache_));
  }
  // Tiles a GPU pass needed and found absent (its feedback): each is queued like a lookup
  // miss, at its own priority. Ids that cannot be tiles of this map are skipped. Returns
  // how many were newly queued or raised.
  struct WantedTile {
    uint64_t tile = 0;
    GridEntry entry;
    uint16_t priority = 1;
  };
  size_t want_tiles(std::span<const WantedTile> tiles) const noexcept;
  // Test hook: how many tiles are sent and unanswered.
  size_t sent_count() const;

 private:
  // What one lookup call (single or batch) carries on its stack while it holds the lock
  // shared: the encoded tile its last lookup ended in (consecutive lookups inside it skip
  // the page-table walk and the hash lookup: lookups grouped by tile), the tiles it
  // missed (queued afterwards) and its counts.
  struct LookupScratch {
    const Evaluator* ev = nullptr;  // the current tile (null: none)
    const WindowDepths* win = nullptr;  // the current tile's window walk (null: it has none)
    const TapWalks* walks = nullptr;    // the current tile's resumable single taps (null: none)
    uint32_t level = 0, rel = 0;    // lookup level; the tile's level relative to its root
    uint64_t x0 = 0, y0 = 0, side = 0;  // the tile's texels at `level`: [x0, x0 + side)
    // The last answers' regions (Evaluator::DepthRegion, page_table.hpp PageHit): texels
    // of `level` sharing (x >> shift, y >> shift) with the region's get its value without
    // a walk (the last-sample cache of MH 2016 §3.3, across tiles and page-table entries
    // alike). A few are kept, so that a PCF kernel's rows and a batch going back and
    // forth between neighbours find theirs; the one answered last is tried first.
    enum class Counted : uint8_t { none, hit, coarse };
    struct Region {  // no initializers: a call's scratch starts with none kept, for free
      uint32_t level, shift;
      uint64_t x, y;
      float value;
      Counted counted;
      bool holds(uint32_t l, uint64_t tx, uint64_t ty) const {
        return l == level && ((tx ^ x) >> shift) == 0 && ((ty ^ y) >> shift) == 0;
      }
    };
    static constexpr uint32_t kRegions = 8;
    std::array<Region, kRegions> regions;  // the first `used` are kept
    uint32_t used = 0, last = 0, next = 0;  // how many; the one answered last; the one replaced next
    // The regions again as 32-bit keys, for find's branch-free scan of all of them at once
    // (levels <= 20, so a texel fits in 24 bits and the level in the top 8 of key_x): a
    // texel's keys kx, ky are held by region i when ((kx ^ key_x[i]) | (ky ^ key_y[i])) &
    // key_mask[i] is 0. A slot not kept has key_x ~0 (level 255), which no texel matches.
    alignas(16) std::array<uint32_t, kRegions> key_x{~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u};
    alignas(16) std::array<uint32_t, kRegions> key_y{}, key_mask{~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u};
    // The tap depths of the last kernels (pcf_shared), one window per level parity (a
    // filtered lookup alternates two adjacent levels): a kernel on the same row of taps
    // reuses the columns it shares with the last one and reads only its new ones, so a
    // kernel sliding along a row reads r taps, not r * r (the depths are the map's, exact
    // while the lock is held). r == 0: no window yet.
    struct Taps {
      uint32_t level, r = 0;
      uint64_t y;                               // the kernel's centre row: same y, same rows
      // The centre x of a kernel whose first r - 1 columns the window holds (the last
      // kernel was interior and this one's left neighbour; ~0: none): it reads one column.
      uint64_t slide = ~uint64_t(0);
      uint32_t slide_slot;  // then the slot of its new column ((slide + (r - 1) / 2) % r, kept)
      std::array<uint64_t, kMaxPcf> col;        // each column's tap x (~0: none)
      std::array<float, kMaxPcf * kMaxPcf> depth;  // [column * r + row]
    };
    std::array<Taps, 2> taps;
    // The columns a kernel sliding right along a row reads next, fetched kAhead at a time
    // in one window walk per tile (the walk to their common node shared by kAhead
    // kernels): columns [x0, x0 + n) of rows [y0, y0 + r) of `level`, depth[(x - x0) * r +
    // row], so a kernel inside them is r * r consecutive depths; the r - 1 columns the next
    // kernel shares stay in front when more are read. One per level parity, as taps.
    static constexpr uint32_t kAhead = 8;
    struct Ahead {
      uint32_t level, r, n = 0;  // n == 0: none
      uint64_t x0, y0;
      float depth[(kAhead + kMaxPcf - 1) * kMaxPcf];
    };
    std::array<Ahead, 2> ahead;
    static constexpr size_t kMaxMisses = 8;  // more distinct misses in one call: asked again later
    std::array<uint64_t, kMaxMisses> miss_tile{};
    std::array<GridEntry, kMaxMisses> miss_entry{};
    size_t misses = 0;
    uint64_t hits = 0, missed = 0, coarse = 0;
    // The kept region holding texel (l, x, y), now the last one, or null. A region lies in
    // the map (shift <= level), so a texel it holds is in the map.
    const Region* find(uint32_t l, uint64_t tx, uint64_t ty) {
      if (used == 0) return nullptr;
      if (regions[last].holds(l, tx, ty)) return &regions[last];
      return find_other(l, tx, ty);
    }
    // find, the last one's region already tried.
    const Region* find_other(uint32_t l, uint64_t tx, uint64_t ty) {
      if (((tx | ty) >> 24) != 0 || l > 254) return nullptr;  // outside every map: no region holds it
      const uint32_t m = holding(uint32_t(tx) | l << 24, uint32_t(ty));
      if (m == 0) return nullptr;
      last = uint32_t(__builtin_ctz(m));  // any holding region answers the same (the same texel's value)
      return &regions[last];
    }
    // Bit i set: region i holds the texel of keys (kx, ky).
    uint32_t holding(uint32_t kx, uint32_t ky) const {
      static_assert(kRegions == 8);
#if defined(__SSE2__)
      const __m128i x = _mm_set1_epi32(int(kx)), y = _mm_set1_epi32(int(ky)), zero = _mm_setzero_si128();
      auto half = [&](size_t at) {
        const __m128i kx4 = _mm_load_si128(reinterpret_cast<const __m128i*>(key_x.data() + at));
        const __m128i ky4 = _mm_load_si128(reinterpret_cast<const __m128i*>(key_y.data() + at));
        const __m128i m4 = _mm_load_si128(reinterpret_cast<const __m128i*>(key_mask.data() + at));
        const __m128i d = _mm_and_si128(_mm_or_si128(_mm_xor_si128(x, kx4), _mm_xor_si128(y, ky4)), m4);
        return uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(d, zero))));
      };
      return half(0) | half(4) << 4;
#else
      uint32_t m = 0;
      for (uint32_t i = 0; i < kRegions; ++i)
        m |= uint32_t((((kx ^ key_x[i]) | (ky ^ key_y[i])) & key_mask[i]) == 0) << i;
      return m;
#endif
    }
    void set_region(uint32_t l, uint64_t tx, uint64_t ty, uint32_t shift, float value, Counted c) {
      regions[next] = Region{l, shift, tx, ty, value, c};
      key_x[next] = uint32_t(tx) | l << 24;  // regions are set for texels of the map (< 2^20)
      key_y[next] = uint32_t(ty);
      key_mask[next] = ~((1u << shift) - 1u);
      last = next;
      next = (next + 1) % kRegions;
      used = std::min(used + 1, kRegions);
    }
    const Region* last_region() const { return used ? &regions[last] : nullptr; }
    // A region's answer, counted like the lookup that made it.
    float answer(const Region& g) {
      if (g.counted == Counted::hit) ++hits;
      else if (g.counted == Counted::coarse) ++missed, ++coarse;
      return g.value;
    }
    bool covers(uint32_t l, uint64_t x, uint64_t y) const {
      return ev && l == level && x - x0 < side && y - y0 < side;  // unsigned: x < x0 wraps
    }
    // The current tile's fields above, as one value (ev null: none).
    struct TileView {
      const Evaluator* ev = nullptr;
      const WindowDepths* win = nullptr;
      const TapWalks* walks = nullptr;
      uint32_t level = 0, rel = 0;
      uint64_t x0 = 0, y0 = 0, side = 0;
      bool covers(uint32_t l, uint64_t x, uint64_t y) const {
        return ev && l == level && x - x0 < side && y - y0 < side;
      }
    };
    TileView tile() const { return {ev, win, walks, level, rel, x0, y0, side}; }
    void set_tile(const TileView& t) {
      ev = t.ev, win = t.win, walks = t.walks, level = t.level, rel = t.rel, x0 = t.x0, y0 = t.y0, side = t.side;
    }
    // The tile fill_columns was in before it entered another: a column across a
    // tile border alternates between two tiles, and this one comes back without a
    // page-table walk (lock held: it stays resident).
    TileView alt;
  };
  // Walks (level, x, y) (in the map) under the shared lock. True: it ends in a resident
  // encoded tile, now sc's current one. False: `value` answers (coarse when missed).
  // What a walk that ended in a resident tile passed through (TileMemo's entry, the
  // batch's memo in remote_map_lookups.cpp): the tile's slot and the index tiles' slots on
  // its way (path_count > kMemoPath: too many to keep).
  static constexpr uint32_t kMemoPath = 3;
  struct WalkNote {
    uint32_t slot = kNoSlot;
    uint32_t path_count = 0;
    uint32_t path[kMemoPath];
  };
  bool enter_tile(uint32_t level, uint64_t x, uint64_t y, LookupScratch& sc, float& value,
                  WalkNote* note = nullptr) const noexcept;
  // The page-table walk both of them make over the cache: each resident index tile on the
  // way marked used and its slot kept (up to kMemoPath); `page` is the cache's answer for
  // the tile the walk ended at (for a value: the last tile it asked about).
  struct ResidentWalk {
    PageHit hit;
    PageEntry page;
    uint32_t path_count = 0;
    uint32_t path[kMemoPath];
    // `note` (if any) names `slot` and the index tiles passed.
    void fill(uint32_t slot, WalkNote* note) const noexcept;
  };
  ResidentWalk walk_resident(uint32_t level, uint64_t x, uint64_t y) const noexcept;
  // A thread's memo of the resident tiles its batches entered, across calls (the render's
  // batches of one frame come in screen order, and neighbouring batches meet the same
  // tiles): a texel's tile without the page-table walk (the skip grid, the cache's hash
  // bucket, index tiles, the slot arrays: a chain of dependent loads per run of taps).
  // Each entry holds for as long as no tile of this map became resident or left
  // (TileCache::journal_end unchanged: the walks' answers are then the same).
  struct TileMemo;  // remote_map_lookups.cpp
  // This thread's memo, emptied if another map or another residency filled it; null when
  // it could not be allocated (the batch then walks every tile).
  TileMemo* tile_memo() const noexcept;
  // The memo's tile holding (level, x, y), marked used (with the index tiles its walk
  // passed) and prefetched (WindowDepths::prefetch, TapWalks::prefetch); false if the memo
  // has none.
  bool memo_tile(TileMemo& m, uint32_t level, uint64_t x, uint64_t y, LookupScratch::TileView& tile) const noexcept;
  // Keeps `tile` (the walk of texel (x, y)'s, with its note) in the memo.
  static void memo_keep(TileMemo& m, uint64_t x, uint64_t y, const LookupScratch::TileView& tile,
                        const WalkNote& note) noexcept;
  float depth_shared(uint32_t level, uint64_t x, uint64_t y, LookupScratch& sc) const noexcept;
  // Evaluator::pcf's answer, from the kept regions: a kernel with no tap clamped on the
  // rows of the columns kept ahead (LookupScratch::Ahead) and reaching at most to the
  // column after them (a screen-coherent row of kernels) counts its r * r depths there,
  // reading the columns it lacks kAhead at a time, one window walk per tile or region
  // they lie in (fill_columns, across tile borders and missing tiles alike); else
  // (pcf_general) a kernel inside one region answers at once;
  // one on the last kernels' rows reads only its new columns (the tap window); another
  // inside one resident tile (or crossing only the map's edges) goes through the tile's
  // own shared-walk pcf (MH §3.3, DAG-MH §3.5); others with no tap clamped counted one
  // window per tile or region (count_window_shared); the rest row by row, the taps of a row that
  // one region holds together (MH §3.3's last-sample cache, across tile borders and
  // missing tiles alike).
  // pcf_batch's body, under a lock the caller holds.
  void pcf_batch_shared(std::span<const PcfQuery> queries, std::span<float> out, LookupScratch& sc) const noexcept;
  // How many texels of [ax, bx] x [ay, by] (of `level`, in the map) are lit for
  // `receiver`: the rectangle cut at the borders of the resident tiles and kept regions
  // over it, each part one WindowDepths::count_window or one region's answer times its
  // area; every texel counted as depth_shared answers it (missing tiles coarse, as there).
  // Columns [tx, tx + n) of the rows [ky0, ky1] (of `level`, in the map; 2 <= rows <=
  // kMaxPcf) into out[(column - tx) * rows + row - ky0], returning n (1 <= n <= kAhead,
  // as far as every part reaches): the columns cut at the borders of the tiles and kept
  // regions they cross, each part one WindowDepths::depth_window or one region's value
  // (missing tiles coarse, as depth_shared answers them). 0: a tile with no window walk.
  uint32_t fill_columns(uint32_t level, uint64_t tx, uint64_t ky0, uint64_t ky1, LookupScratch& sc,
                        float* out) const noexcept;
  // Taps: how a part counts, FlatTaps (one receiver: WindowDepths::count_window) or
  // PlaneTaps (each texel against the receiver plane: WindowDepths::count_window_plane),
  // receiver_plane.hpp; one cut for both (remote_map_lookups.cpp, instantiated there).
  template <class Taps>
  uint32_t count_window_shared(uint32_t level, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by, const Taps& taps,
                               LookupScratch& sc) const noexcept;
  float pcf_shared(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver,
                   LookupScratch& sc) const noexcept;
  // pcf_shared with each texel against the receiver plane (count_window_shared with
  // PlaneTaps), remote_map_plane.cpp.
  float pcf_plane_shared(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p,
                         LookupScratch& sc) const noexcept;
  // pcf_shared for every kernel but one counted from the columns kept ahead.
  float pcf_general(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver,
                    LookupScratch& sc) const noexcept;
  // The columns kept ahead for `level` (on the kernel's rows, x0 <= kx0 <= x0 + n < kx0 +
  // r) made to start at kx0 and hold at least r columns: the ones from kx0 on moved to
  // the front, the rest read by fill_columns. False: a tile with no window walk (then
  // none are kept).
  bool extend_ahead(uint32_t level, uint64_t kx0, uint32_t r, LookupScratch& sc) const noexcept;
  float visibility_shared(const WorldPoint& world, float footprint_world, uint32_t pcf_radius,
                          LookupScratch& sc) const noexcept;
  // The same from the point's light-space position `p` (LightSpace::to_light of `w`).
  float visibility_at(const LightPoint& p, const Vec3d& w, float footprint_world, uint32_t pcf_radius,
                      LookupScratch& sc) const noexcept;
  // After the shared part: counts, then (exclusive) the misses queued at miss_priority.
  void finish_lookups(const LookupScratch& sc) const noexcept;
  void mark_used(uint32_t slot) const noexcept {
    std::atomic<uint32_t>& a = slot_used_[slot];
    if (a.load(std::memory_order_relaxed) != epoch_) a.store(epoch_, std::memory_order_relaxed);
  }
  // Replays the slots' use into the cache's LRU list (exclusive lock held): see above.
  void sync_lru_locked() noexcept;
  // Queues `tile` (lock held). Returns true if newly queued or raised.
  bool want_locked(uint64_t tile, const GridEntry& e, uint16_t priority) const noexcept;
  // The record of `tile` if it was sent in `request_id` and not answered (lock held).
  RequestRecord* sent_record_locked(uint64_t tile, uint32_t request_id) noexcept;
  // Forgets the request and leaves the page absent (cancelled, or no room to retry).
  void drop_locked(RequestRecord& r) noexcept;
  // Forgets the request and makes the page constant: lookups answer the entry's value.
  void give_up_locked(RequestRecord& r) noexcept;
  // A delivery of `tile` in `request_id` failed (counted in `counter`): queue it again,
  // or give it up after max_tile_retries.
  void retry_or_give_up(uint64_t tile, uint32_t request_id, uint64_t MapStats::*counter) noexcept;
  void retry_or_give_up_locked(uint64_t tile, uint32_t request_id, uint64_t MapStats::*counter) noexcept;
  // tile_arrived once its record was found: the checks, the slot, the publication.
  void tile_answer(const proto::TileMeta& meta, uint32_t request_id, std::span<const uint8_t> stored,
                   const GridEntry& entry) noexcept;
  // Decompresses (or copies) `stored` into the arena (to_arena, room there: `held` is
  // then its bytes) or else into the reserved `slot`, and opens it; false if the bytes do
  // not make the tile `entry` names. Runs without the lock.
  bool fill_slot(uint32_t slot, const proto::TileMeta& meta, const GridEntry& entry,
                 std::span<const uint8_t> stored, bool to_arena, std::unique_ptr<Evaluator>& ev, CutGrid& grid,
                 std::span<const uint8_t>& held) noexcept;
  // Visits the tiles needed for lookups at `level` in [x0, x1) x [y0, y1) (lock held):
  // fn(tile_id, entry, page) for each non-resident one; returns false if fn did.
  template <class Fn>
  bool walk_region(uint32_t level, uint64_t x0, uint64_t y0, uint64_t x1, uint64_t y1, Fn&& fn) const;
  // Regions asked for and not yet resident (request_region): each index tile's arrival walks
  // them again so that its children follow. Complete regions are forgotten (remember: a region
  // the walk found resident is never kept; rerequest: those now resident are dropped); a region
  // inside a remembered one of its level only raises that one's priority.
  void remember_region_locked(const RegionRequest& r);
  void rerequest_regions_locked();
  // Stack lookups: the StackMap's tile source (stack_tiles) reads the cache (shared lock
  // held) and notes misses in a per-thread scratch; they are wanted once the lock is dropped.
  // One cell's tile, its miss noted (stack_tiles' non-resident cells).
  StackTileRef stack_tile(uint64_t cell) const noexcept;
  // out[i] = stack_tile(cells[i]) for i < n, the pages first, then the resident slots'
  // evaluators prefetched, then the refs (StackMap::TileSource: the loads overlap).
  void stack_tiles(const uint64_t* cells, uint32_t n, StackTileRef* out) const noexcept;
  void open_stack(const std::vector<uint8_t>& grid_bytes);  // the constructor's, for stack packs
  static std::unique_ptr<Evaluator> open_stack_tile(const StackGrid& g, uint64_t id, std::span<uint8_t> raw, uint32_t pack_flags);
  template <class Fn>
  auto stack_lookup(Fn&& fn) const noexcept;

  // ---- views (remote_views.cpp) ----
  // One tile a view needs: `path` for a resident index tile its walks pass through (kept
  // resident too, not counted as a need), else the tile the walk ended at (an encoded
  // tile, or an index tile not at hand: its children follow once it arrives). `ahead`:
  // needed only by the camera's poses ahead (ViewOptions::time), not by its pixels now.
  struct ViewTile {
    uint64_t tile;
    GridEntry entry;
    float distance;
    bool path, seen_resident, ahead;
  };
  static bool tile_less(const ViewTile& a, const ViewTile& b) { return a.tile < b.tile; }
  struct View {
    bool used = false;
    uint32_t id = 0;
    uint16_t priority = 0;
    uint32_t wanted = 0;
    std::array<double, 16> last_vp{};  // the previous request's matrix and time (views_mu_)
    double last_time = 0;
    bool has_last = false;
    std::vector<ViewTile> tiles;   // kept, sorted by tile id (mu_)
    std::vector<ViewTile> next, scratch;  // the next request's work (views_mu_)
  };
  bool in_other_view_locked(const View* self, uint64_t tile) const noexcept;
  uint32_t view_slots() const noexcept;
  ViewStats view_counts_locked(const View& v) const noexcept;
  // Appends the tiles the screen samples of the camera with inverse view-projection `inv`
  // need (lock held shared), `ahead` flagged; false when the camera casts nothing.
  template <class Rays>
  void collect_view_tiles(const Rays& rays, const ViewOptions& o, bool ahead, std::vector<ViewTile>& out) const;
  std::mutex views_mu_;  // one request_view at a time; taken before mu_
  std::array<View, kMaxViews> views_;
  uint32_t view_count_ = 0;  // (mu_)
  SurfaceExtent surface_;
  // 1: the slot's tile is in some view (mu_): sync_lru_locked makes it most recently used
  // before every eviction, so views' tiles go last.
  std::vector<uint8_t> slot_in_view_;
  std::shared_ptr<const LightSpace> info_light_;
  SurfaceExtent stack_surface();  // remote_stack.cpp: from slice 0's level-a map

  const std::string name_;
  const ClientOptions options_;
  std::shared_ptr<Notifier> notifier_;
  std::vector<uint8_t> header_bytes_;
  PackHeader header_;
  CutGrid grid_;
  MapPreview preview_;  // after the skip grid in MapInfo: answers where a tile is missing
  // The pack's DAG-MH dictionary (after the preview in MapInfo; tiles/PACK.md "DAG-MH
  // dictionary"): resident for the map's life, beside the slots (counted in a byte
  // budget's metadata: ClientOptions::cache_bytes).
  std::shared_ptr<const dagmh::Dictionary> dictionary_;
  LightSpace light_;
  std::unique_ptr<StackGrid> stack_grid_;
  std::unique_ptr<StackMap> stack_map_;

  mutable RwLock mu_;
  mutable TileCache cache_;
  // Where the 2D map tiles' bytes live: packed tightly (tile_arena.hpp), not in the slots,
  // which are the tile bound apart (the GPU mirror's layout); the cache's slot holds them
  // by reference (TileCache::commit_held). Index tiles and stack cells stay in slots.
  TileArena arena_;
  uint64_t metadata_bytes_ = 0;    // accounted outside the slots (ClientOptions::cache_bytes)
  uint32_t dictionary_slots_ = 0;  // MapStats::dictionary_slots
  // This map among every RemoteMap of the process (never reused): a thread's tile memo
  // (remote_map_lookups.cpp) holds one map's tiles and knows which.
  const uint64_t serial_ = next_serial();
  static uint64_t next_serial() noexcept;
  std::unique_ptr<std::atomic<uint32_t>[]> slot_used_;  // epoch of each slot's last use
  uint32_t epoch_ = 1;                                   // written under the exclusive lock
  struct alignas(64) CounterShard {
    std::atomic<uint64_t> hits{0}, misses{0}, coarse{0};
  };
  static constexpr size_t kCounterShards = 8;  // threads pick one each: no shared cache line
  mutable std::array<CounterShard, kCounterShards> counters_;
  std::vector<std::unique_ptr<Evaluator>> slot_eval_;  // encoded tiles, per slot
  std::vector<const WindowDepths*> slot_window_;       // slot_eval_'s window walk, or null
  std::vector<const TapWalks*> slot_walks_;            // slot_eval_'s resumable single taps, or null
  std::vector<CutGrid> slot_grid_;                     // index tiles, per slot
  // want_capacity queued + max_in_flight * tiles_per_request sent; never grows.
  mutable TileRequests requests_;
  std::vector<uint64_t> cancels_;  // reserved to the sent bound: cancel_outside never allocates
  // Remembered so that index tiles' children follow, until resident (remember_region_locked;
  // cancel_outside forgets those it leaves). Only pending regions count toward kMaxRegions: a
  // frame's cells requested at once (a view's cells, a report's cut) while their index tiles
  // are on the way. Past it the oldest quarter goes (then at most one sweep per quarter).
  static constexpr size_t kMaxRegions = 1024;
  std::array<RegionRequest, kMaxRegions> regions_{};
  size_t region_count_ = 0;
  mutable MapStats stats_;
  uint64_t failed_ = 0;  // tiles given up and remembered (constant pages), <= kMaxFailedTiles
  std::unique_ptr<DeepPart> deep_;
};

}  // namespace st::client

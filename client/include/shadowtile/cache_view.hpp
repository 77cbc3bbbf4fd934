// <shadowtile/cache_view.hpp>: a read-only view of a Map's tile cache for a consumer that
// keeps its own copy of it (the GPU mirror, shadowtile::gpu, or an engine's own): the map's
// static tables, the tables a page-table walk needs (the skip grid, the map preview, the
// DAG-MH dictionary, a stack map's grid), the light transforms, and the slots whose tile
// changed since the consumer last looked; plus the way back, tiles the consumer wants;
// and the deep part's resident tiles (partial occluders), when the map has one.
//
// Lifetime: the view holds the Map open; every span it returns stays valid and unchanged
// for the view's life (the tables are immutable once the map is open). Thread safety:
// like Map, any thread (changed_slots calls are serialized per view); changed_slots holds
// the cache's lock shared while it calls its visitor
// (keep the visitor short: copy bytes, update the consumer's state, nothing that calls
// back into the Map). Errors: the constructor throws std::runtime_error for a Map that
// is not open; nothing else throws but std::bad_alloc.
//
// Slot identity: a slot holds at most one tile; a tile id names immutable bytes (packs
// are content-addressed by tile id), so the tile id a slot holds is its generation: a
// consumer that remembers it per slot uploads exactly the slots whose tile changed.
#pragma once
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "shadowtile/client.hpp"

namespace st::client {

inline constexpr uint64_t kNoTile = ~uint64_t(0);  // an empty slot (st::kInvalidTile)

// A light transform as the pack stores it: the kind (st::LightKind's value) and its 18
// parameters (st::LightSpace::to_array / from_array, tiles/core/light.hpp).
struct LightParams {
  uint32_t kind = 0;
  std::array<double, 18> params{};
};

// One entry of the skip grid or of a stack map's level-K cells: the node's value (the
// answer where nothing finer is resident) and its kind: 0 constant, 1 tile, 2 index tile
// (index_levels: the levels the index tile spans).
struct CacheEntry {
  float value = 0;
  uint32_t kind = 0;
  uint32_t index_levels = 0;
};

struct CacheShape {
  uint32_t finest_level = 0;   // L
  uint32_t skip_level = 0;     // K (2D maps: the skip grid's level)
  uint32_t encoding = 0;       // st::Encoding's value (0 MH, 1 MMH, 2 DAG-MH, 3 vsdag)
  uint32_t slot_count = 0;     // cache slots
  uint32_t slot_bytes = 0;     // bytes a slot holds at most
  uint32_t slices = 0;         // stack maps: N slices; 0 for a 2D map
};

// The map preview (tiles/core/map_preview.hpp): coarse answers where a tile is absent.
struct PreviewTables {
  uint32_t levels = 0, mask_words = 0;
  std::span<const uint32_t> ordinals, bases;
  std::span<const float> entry_values;
  std::span<const uint64_t> masks;
  std::span<const float> values;
};

// A stack map's grid (tiles/core/stack_grid.hpp): the octree's top levels and the cells.
struct StackTables {
  uint32_t xy_level = 0, w_level = 0, slices = 0, skip_level = 0;
  std::vector<std::span<const float>> coarse;  // per octree level l < skip_level
  std::span<const CacheEntry> cells;           // level K's cells, then split cells' children (stack_grid.hpp;
                                               // kind 0 constant, 1 tile, 2 split)
  std::span<const LightParams> lights;         // one per slice
};

// One slot whose tile differs from what the consumer knows: `tile` (kNoTile: the slot is
// empty or its tile is not resident any more) and its bytes (empty for kNoTile).
struct SlotChange {
  uint32_t slot = 0;
  uint64_t tile = kNoTile;
  std::span<const uint8_t> bytes;
};

// A tile the consumer needed and did not have (feedback), with the entry that names it
// (CacheEntry of the page-table walk) and a priority (higher first).
struct WantedTile {
  uint64_t tile = kNoTile;
  CacheEntry entry;
  uint16_t priority = 1;
};

// The deep part (partial occluders, Map::has_deep; tiles/core/DEEP.md): the deep map's
// level D (0 until its directory arrived) and its tiles' side bits b; tiles are 2^b texels
// a side, at (tx, ty) of a grid 2^(D - b) tiles a side.
struct DeepShape {
  uint32_t level = 0;
  uint32_t side_bits = 0;
};

// One resident deep tile: its place in the grid and its bytes (tiles/core/deep_format.hpp,
// validated, as the client holds it).
struct DeepTile {
  uint32_t tx = 0, ty = 0;
  std::span<const uint8_t> bytes;
};

// A deep tile a consumer needed and did not have (its feedback): its place in the grid.
struct DeepWant {
  uint32_t tx = 0, ty = 0;
};

class CacheView {
 public:
  // std::runtime_error: the Map is not open.
  explicit CacheView(const Map& map);
  ~CacheView();
  CacheView(const CacheView&) = delete;
  CacheView& operator=(const CacheView&) = delete;

  const CacheShape& shape() const;
  // The 2D skip grid: (4^K - 1) / 3 coarse values (levels 0..K-1, row-major each), 4^K entries.
  std::span<const float> skip_coarse() const;
  std::span<const CacheEntry> skip_entries() const;
  PreviewTables preview() const;
  std::span<const uint8_t> dictionary() const;  // the DAG-MH dictionary's bytes; empty: none
  LightParams light() const;                    // the pack's light (2D maps)
  const StackTables* stack() const;             // null for a 2D map
  // A stack map's cells and their tile ids (false: the id names no cell).
  uint64_t stack_cell_tile(uint64_t cell) const;
  bool stack_tile_cell(uint64_t tile, uint64_t& cell) const;

  // Calls visit(change) for every slot s whose resident tile differs from known[s]
  // (known.size() == slot_count; kNoTile for empty), each once, under the cache's lock
  // (taken shared: lookups go on). When visit returns true the consumer took the change
  // and known[s] becomes its tile; false leaves known[s] as it was (the slot comes again
  // next time: an upload budget). Returns the changes visited.
  // Cost: O(slots changed since the last call), not O(slots): the view follows the cache's
  // change journal for the `known` array it last served, so one view serves one consumer,
  // whose `known` changes only through this call. The first call, a different array (by
  // address or size), or a call so late that the journal overran (more changes than about
  // slot_count) compares every slot, in slot order; otherwise slots come in the order they
  // changed. Allocates nothing.
  template <class Visit>
  size_t changed_slots(std::span<uint64_t> known, Visit&& visit) const {
    return changed_slots_impl(known, &visit, [](void* v, const SlotChange& c) { return (*static_cast<Visit*>(v))(c); });
  }

  // ---- the deep part (all three answer "none" for a map without one) ----
  bool has_deep() const;
  // A count that changes whenever the deep directory arrives or a deep tile becomes
  // resident or is dropped: a consumer that remembers it re-reads deep_tiles only then.
  uint64_t deep_generation() const;
  // Calls visit(const DeepTile&) for every resident deep tile (any order), under the deep
  // part's lock: the bytes are valid only during the call (copy them; call nothing on the
  // Map). Returns the shape; level 0 (directory not known yet, or no deep part): no visits.
  template <class Visit>
  DeepShape deep_tiles(Visit&& visit) const {
    return deep_tiles_impl(&visit, [](void* v, const DeepTile& t) { (*static_cast<Visit*>(v))(t); });
  }
  // Calls visit(std::span<const uint8_t> bitmap) with the deep directory's bitmap under
  // the deep part's lock (bit ty << (D - b) | tx of the little-endian bytes: a deep tile
  // exists there; valid only during the call). Returns the shape; level 0 (directory not
  // known yet, or no deep part): no call. A mirror feeds back only tiles that exist.
  template <class Visit>
  DeepShape deep_directory(Visit&& visit) const {
    return deep_directory_impl(&visit, [](void* v, std::span<const uint8_t> b) { (*static_cast<Visit*>(v))(b); });
  }
  // Queues deep tiles the consumer needed (GPU feedback): those the directory names that
  // are neither resident nor on their way. Returns how many were queued. Never blocks.
  size_t want_deep_tiles(std::span<const DeepWant> tiles) const;
  // The CPU's own deep lookup (Map::transmittance / transmittance_filtered after their
  // light transform), for consumers that compare against it: per-channel transmittance at
  // light-space (u, v) in [0, 1) and depth d, over a footprint `width` map units wide (0:
  // the texel under (u, v)). A missing tile answers 1 and is queued, as there. Never blocks.
  std::array<float, 3> deep_transmittance(double u, double v, float d, double width) const noexcept;

  // Queues tiles the consumer needed on the Map's request queue (raising a queued tile's
  // priority); returns how many were newly queued or raised. Never blocks on the network.
  size_t want_tiles(std::span<const WantedTile> tiles) const;

 private:
  size_t changed_slots_impl(std::span<uint64_t> known, void* visit, bool (*call)(void*, const SlotChange&)) const;
  DeepShape deep_tiles_impl(void* visit, void (*call)(void*, const DeepTile&)) const;
  DeepShape deep_directory_impl(void* visit, void (*call)(void*, std::span<const uint8_t>)) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace st::client

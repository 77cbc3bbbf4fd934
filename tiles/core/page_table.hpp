// The page-table walk of a cut map, written once for every reader of one: the pack
// evaluator, the client's cache, `verify` and the load tester.
//
// The page table is the skip grid (a CutGrid at level K, tile_cut_grid.hpp) and, below
// entries of kind `index`, index tiles (CutGrids of 1..4 levels) whose entries point one
// step further down, until an entry is constant or names an encoded tile. A texel
// (level, x, y) is answered by
//   - the skip grid's coarse pyramid when level < K;
//   - the entry above it when that entry is constant or sits at `level` itself;
//   - an index tile's coarse values when `level` falls inside the index tile;
//   - otherwise the encoded tile the walk ends at, at relative level level - tile level.
//
// Out of range, one rule for every reader: a texel outside the map (level above the
// map's finest level, or x, y >= 2^level) is lit: it answers kLitDepth (texel_in_map).
//
// Index tiles come from the caller (a pack on disk, a cache slot): `index_tile(id, entry)`
// returns the parsed CutGrid, or null when it is not at hand (not resident yet). The walk
// then stops and says so, with the value of the deepest node it reached: every level of
// the hierarchy is a complete shadow map, so that value is the coarse answer.
#pragma once
#include <algorithm>
#include <cstdint>

#include "tiles/core/interval.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

// The one out-of-range rule: true when texel (x, y) of `level` lies in a map whose
// finest level is `map_level`.
inline bool texel_in_map(uint32_t map_level, uint32_t level, uint64_t x, uint64_t y) {
  return level <= map_level && (x >> level) == 0 && (y >> level) == 0;
}

// Where one texel's answer lives.
struct PageHit {
  enum class Kind : uint8_t {
    value,   // `value` answers (skip grid, index tile coarse values, or a constant entry)
    tile,    // the encoded tile `tile` answers: depth(rel, tx, ty) of that tile
    absent,  // the index tile `tile` is not at hand: `value` is the coarse answer
  };
  Kind kind = Kind::value;
  float value = kLitDepth;  // value: the answer; tile/absent: the entry's (coarse) value
  uint64_t tile = 0;        // tile/absent: the tile id (make_tile_id of its root)
  GridEntry entry;          // tile/absent: the page-table entry naming the tile
  uint32_t rel = 0;         // tile: `level` relative to the tile's root
  uint64_t tx = 0, ty = 0;  // tile: the texel inside the tile, at relative level `rel`
  // The texels of `level` sharing (x >> region_shift, y >> region_shift) get this same
  // hit: `value` (for a tile, the coarse answer while it is not at hand) answers for the
  // whole node of the entry the walk stopped at.
  uint32_t region_shift = 0;
};

// Walks texel (level, x, y), which must satisfy texel_in_map(map_level, ...), where the
// skip grid `skip` sits at level skip.levels <= level's map. IndexTiles is callable as
// `const CutGrid* (uint64_t id, const GridEntry& entry)`.
template <class IndexTiles>
PageHit walk_page_table(const CutGrid& skip, uint32_t level, uint64_t x, uint64_t y, IndexTiles&& index_tile) {
  PageHit hit;
  const uint32_t k = skip.levels;
  if (level < k) {
    hit.value = skip.coarse_at(level, x, y);
    return hit;
  }
  // The entry at (l, ex, ey): the node above texel (x, y) of `level`.
  uint32_t l = k;
  uint64_t ex = x >> (level - k), ey = y >> (level - k);
  GridEntry e = skip.entry(ex, ey);
  for (;;) {
    hit.value = e.value;
    hit.region_shift = level - l;
    if (e.kind == EntryKind::constant || l == level) return hit;
    hit.tile = make_tile_id(l, uint32_t(ex), uint32_t(ey));
    hit.entry = e;
    const uint32_t rel = level - l;
    const uint64_t lx = x - (ex << rel), ly = y - (ey << rel);  // texel inside the tile
    if (e.kind == EntryKind::tile) {
      hit.kind = PageHit::Kind::tile;
      hit.rel = rel, hit.tx = lx, hit.ty = ly;
      return hit;
    }
    const CutGrid* g = index_tile(hit.tile, e);
    if (g == nullptr) {
      hit.kind = PageHit::Kind::absent;
      return hit;
    }
    const uint32_t d = g->levels;
    if (rel < d) {
      hit.value = g->coarse_at(rel, lx, ly);
      hit.region_shift = 0;
      return hit;
    }
    ex = (ex << d) + (lx >> (rel - d));
    ey = (ey << d) + (ly >> (rel - d));
    l += d;
    e = g->entry(lx >> (rel - d), ly >> (rel - d));
  }
}

// Visits every tile that lookups at `level` inside texels [x0, x1) x [y0, y1) may need,
// coarse to fine: fn(id, entry, tile_level, tile_x, tile_y) -> bool (false stops the
// visit). Index tiles are visited and, when `index_tile` has them, descended into; their
// children are visited only where they meet the region. Returns false if fn stopped it.
// The region must lie in the map (texel_in_map of both corners); level <= K visits none.
template <class IndexTiles, class Fn>
bool visit_page_tiles(const CutGrid& skip, uint32_t level, uint64_t x0, uint64_t y0, uint64_t x1, uint64_t y1,
                      IndexTiles&& index_tile, Fn&& fn);

namespace page_table_detail {
template <class IndexTiles, class Fn>
bool visit_entry(uint32_t l, uint64_t ex, uint64_t ey, const GridEntry& e, uint32_t level, uint64_t x0,
                 uint64_t y0, uint64_t x1, uint64_t y1, IndexTiles& index_tile, Fn& fn) {
  if (e.kind == EntryKind::constant || level <= l) return true;  // the entry answers
  const uint64_t id = make_tile_id(l, uint32_t(ex), uint32_t(ey));
  if (!fn(id, e, l, ex, ey)) return false;
  if (e.kind == EntryKind::tile) return true;
  const CutGrid* g = index_tile(id, e);
  if (g == nullptr) return true;
  const uint32_t d = g->levels, cl = l + d;
  if (level <= cl) return true;
  const uint32_t s = level - cl;
  const uint64_t cx0 = std::max(ex << d, x0 >> s), cx1 = std::min((ex + 1) << d, ((x1 - 1) >> s) + 1);
  const uint64_t cy0 = std::max(ey << d, y0 >> s), cy1 = std::min((ey + 1) << d, ((y1 - 1) >> s) + 1);
  for (uint64_t cy = cy0; cy < cy1; ++cy)
    for (uint64_t cx = cx0; cx < cx1; ++cx)
      if (!visit_entry(cl, cx, cy, g->entry(cx - (ex << d), cy - (ey << d)), level, x0, y0, x1, y1, index_tile, fn))
        return false;
  return true;
}
}  // namespace page_table_detail

template <class IndexTiles, class Fn>
bool visit_page_tiles(const CutGrid& skip, uint32_t level, uint64_t x0, uint64_t y0, uint64_t x1, uint64_t y1,
                      IndexTiles&& index_tile, Fn&& fn) {
  const uint32_t k = skip.levels;
  if (level <= k || x0 >= x1 || y0 >= y1) return true;
  const uint32_t s = level - k;
  for (uint64_t cy = y0 >> s; cy <= (y1 - 1) >> s; ++cy)
    for (uint64_t cx = x0 >> s; cx <= (x1 - 1) >> s; ++cx)
      if (!page_table_detail::visit_entry(k, cx, cy, skip.entry(cx, cy), level, x0, y0, x1, y1, index_tile, fn))
        return false;
  return true;
}

}  // namespace st

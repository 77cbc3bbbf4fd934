// Several slices of one per-slice stack cell (stack_slices.hpp) read at once: the soft and
// time-interpolated stack lookups (stack_map.hpp) ask one cell for the texels of many
// slices in a row. Each slice is its own 2D tile, so no node is shared from one slice's
// walk to the next; but the walks are independent of each other, so they can run in
// lockstep: the skip entries of every slice first, then one level of every walk that
// still descends, then every treelet, then every value. Within a walk each load depends
// on the one before (skip entry, node, treelet, value chunk, multipliers); across walks
// none does, so the loads of one round are in flight together instead of one walk's
// misses after another's (a soft lookup over 64 samples of per-slice cells read each
// slice's tile cold, one dependent miss after another).
//
// Every answer is SliceTiles::depth's bit for bit: each walk is View::lookup_index's
// (descend from the skip table to the texel's level, one level a step, then finish) on
// the slice's own tile; MMH tiles (no DAG-MH view) take the evaluator's own depth().
#pragma once
#include <cstdint>

#include "tiles/core/dagmh_traverse.hpp"
#include "tiles/core/stack_slices.hpp"

namespace st {

inline constexpr uint32_t kMaxSliceWalks = 32;  // the most slices one call reads

// out[i] = t[i]->depth(x[i], y[i], w[i], t[i]->xy_level()) for i < count <= kMaxSliceWalks:
// walks in different per-slice tiles (a soft lookup's samples, whose texels cross cells from
// one sample to the next, each in its own tile) run in lockstep as well; x[i], y[i] <
// 2^xy_level(), w[i] < slices() of their tile (not checked).
inline void slice_depths(const SliceTiles* const* t, uint32_t count, const uint64_t* x, const uint64_t* y,
                         const uint32_t* w, float* out) noexcept {
  const dagmh::View* view[kMaxSliceWalks];
  dagmh::Cursor c[kMaxSliceWalks];
  uint32_t walks[kMaxSliceWalks], active[kMaxSliceWalks], m[kMaxSliceWalks];
  uint32_t nw = 0;
  for (uint32_t i = 0; i < count; ++i) {
    const SliceTiles& ti = *t[i];
    m[i] = ti.xy_level();
    if (ti.is_constant(w[i])) {
      out[i] = ti.constant_value(w[i]);
    } else if (!(view[i] = ti.view(w[i]))) {
      out[i] = ti.evaluator(w[i]).depth(m[i], x[i], y[i]);
    } else {
      c[i] = view[i]->start(m[i], m[i], x[i], y[i]);
      walks[nw++] = i;
    }
  }
  auto descending = [&](uint32_t i) { return (c[i].ref & dagmh::kRefTagMask) == dagmh::kRefInner && c[i].level < m[i]; };
  uint32_t na = 0;
  for (uint32_t j = 0; j < nw; ++j)
    if (descending(walks[j])) active[na++] = walks[j];
  while (na) {  // one level of every walk that still descends (View::descend's own step)
    uint32_t kept = 0;
    for (uint32_t j = 0; j < na; ++j) {
      const uint32_t i = active[j];
      c[i] = view[i]->descend(c[i], c[i].level + 1, m[i], x[i], y[i]);
      if (descending(i)) active[kept++] = i;
    }
    na = kept;
  }
  uint32_t index[kMaxSliceWalks];
  for (uint32_t j = 0; j < nw; ++j) {
    const uint32_t i = walks[j];
    index[i] = view[i]->finish(c[i], m[i], x[i], y[i]);
  }
  for (uint32_t j = 0; j < nw; ++j) out[walks[j]] = view[walks[j]]->value(index[walks[j]]);
}

// out[i] = t.depth(x[i], y[i], w[i], t.xy_level()) for i < count <= kMaxSliceWalks: the
// slices of one tile.
inline void slice_depths(const SliceTiles& t, uint32_t count, const uint64_t* x, const uint64_t* y, const uint32_t* w,
                         float* out) noexcept {
  const SliceTiles* tiles[kMaxSliceWalks];
  for (uint32_t i = 0; i < count; ++i) tiles[i] = &t;
  slice_depths(tiles, count, x, y, w, out);
}

}  // namespace st

// The skip grid's values against the depth intervals below them (MH 2016 §3.1, in its
// tiled form: the coarse levels are a hierarchy built over the cells' root intervals).
//
// A coarse value of level j < K is stored by a node whose admissible interval lies inside
// the hull [min lo, max hi] of its descendants' intervals, or inherited by a node that
// holds nothing of its own; either way it lies in the hull of the level-K cells below it.
// A cell's entry value answers the cell's root (or, when constant, every texel of it), so
// it lies in the hull of the cell's texels' intervals. Those two facts are what this
// checks, from hulls that either the build journal's cell records give (PackReader's
// verify) or a re-trace of the cells' texels gives (`shadowtile verify --all`, which has
// the scene but, for a finished payloads-only pack, no journal).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "tiles/core/tile_cut_grid.hpp"

namespace st {

// Per-cell interval hulls at the skip level K (row-major, 2^K a side). A cell whose
// `known` is 0 is skipped, and so is every coarse texel above it.
struct CellHulls {
  uint32_t k = 0;
  std::vector<float> lo, hi;
  std::vector<uint8_t> known;

  explicit CellHulls(uint32_t levels);
  size_t side() const { return size_t(1) << k; }
  void set(size_t cx, size_t cy, float l, float h) {
    const size_t i = cy * side() + cx;
    lo[i] = l, hi[i] = h, known[i] = 1;
  }
};

// Throws st::FormatError("<name>: ...") naming the first entry or coarse value that lies
// outside its hull; returns how many values were checked. `grid.levels` must equal
// `hulls.k`.
uint64_t check_coarse_hulls(const CutGrid& grid, const CellHulls& hulls, const std::string& name);

}  // namespace st

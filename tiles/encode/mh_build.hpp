// Construction of a sparse multiresolution hierarchy from a tile of depth intervals
// (MH §3.1): bottom-up (Alg. 2) and top-down (Alg. 1), and the tiled construction that
// stitches the roots of finished tiles into one hierarchy.
#pragma once
#include <cstdint>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/interval.hpp"

namespace st {

enum class MhConstruction : uint8_t { bottom_up = 0, top_down = 1 };

// Builds the hierarchy of a square tile (width == height == 2^n, n <= 14). Intervals must
// satisfy lo <= hi and be finite (throws st::Error otherwise, naming the texel). The
// result satisfies the lossless invariant: for every texel, Hierarchy::depth_at(n, x, y)
// lies in its interval; and every level is a complete map (depth_at(l, x, y) lies within
// [min lo, max hi] of the texels below (l, x, y)). A valued node's [lo, hi] is, from
// bottom-up, exactly the intersection of the intervals of the texels it answers for;
// from top-down, a non-empty part of it. Any value inside is safe either way.
// Bottom-up is the fast one (~25x top-down, bench/construction.cpp).
Hierarchy build_hierarchy(const IntervalTile& tile, MhConstruction method = MhConstruction::bottom_up);

// Tiled construction (MH §3.1 "Tiled construction"): given the hierarchies of a
// 2^k x 2^k grid of equal tiles (row-major, tiles[j * 2^k + i] is tile (i, j)), builds
// the coarse hierarchy over their roots' intervals and returns one hierarchy of depth
// k + n. The tiles' own nodes are moved, not copied.
Hierarchy stitch_tiles(std::vector<Hierarchy>&& tiles, uint32_t grid_level,
                       MhConstruction method = MhConstruction::bottom_up);

}  // namespace st

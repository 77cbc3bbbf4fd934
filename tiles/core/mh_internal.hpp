// Private helpers shared by the MH constructions (mh_build*.cpp); not a public header.
#pragma once
#include <cstdint>

#include "tiles/core/hierarchy.hpp"
#include "tiles/core/interval.hpp"

namespace st::mh_detail {

// A value inside [lo, hi] (lo <= hi, both finite) that is as central as float allows.
// The mean is taken in double: the sum of two finite floats cannot overflow there, and
// rounding is monotone, so 0.5 * (lo + hi) rounded to double and then to float stays in
// [lo, hi] (lo and hi are themselves representable). The clamp only guards against
// flush-to-zero modes. lo == hi (also -0.0 vs 0.0) returns lo unchanged, bit for bit.
inline float safe_midpoint(float lo, float hi) {
  if (!(lo < hi)) return lo;
  float m = float(0.5 * (double(lo) + double(hi)));
  if (m < lo) m = lo;
  if (m > hi) m = hi;
  return m;
}

// Throws st::Error unless the tile is square, a power of two a side (<= 2^14), its data
// has width*height entries and every interval is finite with lo <= hi. Returns log2(side).
uint32_t validate_tile(const IntervalTile& tile);

// MH §3.1 Alg. 2 (bottom-up) and Alg. 1 (top-down) on a validated tile of side 2^n.
Hierarchy build_bottom_up(const IntervalTile& tile, uint32_t n);
Hierarchy build_top_down(const IntervalTile& tile, uint32_t n);

}  // namespace st::mh_detail

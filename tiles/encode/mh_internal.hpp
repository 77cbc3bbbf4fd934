// Private helpers shared by the MH constructions (mh_build*.cpp); not a public header.
#pragma once
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/interval.hpp"

namespace st::mh_detail {

// A value inside [lo, hi] (lo <= hi, both finite) that is as central as float allows.
// The mean is taken in double: the sum of two finite floats cannot overflow there, and
// rounding is monotone, so 0.5 * (lo + hi) rounded to double and then to float stays in
// [lo, hi] (lo and hi are themselves representable); subnormals are exact in double.
// lo == hi returns lo bit for bit ((lo + lo) / 2 is exact); for [-0.0, 0.0] some zero.
// The clamp only guards against flush-to-zero modes. Branch-free: it runs per node.
inline float safe_midpoint(float lo, float hi) {
  float m = float(0.5 * (double(lo) + double(hi)));
  m = m < lo ? lo : m;
  return m > hi ? hi : m;
}

// The float in [lo, hi] (lo <= hi, no NaN) with the most trailing zero bits: 0 if the
// interval holds it, else the common high bits of the ends' bit patterns (monotone in the
// value for each sign) with every lower bit clear; lo == hi returns lo. Any point of an
// admissible interval is lossless (MH 2016 §3.1); the roundest one makes nearly equal
// subtrees equal (the octree's shared blocks, MHOCT.md "Value choice").
inline float roundest_in(float lo, float hi) {
  if (lo <= 0.0f && 0.0f <= hi) return 0.0f;
  if (hi < 0.0f) return -roundest_in(-hi, -lo);
  const uint32_t a = std::bit_cast<uint32_t>(lo), b = std::bit_cast<uint32_t>(hi);
  if (a == b) return lo;
  const int m = 31 - std::countl_zero(a ^ b);  // the highest differing bit: set in b
  return std::bit_cast<float>((b >> m) << m);
}

// The margin central_roundest keeps free on either side of a node's interval, as a
// fraction of its width. Any value inside is lossless (MH 2016 §3.1); a smaller margin
// leaves a wider window, so rounder values (fewer significant mantissa bits), more equal
// blocks and more sharing in the octree (MHOCT.md "Value choice"); a wider one keeps the
// value further from receivers that lie within a surface's interval. 1/8: the middle
// three quarters. Changing it changes the encoder's bytes, not the format.
inline constexpr double kCentralMargin = 0.125;

// The window central_roundest chooses in: [l, h], the middle of [lo, hi] (kCentralMargin
// of the width left out on either side) rounded inward to floats, or the one point
// safe_midpoint(lo, hi) where rounding leaves no float inside (a very narrow interval).
// The octree encoder's subtree merger keeps every merged value inside the intersection
// of the windows it answers for (MHOCT.md "Version 3, merged subtrees measured").
inline void central_window(float lo, float hi, float& l, float& h) {
  const double a = double(lo), b = double(hi), q = kCentralMargin * (b - a);
  l = float(a + q), h = float(b - q);  // rounding is monotone: lo <= l <= h <= hi
  l = l < lo ? lo : l;
  h = h > hi ? hi : h;
  if (!(l <= h)) l = h = safe_midpoint(lo, hi);
}

// The roundest float (roundest_in) of the middle of [lo, hi] (kCentralMargin of the width
// left out on either side): a canonical value that still keeps a margin on either side,
// as the midpoint keeps half, for receivers that lie within a surface's interval (the
// octree's values, MHOCT.md "Value choice"). lo == hi returns lo.
inline float central_roundest(float lo, float hi) {
  float l, h;
  central_window(lo, hi, l, h);
  return roundest_in(l, h);  // lo == hi: the window is [lo, lo]
}

// Hash of a hash-consing key (a node's kind, value bits, mask and its children's ids):
// the octree encoder's and the sharing measure's tables. Keys are compared in full, so
// the hash only spreads them.
struct WordKeyHash {
  template <size_t N>
  size_t operator()(const std::array<uint32_t, N>& k) const noexcept {
    uint64_t h = 0x9E3779B97F4A7C15ull;
    for (uint32_t v : k) h = (h ^ v) * 0xff51afd7ed558ccdull, h ^= h >> 32;
    return size_t(h);
  }
};

// Throws st::Error unless the tile is square, a power of two a side (<= 2^14) and its
// data has width*height entries. Returns log2(side).
uint32_t validate_tile_shape(const IntervalTile& tile);
// Throws st::Error naming the first texel whose interval is not finite with lo <= hi.
void validate_tile_values(const IntervalTile& tile);

// MH §3.1 Alg. 2 (bottom-up) and Alg. 1 (top-down) on a validated tile of side 2^n.
Hierarchy build_bottom_up(const IntervalTile& tile, uint32_t n);
Hierarchy build_top_down(const IntervalTile& tile, uint32_t n);

}  // namespace st::mh_detail

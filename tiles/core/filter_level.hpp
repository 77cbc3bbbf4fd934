// Hierarchical filtering (MH 2016 §3.3): a receiver whose footprint in light space covers
// many finest-level texels is filtered at a coarser level of the hierarchy, where one
// texel covers about that footprint, and blended between the two nearest levels
// (trilinear, like a mip chain) so that the shadow does not pop where the level changes.
//
// Written once for every reader (render, report, the load tester, the client API) and
// for shader mirrors that must answer bit for bit the same. The contract, step by step:
//
//   input   finest: the map's finest level L (<= 20); footprint: the side of the
//           receiver's footprint in finest-level texels, a float32 (NaN, < 1: one texel).
//   bits    b = bit pattern of footprint (IEEE-754 binary32), e = (b >> 23) - 127, the
//           exponent: floor(log2 footprint) for footprint >= 1, by integer operations only.
//   t       float32 with sign 0, exponent 127 and footprint's mantissa (b & 0x7FFFFF),
//           minus 1.0f: footprint / 2^e - 1, in [0, 1). The fraction of the level step
//           (linear within an octave: log2 with a piecewise-linear fraction, exact in
//           float arithmetic, continuous at every power of two).
//   levels  fine = L - e, coarse = L - e - 1. If e >= L (a footprint of the whole map or
//           more, infinity included), fine = coarse = 0 and t = 0.
//   blend   result = a + t * (c - a) with a = pcf at `fine`, c = pcf at `coarse`, float32,
//           one rounding per operation in that order (no fused multiply-add: the C++
//           build uses -std=c++20, whose floating-point contraction is off; a GLSL mirror
//           marks the expression `precise`). t = 0 gives a exactly.
//
// Texel coordinates at each level come from LightSpace::texel_of(level, u, v) (integer
// shifts of the finest texel for the same (u, v)), and a and c are Evaluator::pcf with its
// per-tap semantics, unchanged.
#pragma once
#include <bit>
#include <cstdint>

namespace st {

struct FilterLevels {
  uint32_t fine = 0, coarse = 0;  // coarse == fine - 1, or both 0
  float t = 0;                    // weight of `coarse`
};

inline FilterLevels filter_levels(uint32_t finest, float footprint) {
  if (!(footprint > 1.0f) || finest == 0) return {finest, finest, 0.0f};  // NaN, <= 1 texel
  const uint32_t b = std::bit_cast<uint32_t>(footprint);
  const uint32_t e = (b >> 23) - 127u;  // footprint > 1: the sign bit is 0, e >= 0
  if (e >= finest) return {0, 0, 0.0f};
  const float t = std::bit_cast<float>((b & 0x7FFFFFu) | 0x3F800000u) - 1.0f;
  return {finest - e, finest - e - 1, t};
}

inline float filter_blend(float fine_value, float coarse_value, float t) {
  const float step = coarse_value - fine_value;
  const float scaled = t * step;
  return fine_value + scaled;
}

}  // namespace st

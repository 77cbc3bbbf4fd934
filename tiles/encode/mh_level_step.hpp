// The 2x2 level step of the bottom-up construction (MH §3.1, Alg. 2; the authors' demo,
// lscandolo/Compressed-shadow-maps, QuadtreeCreation.cu). Private to mh_build*.cpp. A portable scalar version (the reference)
// and an SSE2 one (x86-64 baseline) that tests check against each other.
//
// Given the four children's intervals I_c (child order, hierarchy.hpp) and `desc` (bit c
// set iff child c has stored descendants): the parent's interval I is [max lo, min hi]
// if that is non-empty (it covers all four); otherwise the mode by the sweep of MH
// Fig. 3: the child lower bound lying inside the most child intervals (the best depth
// can always be taken at some lower bound), I = the intersection of those children.
// Child c is covered iff I_c contains I; covered children vanish, or turn empty if they
// have descendants; the others are stored with a value.
#pragma once
#include <algorithm>
#include <cfloat>
#include <cstdint>
// ST_MH_SSE2: 1 where SSE2 is there (all x86-64); define ST_MH_NO_SIMD to build and test
// the portable path on x86 too.
#if defined(__SSE2__) && !defined(ST_MH_NO_SIMD)
#define ST_MH_SSE2 1
#include <emmintrin.h>
#else
#define ST_MH_SSE2 0
#endif

namespace st::mh_detail {

// Population count of a 4-bit mask (__builtin_popcount is a libgcc call without -mpopcnt).
inline constexpr uint8_t kPop4[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

struct StepOut {
  float lo, hi;
  uint8_t present;  // children stored (valued or empty)
  uint8_t valued;   // children stored with a value (= not covered)
};

// Among candidates with their covered-children masks, the best: most children covered,
// then (ties) most covered children without descendants, since those vanish while
// covered inner children only turn empty; then the lowest index (deterministic).
inline uint32_t best_candidate(const uint32_t mask[4], uint32_t desc) {
  uint32_t best = 0, best_score = 0;
  for (uint32_t i = 0; i < 4; ++i) {
    uint32_t score = kPop4[mask[i]] * 8u + kPop4[mask[i] & ~desc & 0xFu];
    if (score > best_score) best_score = score, best = i;
  }
  return best;
}

inline StepOut finish_mode(const float lo[4], const float hi[4], const uint32_t mask[4], uint32_t desc) {
  uint32_t best = best_candidate(mask, desc);
  float ih = FLT_MAX;
  for (uint32_t j = 0; j < 4; ++j)
    if (mask[best] >> j & 1) ih = std::min(ih, hi[j]);
  uint32_t valued = ~mask[best] & 0xFu;
  return {lo[best], ih, uint8_t(valued | (mask[best] & desc)), uint8_t(valued)};
}

inline StepOut level_step_scalar(const float lo[4], const float hi[4], uint32_t desc) {
  float l = std::max(std::max(lo[0], lo[1]), std::max(lo[2], lo[3]));
  float h = std::min(std::min(hi[0], hi[1]), std::min(hi[2], hi[3]));
  if (l <= h) return {l, h, uint8_t(desc), 0};
  uint32_t mask[4];
  for (uint32_t i = 0; i < 4; ++i) {
    mask[i] = 0;
    for (uint32_t j = 0; j < 4; ++j) mask[i] |= uint32_t(lo[j] <= lo[i] && lo[i] <= hi[j]) << j;
  }
  return finish_mode(lo, hi, mask, desc);
}

#if ST_MH_SSE2
inline StepOut level_step_sse(__m128 lo, __m128 hi, uint32_t desc) {
  __m128 mx = _mm_max_ps(lo, _mm_shuffle_ps(lo, lo, _MM_SHUFFLE(2, 3, 0, 1)));
  mx = _mm_max_ps(mx, _mm_shuffle_ps(mx, mx, _MM_SHUFFLE(1, 0, 3, 2)));
  __m128 mn = _mm_min_ps(hi, _mm_shuffle_ps(hi, hi, _MM_SHUFFLE(2, 3, 0, 1)));
  mn = _mm_min_ps(mn, _mm_shuffle_ps(mn, mn, _MM_SHUFFLE(1, 0, 3, 2)));
  float l = _mm_cvtss_f32(mx), h = _mm_cvtss_f32(mn);
  if (l <= h) return {l, h, uint8_t(desc), 0};
  uint32_t mask[4];
  const __m128 b[4] = {_mm_shuffle_ps(lo, lo, 0x00), _mm_shuffle_ps(lo, lo, 0x55), _mm_shuffle_ps(lo, lo, 0xAA),
                       _mm_shuffle_ps(lo, lo, 0xFF)};
  for (uint32_t i = 0; i < 4; ++i)
    mask[i] = uint32_t(_mm_movemask_ps(_mm_and_ps(_mm_cmple_ps(lo, b[i]), _mm_cmple_ps(b[i], hi))));
  alignas(16) float los[4], his[4];
  _mm_store_ps(los, lo);
  _mm_store_ps(his, hi);
  return finish_mode(los, his, mask, desc);
}
#endif

}  // namespace st::mh_detail

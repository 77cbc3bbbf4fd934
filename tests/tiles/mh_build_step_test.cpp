// The 2x2 level step of the bottom-up construction (MH §3.1 Alg. 2) and the float-safe
// midpoint, checked against their definitions on random quads of special values.
#include <gtest/gtest.h>

#include <bit>
#include <cfloat>
#include <cmath>
#include <cstring>

#include "tests/tiles/interval_fields.hpp"
#include "tiles/encode/mh_internal.hpp"
#include "tiles/encode/mh_level_step.hpp"

namespace st::mh_detail {
namespace {

// Values that collide often (so intersections and ties are common) plus extremes.
float pick(fields::Rng& rng) {
  static const float kValues[] = {0.0f,    -0.0f, 0.25f,        0.5f,    0.75f,    1.0f,    FLT_TRUE_MIN, FLT_MIN,
                                  -1e30f,  1e30f, -FLT_MAX,     FLT_MAX, 1e-30f,   0.3f,    0.6f,         0.9f};
  if (rng.below(4) == 0) return float(rng.uniform());
  return kValues[rng.below(16)];
}

TEST(MhLevelStep, MatchesItsDefinitionOnRandomQuads) {
  fields::Rng rng(11);
  const int kQuads = fields::small_test_scale() ? 20000 : 200000;
  for (int q = 0; q < kQuads; ++q) {
    float lo[4], hi[4];
    for (int c = 0; c < 4; ++c) {
      float a = pick(rng), b = pick(rng);
      lo[c] = std::min(a, b), hi[c] = std::max(a, b);
    }
    const uint32_t desc = rng.below(16);
    StepOut s = level_step_scalar(lo, hi, desc);
    ASSERT_LE(s.lo, s.hi);
    uint32_t covered = ~uint32_t(s.valued) & 0xF;
    ASSERT_NE(covered, 0u) << "the mode covers at least one child";
    // Covered exactly when the child's interval contains the parent's.
    float ilo = -FLT_MAX, ihi = FLT_MAX;
    for (uint32_t c = 0; c < 4; ++c) {
      bool contains = lo[c] <= s.lo && s.hi <= hi[c];
      ASSERT_EQ(contains, bool(covered >> c & 1)) << "child " << c;
      if (contains) ilo = std::max(ilo, lo[c]), ihi = std::min(ihi, hi[c]);
    }
    // The parent's interval is the intersection of the covered children.
    ASSERT_EQ(s.lo, ilo);
    ASSERT_EQ(s.hi, ihi);
    // Maximal: no depth lies in more child intervals.
    int best = 0;
    for (uint32_t i = 0; i < 4; ++i) {
      int n = 0;
      for (uint32_t j = 0; j < 4; ++j) n += lo[j] <= lo[i] && lo[i] <= hi[j];
      best = std::max(best, n);
    }
    ASSERT_EQ(std::popcount(covered), best);
    // Stored: every uncovered child, and covered children with descendants (empty).
    ASSERT_EQ(uint32_t(s.present), uint32_t(s.valued) | (covered & desc));
#if ST_MH_SSE2
    StepOut v = level_step_sse(_mm_loadu_ps(lo), _mm_loadu_ps(hi), desc);
    ASSERT_EQ(v.lo, s.lo);  // float equality: -0.0 and 0.0 may be picked differently
    ASSERT_EQ(v.hi, s.hi);
    ASSERT_EQ(v.present, s.present);
    ASSERT_EQ(v.valued, s.valued);
#endif
  }
}

TEST(MhLevelStep, TiesPreferCoveringChildrenWithoutDescendants) {
  // Two disjoint pairs: {0, 1} around 0.2, {2, 3} around 0.8. Children 0 and 1 have
  // descendants: covering {2, 3} makes both vanish, covering {0, 1} only empties them.
  float lo[4] = {0.1f, 0.15f, 0.7f, 0.75f}, hi[4] = {0.3f, 0.25f, 0.9f, 0.85f};
  StepOut s = level_step_scalar(lo, hi, 0b0011);
  EXPECT_EQ(s.valued, 0b0011);
  EXPECT_EQ(s.present, 0b0011);
  EXPECT_EQ(s.lo, 0.75f);
  EXPECT_EQ(s.hi, 0.85f);
}

TEST(MhSafeMidpoint, StaysInsideAndIsExactForPoints) {
  fields::Rng rng(12);
  for (int k = 0; k < 200000; ++k) {
    float a = pick(rng), b = pick(rng);
    if (rng.below(3) == 0) {
      uint32_t bits = uint32_t(rng.next());
      std::memcpy(&a, &bits, 4);
      if (!std::isfinite(a)) continue;
    }
    float lo = std::min(a, b), hi = std::max(a, b);
    float m = safe_midpoint(lo, hi);
    ASSERT_TRUE(lo <= m && m <= hi) << lo << " " << hi << " -> " << m;
    float p = safe_midpoint(lo, lo);
    ASSERT_EQ(std::bit_cast<uint32_t>(p), std::bit_cast<uint32_t>(lo));
  }
  EXPECT_EQ(safe_midpoint(-FLT_MAX, FLT_MAX), 0.0f);
  EXPECT_EQ(safe_midpoint(FLT_TRUE_MIN, 2 * FLT_TRUE_MIN), FLT_TRUE_MIN * 2);  // ties to even
  EXPECT_EQ(std::bit_cast<uint32_t>(safe_midpoint(-0.0f, -0.0f)), 0x80000000u);
  EXPECT_EQ(safe_midpoint(1e-30f, 1e30f), 5e29f);
}

}  // namespace
}  // namespace st::mh_detail

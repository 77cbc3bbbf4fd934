// DAG-MH value chunks (§3.3 reconstruction, §3.4, Alg. 2): every decoded value lies in
// its interval bit-exactly, the sweep's base and the fewest factor bits are chosen, and
// the decoder's arithmetic is two roundings, never a fused multiply-add.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "tests/tiles/interval_fields.hpp"
#include "tiles/encode/dagmh_values_encode.hpp"
#include "common/error.hpp"

namespace st::dagmh {
namespace {

float decode(const EncodedValues& e, uint32_t i) {
  return read_value(reinterpret_cast<const uint8_t*>(e.chunks.data()), e.multipliers.data(), i);
}

std::string first_outside(const std::vector<ValueSlot>& slots, const EncodedValues& e) {
  for (uint32_t i = 0; i < slots.size(); ++i) {
    const float v = decode(e, i);
    if (!(slots[i].lo <= v && v <= slots[i].hi))
      return "value " + std::to_string(i) + " = " + std::to_string(v);
  }
  return "";
}

TEST(DagmhValues, AffineValueRoundsTheProductBeforeTheSum) {
  // c_f * i is inexact here, and fma(c_f, i, c_l) differs from the two-rounding result.
  const float c_l = 1.0f, c_f = 0.1f;
  bool found_difference = false;
  for (uint32_t i = 1; i < 100000; ++i) {
    volatile float product = c_f * float(i);
    const float two_roundings = c_l + product;
    ASSERT_EQ(affine_value(c_l, c_f, i), two_roundings) << i;
    found_difference |= std::fma(c_f, float(i), c_l) != two_roundings;
  }
  EXPECT_TRUE(found_difference);  // so the rule matters and the test above can fail
}

TEST(DagmhValues, RandomChunksDecodeInsideTheirIntervals) {
  fields::Rng rng(1);
  for (int mode = 0; mode < 6; ++mode) {
    std::vector<ValueSlot> slots;
    for (int i = 0; i < 32 * 50 + 7; ++i) {
      const float a = float(rng.uniform());
      float w = 0;
      switch (mode) {
        case 0: w = 0; break;                                  // zero-width: open geometry
        case 1: w = float(rng.uniform(0, 1e-6)); break;        // very narrow
        case 2: w = float(rng.uniform(0, 0.1)); break;         // wide
        case 3: w = rng.below(2) ? 0.0f : 0.5f; break;         // mixed
        case 4: w = float(rng.uniform(0, 1e-3)) * float(rng.below(2)); break;
        default: w = 1e-7f * float(rng.below(4)); break;       // a few ulps
      }
      slots.push_back({a, std::min(1.0f, a + w), a});
    }
    const auto e = encode_values(slots);
    EXPECT_EQ(first_outside(slots, e), "") << "mode " << mode;
    EXPECT_EQ(e.chunks.size(), (slots.size() + 31) / 32);
  }
}

TEST(DagmhValues, SpecialValues) {
  const float pool[] = {0.0f, -0.0f, 1.0f, 1e-45f, 2e-45f, 1.17549435e-38f, 1e-30f, -1e-30f,
                        1e30f, -1e30f, 3.4028235e38f, -3.4028235e38f, 0.5f, 0.99999994f,
                        -INFINITY, INFINITY};
  fields::Rng rng(9);
  std::vector<ValueSlot> slots;
  for (int i = 0; i < 32 * 40; ++i) {
    float a = pool[rng.below(16)], b = rng.below(2) ? a : pool[rng.below(16)];
    if (b < a) std::swap(a, b);
    slots.push_back({a, b, a});
  }
  const auto e = encode_values(slots);
  EXPECT_EQ(first_outside(slots, e), "");
}

TEST(DagmhValues, BaseCoversTheMostIntervalsAndFewestBitsAreUsed) {
  // 20 intervals around 0.3 (the sweep's best point) and 12 points on a 1/64 grid.
  std::vector<ValueSlot> slots;
  for (int i = 0; i < 20; ++i) slots.push_back({0.25f + 0.001f * float(i), 0.4f, 0.3f});
  for (int i = 0; i < 12; ++i) {
    const float p = 0.5f + float(i * 3) / 64.0f;
    slots.push_back({p, p, p});
  }
  const auto e = encode_values(slots);
  ASSERT_EQ(e.chunks.size(), 1u);
  const ChunkInfo& c = e.chunks[0];
  EXPECT_TRUE(0.25f + 0.019f <= c.base && c.base <= 0.4f);
  EXPECT_EQ(c.mask, 0xFFFu << 20);
  EXPECT_EQ(c.factor_bits(), 6u);  // 33 steps of 1/64 (the grid's power of two) need 6 bits
  EXPECT_EQ(first_outside(slots, e), "");
}

TEST(DagmhValues, UniformChunksNeedNoMultipliersAndTwoClustersNeedZeroBits) {
  std::vector<ValueSlot> same(32, ValueSlot{0.2f, 0.6f, 0.4f});
  auto e = encode_values(same);
  EXPECT_EQ(e.chunks[0].mask, 0u);
  EXPECT_EQ(e.chunks[0].base, 0.5f);  // the roundest float of [0.2, 0.6] (the bytes deflate best)
  EXPECT_EQ(e.stats.multipliers, 0u);
  std::vector<ValueSlot> two;
  for (int i = 0; i < 32; ++i)
    two.push_back(i % 3 ? ValueSlot{0.1f, 0.2f, 0.15f} : ValueSlot{0.7f + 0.001f * float(i), 0.9f, 0.8f});
  e = encode_values(two);
  EXPECT_EQ(e.chunks[0].factor_bits(), 0u);
  EXPECT_EQ(first_outside(two, e), "");
}

TEST(DagmhValues, ScatteredPointsFallBackToRawFloats) {
  std::vector<ValueSlot> slots;
  fields::Rng rng(4);
  for (int i = 0; i < 32; ++i) {
    const float p = float(std::ldexp(rng.uniform(0.5, 1), int(rng.below(60)) - 30));
    slots.push_back({p, p, p});
  }
  const auto e = encode_values(slots);
  EXPECT_EQ(e.chunks[0].factor_bits(), kRawFactorBits);
  EXPECT_EQ(first_outside(slots, e), "");
  for (uint32_t i = 0; i < 32; ++i) EXPECT_EQ(decode(e, i), slots[i].lo);
}

TEST(DagmhValues, RejectsInvalidIntervals) {
  std::vector<ValueSlot> slots = {{0.5f, 0.4f, 0.45f}};
  EXPECT_THROW(encode_values(slots), Error);
  slots = {{NAN, 0.4f, 0.4f}};
  EXPECT_THROW(encode_values(slots), Error);
}

}  // namespace
}  // namespace st::dagmh

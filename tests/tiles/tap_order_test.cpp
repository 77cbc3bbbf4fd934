// tap_order (tiles/core/tap_order.hpp): a permutation of the batch, in Morton order of the
// taps' texels at the key's precision, stable within a key; batches holding a kernel or a
// level finer than the map are refused untouched.
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "tiles/core/tap_order.hpp"

namespace st {
namespace tap_order_test {

// Morton code of texel (x, y) scaled to `finest`, whole (for the order's check).
uint64_t morton(const PcfQuery& q, uint32_t finest) {
  const uint64_t x = q.x << (finest - q.level), y = q.y << (finest - q.level);
  uint64_t m = 0;
  for (uint32_t b = 0; b < 32; ++b) m |= ((x >> b) & 1) << (2 * b) | ((y >> b) & 1) << (2 * b + 1);
  return m;
}

TEST(TapOrder, IsAPermutationInMortonOrderStableWithinAKey) {
  std::mt19937_64 rng(7);
  for (uint32_t span_bits : {0u, 3u, 8u, 12u, 20u}) {
    for (size_t n : {size_t(1), size_t(2), size_t(100), kTapOrderMax}) {
      const uint32_t finest = 20;
      std::vector<PcfQuery> q(n);
      const uint64_t ox = rng() & ((1u << 20) - (1u << span_bits)), oy = rng() & ((1u << 20) - (1u << span_bits));
      for (auto& t : q) {
        const uint32_t level = 18 + uint32_t(rng() % 3);  // taps of three levels, scaled alike
        const uint64_t mask = span_bits ? (uint64_t(1) << span_bits) - 1 : 0;
        t = PcfQuery{((ox | (rng() & mask)) >> (finest - level)), ((oy | (rng() & mask)) >> (finest - level)), level, 1,
                     0.5f};
      }
      std::vector<uint16_t> order(n, 0xFFFF);
      ASSERT_TRUE(tap_order(q, finest, order.data()));
      std::vector<bool> seen(n, false);
      for (uint16_t i : order) {
        ASSERT_LT(i, n);
        ASSERT_FALSE(seen[i]) << "index " << i << " twice";
        seen[i] = true;
      }
      // The key keeps the 8 highest differing bits of each axis: order by the Morton code
      // with the bits below them cleared, and batch order within equal keys.
      uint64_t differ = 0;
      for (const auto& t : q) differ |= morton(t, finest) ^ morton(q[0], finest);
      const uint32_t high = uint32_t(std::bit_width(differ));
      const uint32_t drop = high > 16 ? (high - 15) & ~1u : 0;  // whole bit pairs below the key
      for (size_t k = 1; k < n; ++k) {
        const uint64_t a = morton(q[order[k - 1]], finest) >> drop, b = morton(q[order[k]], finest) >> drop;
        ASSERT_LE(a, b) << "span " << span_bits << ", n " << n << ", at " << k;
        if (a == b) {
          ASSERT_LT(order[k - 1], order[k]) << "stable within a key";
        }
      }
    }
  }
}

TEST(TapOrder, RefusesKernelsAndLevelsFinerThanTheMap) {
  std::vector<PcfQuery> q(64, PcfQuery{1, 2, 10, 1, 0.5f});
  std::vector<uint16_t> order(q.size(), 7);
  q[40].r = 3;
  EXPECT_FALSE(tap_order(q, 10, order.data()));
  q[40].r = 1, q[41].level = 11;
  EXPECT_FALSE(tap_order(q, 10, order.data()));
  for (uint16_t i : order) EXPECT_EQ(i, 7) << "untouched";
}

}  // namespace tap_order_test
}  // namespace st

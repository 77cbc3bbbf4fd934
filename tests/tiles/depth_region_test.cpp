// Evaluator::depth_region: the region each encoding reports around a texel really shares
// its answer (every texel in it gives the same depth() bits), the value is depth()'s, and
// the regions are not vacuous (a field with constant areas reports regions wider than one
// texel). The client's last-sample cache trusts exactly this (client/remote_map.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <vector>

#include "interval_fields.hpp"
#include "tiles/build/encode.hpp"
#include "tiles/build/mh_build.hpp"

namespace st {
namespace {

uint32_t bits(float f) { return std::bit_cast<uint32_t>(f); }

TEST(DepthRegion, EveryTexelOfTheRegionSharesTheAnswer) {
  const uint32_t L = fields::small_test_scale() ? 6 : 7, side = 1u << L;
  for (const fields::NamedField& f : fields::all_fields(side, 20261203)) {
    const Hierarchy h = build_hierarchy(f.tile);
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      SCOPED_TRACE(f.name + " " + to_string(e));
      const std::vector<uint8_t> bytes = encode(h, e);
      const auto eval = open_encoded(e, bytes);
      fields::Rng rng(uint64_t(e) + 1);
      uint64_t wide = 0;
      for (uint32_t level = 0; level <= L; ++level)
        for (uint32_t k = 0; k < 64; ++k) {
          const uint64_t n = uint64_t(1) << level;
          const uint64_t x = rng.next() & (n - 1), y = rng.next() & (n - 1);
          const DepthRegion r = eval->depth_region(level, x, y);
          ASSERT_LE(r.shift, level);
          ASSERT_EQ(bits(r.value), bits(eval->depth(level, x, y))) << "level " << level << " at " << x << "," << y;
          wide += r.shift > 0;
          const uint64_t s = uint64_t(1) << r.shift, x0 = x & ~(s - 1), y0 = y & ~(s - 1);
          // Up to 16 x 16 texels of the region, its far edges included.
          std::vector<uint64_t> offsets;
          for (uint64_t o = 0; o < s; o += std::max<uint64_t>(1, s / 16)) offsets.push_back(o);
          offsets.push_back(s - 1);
          for (uint64_t j : offsets)
            for (uint64_t i : offsets)
              ASSERT_EQ(bits(eval->depth(level, x0 + i, y0 + j)), bits(r.value))
                  << "level " << level << " region " << x0 << "," << y0 << " shift " << r.shift << " texel " << x0 + i
                  << "," << y0 + j;
        }
      if (f.name == "constant" || f.name == "city") {
        EXPECT_GT(wide, 0u) << "no region wider than a texel";
      }
    }
  }
}

}  // namespace
}  // namespace st

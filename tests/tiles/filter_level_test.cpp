// filter_levels / filter_blend (tiles/core/filter_level.hpp): the levels and the weight
// the header's contract states, continuity at every power of two, the degenerate inputs,
// and Evaluator::pcf_footprint built on them.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/light.hpp"

namespace st {
namespace {

TEST(FilterLevels, OneTexelOrLessNanAndNegativeStayAtTheFinestLevel) {
  for (float f : {0.0f, -3.0f, 0.5f, 1.0f, std::numeric_limits<float>::quiet_NaN()}) {
    const FilterLevels l = filter_levels(14, f);
    EXPECT_EQ(l.fine, 14u) << f;
    EXPECT_EQ(l.coarse, 14u) << f;
    EXPECT_EQ(l.t, 0.0f) << f;
  }
}

TEST(FilterLevels, LevelsAreTheOctaveOfTheFootprintAndTIsItsMantissa) {
  EXPECT_EQ(filter_levels(14, 1.5f).fine, 14u);
  EXPECT_EQ(filter_levels(14, 1.5f).coarse, 13u);
  EXPECT_EQ(filter_levels(14, 1.5f).t, 0.5f);
  EXPECT_EQ(filter_levels(14, 6.0f).fine, 12u);  // [4, 8): two levels up
  EXPECT_EQ(filter_levels(14, 6.0f).t, 0.5f);
  EXPECT_EQ(filter_levels(14, 4.0f).fine, 12u);
  EXPECT_EQ(filter_levels(14, 4.0f).t, 0.0f);
  // The whole map or more (infinity too): the root level.
  for (float f : {16384.0f, 1e30f, std::numeric_limits<float>::infinity()}) {
    const FilterLevels l = filter_levels(14, f);
    EXPECT_EQ(l.fine, 0u);
    EXPECT_EQ(l.coarse, 0u);
    EXPECT_EQ(l.t, 0.0f);
  }
  EXPECT_EQ(filter_levels(0, 8.0f).fine, 0u);
}

TEST(FilterLevels, TheBlendIsContinuousAcrossEveryPowerOfTwo) {
  // Just below 2^e the weight of the coarser level tends to 1; at 2^e that level is the
  // fine one with weight 0: the same level answers on both sides.
  for (uint32_t e = 1; e < 14; ++e) {
    const float p = std::ldexp(1.0f, int(e));
    const FilterLevels below = filter_levels(14, std::nextafter(p, 0.0f));
    const FilterLevels at = filter_levels(14, p);
    EXPECT_EQ(below.coarse, at.fine) << e;
    EXPECT_GT(below.t, 0.99999f) << e;
    EXPECT_LT(below.t, 1.0f) << e;
    EXPECT_EQ(at.t, 0.0f) << e;
  }
  // t grows with the footprint inside an octave.
  float last = -1;
  for (float f = 32.0f; f < 64.0f; f += 0.25f) {
    const FilterLevels l = filter_levels(14, f);
    EXPECT_EQ(l.fine, 9u);
    EXPECT_GT(l.t, last);
    last = l.t;
  }
}

TEST(FilterBlend, EndsAreExactAndTheOrderIsTheStatedOne) {
  EXPECT_EQ(filter_blend(0.36f, 0.8f, 0.0f), 0.36f);
  const float a = 0.36f, c = 0.8f, t = 0.3f;
  const float step = c - a, scaled = t * step;
  EXPECT_EQ(filter_blend(a, c, t), a + scaled);
}

// A map whose every texel of level l holds the value l / 32 (so PCF at a level says which
// level answered: receivers between two levels' values).
class LevelMap final : public Evaluator {
 public:
  uint32_t finest_level() const override { return 10; }
  float depth(uint32_t level, uint64_t, uint64_t) const override { return float(level) / 32.0f; }
};

TEST(PcfFootprint, BlendsTheTwoLevelsTheFootprintPicks) {
  const LevelMap m;
  const float receiver = 8.5f / 32.0f;  // lit at levels >= 9, shadowed at <= 8
  EXPECT_EQ(m.pcf_footprint(0.3, 0.6, receiver, 1.0f, 3), 1.0f);   // level 10
  EXPECT_EQ(m.pcf_footprint(0.3, 0.6, receiver, 2.0f, 3), 1.0f);   // level 9 alone
  EXPECT_EQ(m.pcf_footprint(0.3, 0.6, receiver, 4.0f, 3), 0.0f);   // level 8 alone
  EXPECT_EQ(m.pcf_footprint(0.3, 0.6, receiver, 3.0f, 3), 0.5f);   // 9 and 8, halfway
  EXPECT_EQ(m.pcf_footprint(0.3, 0.6, receiver, 2.5f, 3), 0.75f);  // a quarter of the way
}

}  // namespace
}  // namespace st

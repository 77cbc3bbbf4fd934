// Property tests of the MH constructions (MH §3.1): lossless invariant on every texel,
// complete maps at every level, well-formed hierarchies, exact admissible intervals, on
// every generated field from 1x1 up to 512² (one realistic field at 2048²).
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <limits>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/mh_build_checks.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"

namespace st {
namespace {

using fields::all_fields;

const char* name_of(MhConstruction m) { return m == MhConstruction::bottom_up ? "bottom_up" : "top_down"; }

// Bottom-up stores exact admissible intervals; top-down the (narrower) window it chose in.
void expect_all_properties(const Hierarchy& h, const IntervalTile& tile, const std::string& what, bool exact) {
  ASSERT_EQ(fields::check_well_formed(h), "") << what;
  ASSERT_EQ(fields::check_lossless(h, tile), "") << what;
  ASSERT_EQ(fields::check_levels_complete(h, tile), "") << what;
  ASSERT_EQ(fields::check_admissible(h, tile, exact), "") << what;
}

class MhBuild : public ::testing::TestWithParam<MhConstruction> {
 protected:
  bool exact() const { return GetParam() == MhConstruction::bottom_up; }
};

TEST_P(MhBuild, EveryFieldEverySizeSatisfiesTheInvariants) {
  const uint32_t max_side = fields::small_test_scale() ? 128 : 512;
  for (uint32_t side = 1; side <= max_side; side *= 2)
    for (uint64_t seed : {1ull, 2ull}) {
      for (auto& f : all_fields(side, seed)) {
        std::string what = f.name + " " + std::to_string(side) + "² seed " + std::to_string(seed) + " " +
                           name_of(GetParam());
        Hierarchy h = build_hierarchy(f.tile, GetParam());
        EXPECT_EQ(h.depth, log2_exact(side)) << what;
        expect_all_properties(h, f.tile, what, exact());
        if (HasFatalFailure()) return;
      }
    }
}

TEST_P(MhBuild, RealisticFieldAt2048) {
  const uint32_t side = fields::small_test_scale() ? 256 : 2048;
  IntervalTile tile = fields::scene_field(side, 7);
  Hierarchy h = build_hierarchy(tile, GetParam());
  expect_all_properties(h, tile, std::string("scene 2048² ") + name_of(GetParam()), exact());
  // A realistic field compresses: its open-ground half barely does (every texel is a
  // distinct zero-width depth), the rest does well.
  EXPECT_LT(h.node_count(), size_t(side) * side * 6 / 10);
}

TEST_P(MhBuild, ConstantFieldIsASingleRoot) {
  for (Interval v : {Interval{0.25f, 0.5f}, Interval{0.0f, 0.0f}, Interval{kLitDepth, kLitDepth},
                     Interval{-0.0f, 0.0f}, Interval{FLT_TRUE_MIN, FLT_TRUE_MIN}, Interval{-1e30f, 1e30f}}) {
    IntervalTile tile = fields::constant_field(64, v);
    Hierarchy h = build_hierarchy(tile, GetParam());
    ASSERT_EQ(h.node_count(), 1u);
    EXPECT_EQ(h.levels[0][0].child_mask, 0);
    EXPECT_TRUE(v.contains(h.levels[0][0].value));
    EXPECT_EQ(h.levels[0][0].lo, v.lo);
    EXPECT_EQ(h.levels[0][0].hi, v.hi);
  }
}

TEST_P(MhBuild, ZeroWidthValuesAreStoredBitExactly) {
  // Zero-width intervals admit exactly one float: the value must be that float.
  IntervalTile tile = fields::constant_field(4, {0.5f, 0.5f});
  tile.at(1, 2) = {0.1f, 0.1f};
  tile.at(3, 3) = {FLT_TRUE_MIN, FLT_TRUE_MIN};
  tile.at(0, 0) = {1e30f, 1e30f};
  Hierarchy h = build_hierarchy(tile, GetParam());
  expect_all_properties(h, tile, name_of(GetParam()), exact());
  auto fine = fields::expand_levels(h)[2];
  EXPECT_EQ(fine[morton_encode(1, 2)], 0.1f);
  EXPECT_EQ(fine[morton_encode(3, 3)], FLT_TRUE_MIN);
  EXPECT_EQ(fine[morton_encode(0, 0)], 1e30f);
  EXPECT_EQ(fine[morton_encode(2, 0)], 0.5f);
  // Three stray texels under one 0.5 root: root + at most a few nodes per stray texel.
  EXPECT_LE(h.node_count(), 1u + 3 * 2);
}

TEST_P(MhBuild, RejectsBadInputNamingTheTexel) {
  auto expect_error = [&](const IntervalTile& t, const std::string& needle) {
    try {
      build_hierarchy(t, GetParam());
      ADD_FAILURE() << "no error; expected one naming " << needle;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  IntervalTile t = fields::constant_field(8, {0.1f, 0.2f});
  t.at(3, 5) = {0.3f, 0.2f};
  expect_error(t, "texel (3, 5)");
  expect_error(t, "[0.300000012, 0.200000003]");
  t = fields::constant_field(8, {0.1f, 0.2f});
  t.at(7, 0).lo = std::numeric_limits<float>::quiet_NaN();
  expect_error(t, "texel (7, 0)");
  t = fields::constant_field(8, {0.1f, 0.2f});
  t.at(0, 7).hi = INFINITY;
  expect_error(t, "texel (0, 7)");
  t = fields::constant_field(8, {0.1f, 0.2f});
  t.at(2, 2).lo = -INFINITY;
  expect_error(t, "texel (2, 2)");
  t = fields::constant_field(8, {0.1f, 0.2f});
  t.x0 = 100, t.y0 = 200;
  t.at(1, 1).hi = std::numeric_limits<float>::quiet_NaN();
  expect_error(t, "texel (101, 201)");

  IntervalTile r;
  r.width = 8, r.height = 4, r.data.resize(32);
  expect_error(r, "8x4");
  r.width = r.height = 6, r.data.resize(36);
  expect_error(r, "6x6");
  r.width = r.height = 0, r.data.clear();
  expect_error(r, "0x0");
  r.width = r.height = 8, r.data.resize(10);
  expect_error(r, "holds 10");
  r.width = r.height = 1u << 15, r.data.clear();
  expect_error(r, "exceeds");
}

INSTANTIATE_TEST_SUITE_P(Constructions, MhBuild, ::testing::Values(MhConstruction::bottom_up, MhConstruction::top_down),
                         [](const auto& info) { return std::string(name_of(info.param)); });

}  // namespace
}  // namespace st

// MMH (merged MH quadtree): lossless and within the answering node's interval at every
// level on every generated field, merging of repeated patterns at other depth offsets
// (and at another level), PCF equal to single lookups, pinned header, hostile buffers.
#include <gtest/gtest.h>

#include <cstring>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/mh_quadtree_checks.hpp"
#include "tiles/encode/encode.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/encode/mmh_merge.hpp"

namespace st {
namespace {



// 64² texels, zero-width intervals, all values multiples of 2^-10 (so differences are
// exact in float): the left half holds 8x8 blocks of one random pattern, each block
// shifted by its own depth offset; the right half holds the same pattern upsampled 2x in
// 16x16 blocks (the same subtree shape one level higher), with other offsets.
IntervalTile repeated_patterns(uint64_t seed) {
  fields::Rng rng(seed);
  float pattern[8][8];
  for (auto& row : pattern)
    for (float& v : row) v = float(rng.below(64)) / 1024.0f;
  IntervalTile t;
  t.level = 6;
  t.width = t.height = 64;
  t.data.resize(64 * 64);
  for (uint32_t y = 0; y < 64; ++y)
    for (uint32_t x = 0; x < 64; ++x) {
      float v;
      if (x < 32) {
        const uint32_t block = (y / 8) * 4 + x / 8;
        v = 0.25f + float(block) / 64.0f + pattern[y % 8][x % 8];
      } else {
        const uint32_t block = (y / 16) * 2 + (x - 32) / 16;
        v = 0.125f + float(block) / 32.0f + pattern[(y % 16) / 2][(x % 16) / 2];
      }
      t.at(x, y) = {v, v};
    }
  return t;
}

// 64² texels of independent random zero-width depths, except one 8x8 block of a dyadic
// pattern at (8, 8) (a subtree of height 3 rooted at level 3) and the same pattern
// upsampled 2x in a 16x16 block at (32, 48) at another depth offset (height 3, rooted at
// level 2): the two can only share a block across levels.
IntervalTile pattern_at_two_levels(uint64_t seed) {
  fields::Rng rng(seed);
  float pattern[8][8];
  for (auto& row : pattern)
    for (float& v : row) v = float(rng.below(64)) / 1024.0f;
  IntervalTile t;
  t.level = 6;
  t.width = t.height = 64;
  t.data.resize(64 * 64);
  for (uint32_t y = 0; y < 64; ++y)
    for (uint32_t x = 0; x < 64; ++x) {
      float v = float(rng.uniform(0.0, 0.9));
      if (x >= 8 && x < 16 && y >= 8 && y < 16) v = 0.25f + pattern[y - 8][x - 8];
      if (x >= 32 && x < 48 && y >= 48) v = 0.625f + pattern[(y - 48) / 2][(x - 32) / 2];
      t.at(x, y) = {v, v};
    }
  return t;
}

void expect_mmh_ok(const Hierarchy& h, const IntervalTile& tile, const std::string& what) {
  const auto bytes = encode_mmh(h);
  const auto ev = open_mmh(bytes);
  ASSERT_EQ(mhtest::check_within_answering_intervals(*ev, h), "") << what;
  ASSERT_EQ(mhtest::check_lossless_all_levels(*ev, tile), "") << what;
  EXPECT_LE(bytes.size(), encode_mh(h).size()) << what;
}

TEST(Mmh, EveryFieldEverySizeIsLosslessAtEveryLevel) {
  const uint32_t max_side = fields::small_test_scale() ? 64 : 256;
  for (uint32_t side = 1; side <= max_side; side *= 2)
    for (uint64_t seed : {1ull, 2ull})
      for (auto& f : fields::all_fields(side, seed)) {
        const Hierarchy h = build_hierarchy(f.tile);
        expect_mmh_ok(h, f.tile, f.name + " " + std::to_string(side) + "² seed " + std::to_string(seed));
        if (HasFatalFailure()) return;
      }
}

TEST(Mmh, TopDownHierarchiesToo) {
  const uint32_t side = fields::small_test_scale() ? 64 : 128;
  for (auto& f : fields::all_fields(side, 3)) {
    const Hierarchy h = build_hierarchy(f.tile, MhConstruction::top_down);
    expect_mmh_ok(h, f.tile, f.name + " top-down");
    if (HasFatalFailure()) return;
  }
}

TEST(Mmh, RepeatedPatternsAtOtherDepthOffsetsMerge) {
  for (uint64_t seed : {1ull, 2ull, 3ull}) {
    const IntervalTile tile = repeated_patterns(seed);
    const Hierarchy h = build_hierarchy(tile);
    const auto mh = encode_mh(h);
    const auto mmh = encode_mmh(h);
    // The quadrants share blocks, and inside the shared blocks the shifted copies of
    // the pattern share again (nested merges): about 11x smaller.
    EXPECT_LT(mmh.size() * 6, mh.size()) << "seed " << seed << ": MH " << mh.size() << " MMH " << mmh.size();
    EXPECT_LT(st::load_le<uint32_t>(mmh.data() + mhq::kOffNodeCount) * 6, h.node_count());
    const auto ev = open_mmh(mmh);
    ASSERT_EQ(mhtest::check_within_answering_intervals(*ev, h), "");
    ASSERT_EQ(mhtest::check_lossless_all_levels(*ev, tile), "");
  }
}

TEST(Mmh, ABlockIsSharedAcrossLevels) {
  for (uint64_t seed : {1ull, 2ull}) {
    const IntervalTile tile = pattern_at_two_levels(seed);
    const Hierarchy h = build_hierarchy(tile);
    mhq::MergeStats stats;
    const auto t = mhq::flatten(h, true);
    const auto bytes = mhq::serialize(t, mhq::plan_mmh(t, {}, &stats));
    EXPECT_GE(stats.cross_level_merges, 1u) << "seed " << seed;
    EXPECT_GE(stats.nodes_removed, 40u) << "seed " << seed;
    const auto ev = open_mmh(bytes);
    ASSERT_EQ(mhtest::check_within_answering_intervals(*ev, h), "");
    ASSERT_EQ(mhtest::check_lossless_all_levels(*ev, tile), "");
    ASSERT_EQ(mhtest::check_pcf(*ev, 6, {{12, 12}, {40, 56}, {15, 8}, {47, 63}}, {0.3f, 0.7f, 0.26f}), "");
  }
}

TEST(Mmh, LargeTreesScaleOffsetsAndStayLossless) {
  // 512² independent intervals: scaled offsets near the root, merges further down.
  const IntervalTile tile = fields::uniform_field(512, 9);
  const Hierarchy h = build_hierarchy(tile);
  const auto bytes = encode_mmh(h);
  uint32_t scaled = 0;
  for (uint32_t l = 0; l < 10; ++l) scaled += bytes[mhq::kOffShifts + l] != 0;
  EXPECT_GT(scaled, 0u);
  EXPECT_LT(bytes.size(), encode_mh(h).size());
  const auto ev = open_mmh(bytes);
  EXPECT_EQ(fields::first_violation(tile, [&](uint32_t x, uint32_t y) { return ev->depth(9, x, y); }), "");
}

TEST(Mmh, NoRepeatsNoMergesAndStillExact) {
  // A zero window forbids merging: MMH then differs from MH only in its values.
  const IntervalTile tile = fields::city_field(64, 5);
  const Hierarchy h = build_hierarchy(tile);
  const auto t = mhq::flatten(h, true);
  mhq::MergeOptions none;
  none.window = 0;
  mhq::MergeStats stats;
  const auto bytes = mhq::serialize(t, mhq::plan_mmh(t, none, &stats));
  EXPECT_EQ(stats.merges, 0u);
  EXPECT_EQ(bytes.size(), encode_mh(h).size());
  const auto ev = open_mmh(bytes);
  EXPECT_EQ(mhtest::check_within_answering_intervals(*ev, h), "");
}

TEST(Mmh, PcfEqualsTheAverageOfSingleLookups) {
  const uint32_t side = fields::small_test_scale() ? 64 : 256;
  std::vector<IntervalTile> tiles = {fields::scene_field(side, 3), fields::special_values_field(side, 4),
                                     repeated_patterns(5)};
  for (auto& f : tiles) {
    const Hierarchy h = build_hierarchy(f);
    const auto bytes = encode_mmh(h);
    const auto ev = open_mmh(bytes);
    for (uint32_t level : {f.level, f.level - 1, f.level - 3, 1u, 0u}) {
      const uint64_t s = uint64_t(1) << level;
      std::vector<std::pair<uint64_t, uint64_t>> at = {{0, 0}, {s - 1, s - 1}, {s - 1, 0}, {s / 2, s / 2},
                                                        {s / 3, 2 * s / 3}, {2, s - 3}};
      std::vector<float> receivers = {-1.0f, 0.25f, 0.5f, 1.0f};
      for (auto [x, y] : at) receivers.push_back(ev->depth(level, x, y));
      ASSERT_EQ(mhtest::check_pcf(*ev, level, at, receivers), "");
    }
  }
}

TEST(Mmh, HeaderAndRelativeValuesArePinned) {
  HNode root, a, b;
  root.value = 0.5f, root.lo = 0.25f, root.hi = 0.75f, root.has_value = 1, root.child_mask = 0b0101;
  a.morton = 0, a.value = a.lo = a.hi = 0.25f, a.has_value = 1;
  b.morton = 2, b.value = b.lo = b.hi = 1e-30f, b.has_value = 1;  // 0.5 + (1e-30 - 0.5) != 1e-30
  Hierarchy h;
  h.depth = 1;
  h.levels = {{root}, {a, b}};
  const auto bytes = encode_mmh(h);
  ASSERT_EQ(bytes.size(), 36u);
  EXPECT_EQ(std::memcmp(bytes.data(), "STMM", 4), 0);
  EXPECT_EQ(bytes[6], 2);
  EXPECT_EQ(bytes[7], mhq::kFlagRelative);
  EXPECT_EQ(st::load_le<uint32_t>(bytes.data() + 8), 3u);
  EXPECT_EQ(st::load_le<uint32_t>(bytes.data() + 12), 36u);
  // Root word: mask 0x11, pad = absolute flag of slot 2 (bit 2 of the pad's low nibble),
  // shift 0, offset 2.
  EXPECT_EQ(st::load_le<uint32_t>(bytes.data() + 20), 0x00020411u);
  EXPECT_EQ(st::load_le<uint32_t>(bytes.data() + 24), mhq::float_bits(0.5f));    // the root: absolute
  EXPECT_EQ(st::load_le<uint32_t>(bytes.data() + 28), mhq::float_bits(-0.25f));  // 0.25 relative to 0.5
  EXPECT_EQ(st::load_le<uint32_t>(bytes.data() + 32), mhq::float_bits(1e-30f));  // absolute
  const auto ev = open_mmh(bytes);
  EXPECT_EQ(ev->depth(1, 0, 0), 0.25f);
  EXPECT_EQ(ev->depth(1, 0, 1), 1e-30f);
  EXPECT_EQ(ev->depth(1, 1, 1), 0.5f);
  EXPECT_EQ(ev->depth(0, 0, 0), 0.5f);

  auto bad = bytes;
  bad[21] = 0x02;  // absolute flag on slot 1, which holds no child
  EXPECT_THROW(open_mmh(bad), FormatError);
  EXPECT_EQ(open_mh(bytes)->depth(1, 0, 1), 1e-30f);  // open_mh reads MMH too
  EXPECT_THROW(open_mmh(encode_mh(h)), FormatError);
}

TEST(Mmh, HostileBuffersFailCleanly) {
  for (auto& tile : {fields::scene_field(32, 11), repeated_patterns(7), pattern_at_two_levels(3)}) {
    const auto bytes = encode_mmh(build_hierarchy(tile));
    std::string err;
    mhtest::check_hostile(bytes, [](std::span<const uint8_t> b) { return open_mmh(b); },
                          fields::small_test_scale() ? 200 : 1500, 23, err);
    EXPECT_EQ(err, "");
  }
}

}  // namespace
}  // namespace st

// MH quadtree (MH §3.2, §3.3): round trips bit-identical to the hierarchy at every level
// on every generated field, lossless and complete levels, PCF equal to single lookups,
// pinned header offsets, offset scaling, hostile buffers.
#include <gtest/gtest.h>

#include <bit>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <limits>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/mh_quadtree_checks.hpp"
#include "tiles/encode/encode.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/mh_quadtree_format.hpp"

namespace st {
namespace {



HNode valued(uint64_t morton, float v, uint8_t mask = 0) {
  HNode n;
  n.morton = morton;
  n.value = n.lo = n.hi = v;
  n.has_value = 1;
  n.child_mask = mask;
  return n;
}

HNode empty(uint64_t morton, uint8_t mask) {
  HNode n;
  n.morton = morton;
  n.child_mask = mask;
  return n;
}

// Root 0.5 with children 0 (0.25) and 2 (0.75) at level 1.
Hierarchy tiny() {
  Hierarchy h;
  h.depth = 1;
  h.levels = {{valued(0, 0.5f, 0b0101)}, {valued(0, 0.25f), valued(2, 0.75f)}};
  return h;
}

TEST(MhQuadtree, EveryFieldEverySizeMatchesTheHierarchyAtEveryLevel) {
  const uint32_t max_side = fields::small_test_scale() ? 64 : 256;
  for (uint32_t side = 1; side <= max_side; side *= 2)
    for (uint64_t seed : {1ull, 2ull})
      for (auto& f : fields::all_fields(side, seed)) {
        const std::string what = f.name + " " + std::to_string(side) + "² seed " + std::to_string(seed);
        const Hierarchy h = build_hierarchy(f.tile);
        const auto bytes = encode_mh(h);
        const auto ev = open_mh(bytes);
        ASSERT_EQ(mhtest::check_equals_hierarchy(*ev, h), "") << what;
        ASSERT_EQ(mhtest::check_lossless_all_levels(*ev, f.tile), "") << what;
        EXPECT_EQ(st::load_le<uint32_t>(bytes.data() + mhq::kOffNodeCount), h.node_count()) << what;
      }
}

// A lookup written from tiles/core/MHQUAD.md alone (header, tree words, block formula,
// traversal), without the reader: from a node at level l the child slot is bit
// `level - l - 1` of x and y. `bit_of_child_level` = false reads "bit level - l" with l
// the current node's level instead, the off-by-one the text once invited.
float depth_from_the_spec(std::span<const uint8_t> b, uint32_t level, uint64_t x, uint64_t y,
                          bool bit_of_child_level = true) {
  const uint32_t levels = b[6];
  const uint8_t flags = b[7];
  const size_t tree = 16 + ((levels + 3) & ~3u);
  auto word = [&](uint64_t i) { return st::load_le<uint32_t>(b.data() + tree + 4 * i); };
  auto as_float = [](uint32_t w) {
    float f;
    std::memcpy(&f, &w, 4);
    return f;
  };
  if (flags & 1) return as_float(word(0));  // the root is a leaf
  uint64_t pos = 0, value_word = 1;          // else an inner node: node word, then float
  uint32_t code = 3;
  for (uint32_t l = 0; l < level && code != 1; ++l) {
    const uint32_t bit = bit_of_child_level ? level - l - 1 : level - l;
    const uint32_t c = uint32_t((x >> bit) & 1) | uint32_t(((y >> bit) & 1) << 1);
    const uint32_t w = word(pos), mask = w & 0xff;
    const uint32_t child_code = (mask >> (2 * c)) & 3;
    if (child_code == 0) break;  // no child: the last valued node answers
    const uint32_t s = b[16 + l], off = w >> 16;
    const uint64_t block = ((pos >> s) + off) << s;
    pos = block + uint32_t(std::popcount(mask & ((1u << (2 * c)) - 1)));
    code = child_code;
    if (code == 1) value_word = pos;       // leaf: its float is its word
    else if (code == 3) value_word = pos + 1;  // inner: node word, then float
  }
  return as_float(word(value_word));
}

TEST(MhQuadtree, TheSpecAloneDecodesEveryTexelAtEveryLevel) {
  auto bits = [](float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
  };
  uint64_t misread = 0, texels = 0;
  auto check = [&](const IntervalTile& tile, const std::string& what) {
    const auto bytes = encode_mh(build_hierarchy(tile));
    const auto ev = open_mh(bytes);
    const uint32_t finest = ev->finest_level();
    for (uint32_t level = 0; level <= finest + 2; ++level)  // two levels finer than the tile too
      for (uint64_t y = 0; y < (uint64_t(1) << level); ++y)
        for (uint64_t x = 0; x < (uint64_t(1) << level); ++x) {
          const float want = ev->depth(level, x, y);
          ASSERT_EQ(bits(depth_from_the_spec(bytes, level, x, y)), bits(want))
              << what << " level " << level << " (" << x << ", " << y << ")";
          if (level == finest && level > 0) {
            ++texels;
            misread += bits(depth_from_the_spec(bytes, level, x, y, false)) != bits(want);
          }
          // Finer than the tile: the texel above it at the finest level answers.
          if (level > finest) {
            ASSERT_EQ(bits(want), bits(ev->depth(finest, x >> (level - finest), y >> (level - finest))));
          }
        }
  };
  const uint32_t side = fields::small_test_scale() ? 32 : 64;
  for (uint32_t s = 1; s <= side; s *= 2)
    for (auto& f : fields::all_fields(s, 3)) check(f.tile, f.name + " " + std::to_string(s));
  // Offsets scaled at the top levels: the block formula with shifts != 0.
  const IntervalTile big = fields::uniform_field(512, 9);
  {
    const auto bytes = encode_mh(build_hierarchy(big));
    uint32_t scaled = 0;
    for (uint32_t l = 0; l < 10; ++l) scaled += bytes[mhq::kOffShifts + l] != 0;
    ASSERT_GT(scaled, 0u) << "expected a scaled level";
    const auto ev = open_mh(bytes);
    const uint32_t finest = ev->finest_level();
    for (uint64_t i = 0; i < 20000; ++i) {
      const uint64_t x = (i * 2654435761u) & ((1u << finest) - 1), y = (i * 40503u + 7) & ((1u << finest) - 1);
      ASSERT_EQ(bits(depth_from_the_spec(bytes, finest, x, y)), bits(ev->depth(finest, x, y))) << x << " " << y;
    }
  }
  EXPECT_GT(misread, texels / 4) << "the off-by-one reading should fail visibly";
}

TEST(MhQuadtree, HeaderAndNodeWordsArePinned) {
  static_assert(mhq::kOffMagic == 0 && mhq::kOffVersion == 4 && mhq::kOffLevels == 6 && mhq::kOffFlags == 7);
  static_assert(mhq::kOffNodeCount == 8 && mhq::kOffByteSize == 12 && mhq::kOffShifts == 16);
  static_assert(mhq::tree_offset(1) == 20 && mhq::tree_offset(4) == 20 && mhq::tree_offset(5) == 24);
  static_assert(mhq::tree_offset(21) == 40);
  const auto b = encode_mh(tiny());
  ASSERT_EQ(b.size(), 36u);
  EXPECT_EQ(std::memcmp(b.data(), "STMH", 4), 0);
  EXPECT_EQ(b[4], 1);  // version, little-endian u16
  EXPECT_EQ(b[5], 0);
  EXPECT_EQ(b[6], 2);  // levels
  EXPECT_EQ(b[7], 0);  // flags: inner root, absolute values
  EXPECT_EQ(st::load_le<uint32_t>(b.data() + 8), 3u);
  EXPECT_EQ(st::load_le<uint32_t>(b.data() + 12), 36u);
  for (size_t i = 16; i < 20; ++i) EXPECT_EQ(b[i], 0) << i;  // shifts 0, 0 and padding
  // Root: mask child0 = leaf (01), child2 = leaf (01 << 4); pad 0; block at word 2 = off 2.
  EXPECT_EQ(st::load_le<uint32_t>(b.data() + 20), 0x00020011u);
  EXPECT_EQ(st::load_le<uint32_t>(b.data() + 24), mhq::float_bits(0.5f));
  EXPECT_EQ(st::load_le<uint32_t>(b.data() + 28), mhq::float_bits(0.25f));
  EXPECT_EQ(st::load_le<uint32_t>(b.data() + 32), mhq::float_bits(0.75f));

  Hierarchy leaf_root;
  leaf_root.depth = 3;
  leaf_root.levels = {{valued(0, 0.125f)}, {}, {}, {}};
  const auto c = encode_mh(leaf_root);
  ASSERT_EQ(c.size(), 24u);
  EXPECT_EQ(c[6], 4);
  EXPECT_EQ(c[7], mhq::kFlagRootLeaf);
  const auto ev = open_mh(c);
  EXPECT_EQ(ev->finest_level(), 3u);
  EXPECT_EQ(ev->depth(3, 7, 5), 0.125f);
  EXPECT_EQ(ev->pcf(3, 0, 0, 9, 0.125f), 1.0f);
  EXPECT_EQ(ev->pcf(3, 0, 0, 9, 0.2f), 0.0f);
}

TEST(MhQuadtree, SpecialValuesKeepTheirBits) {
  const float sub = std::numeric_limits<float>::denorm_min();
  const float vals[4] = {-0.0f, sub, FLT_MAX, -1e30f};
  Hierarchy h;
  h.depth = 2;
  h.levels.resize(3);
  h.levels[0] = {valued(0, 0.0f, 0b1111)};
  h.levels[1] = {valued(0, vals[0]), empty(1, 0b1000), valued(2, vals[2], 0b0001), valued(3, vals[3])};
  h.levels[2] = {valued(7, vals[1]), valued(8, 1.0f)};
  const auto bytes = encode_mh(h);  // the evaluator reads these in place
  const auto ev = open_mh(bytes);
  EXPECT_EQ(mhtest::check_equals_hierarchy(*ev, h), "");
  EXPECT_TRUE(std::signbit(ev->depth(1, 0, 0)));
  EXPECT_EQ(ev->depth(2, 3, 1), sub);  // morton 7 = (3, 1)
  EXPECT_EQ(ev->depth(2, 2, 1), 0.0f);  // under the empty node: the root answers
  EXPECT_EQ(ev->depth(2, 0, 2), 1.0f);
  EXPECT_EQ(ev->depth(2, 1, 2), FLT_MAX);
}

TEST(MhQuadtree, PcfEqualsTheAverageOfSingleLookups) {
  const uint32_t side = fields::small_test_scale() ? 64 : 256;
  for (auto& f : {fields::scene_field(side, 3), fields::city_field(side, 4), fields::uniform_field(side, 5)}) {
    const Hierarchy h = build_hierarchy(f);
    const auto bytes = encode_mh(h);
    const auto ev = open_mh(bytes);
    for (uint32_t level : {f.level, f.level - 1, f.level - 3, 1u, 0u}) {
      const uint64_t s = uint64_t(1) << level;
      std::vector<std::pair<uint64_t, uint64_t>> at = {{0, 0}, {s - 1, s - 1}, {0, s - 1}, {s / 2, s / 2},
                                                        {s / 3, 2 * s / 3}, {1, s - 2}, {s - 1, s / 2}};
      std::vector<float> receivers = {0.0f, 0.3f, 0.5f, 0.99f, 1.0f};
      for (auto [x, y] : at) receivers.push_back(ev->depth(level, x, y));
      ASSERT_EQ(mhtest::check_pcf(*ev, level, at, receivers), "");
    }
  }
}

TEST(MhQuadtree, LargeTreesScaleTheirOffsets) {
  // 512² independent intervals: about 280k words, so level-1 offsets exceed 16 bits.
  const IntervalTile tile = fields::uniform_field(512, 9);
  const Hierarchy h = build_hierarchy(tile);
  const auto bytes = encode_mh(h);
  uint32_t scaled = 0;
  for (uint32_t l = 0; l < 10; ++l) scaled += bytes[mhq::kOffShifts + l] != 0;
  EXPECT_GT(scaled, 0u);
  EXPECT_EQ(bytes[mhq::kOffShifts + 9], 0) << "the finest level has no children";
  const auto ev = open_mh(bytes);
  EXPECT_EQ(mhtest::check_equals_hierarchy(*ev, h), "");
  // Padding stays small: the tree is within 1% of its node words.
  const uint64_t node_words = h.node_count() + [&] {
    size_t inner = 0;
    for (auto& l : h.levels)
      for (auto& n : l) inner += n.has_value && n.child_mask;
    return inner;
  }();
  EXPECT_LE(bytes.size() - mhq::tree_offset(10), node_words * 4 * 101 / 100);
}

TEST(MhQuadtree, HostileBuffersFailCleanly) {
  const Hierarchy h = build_hierarchy(fields::scene_field(32, 11));
  const auto bytes = encode_mh(h);
  std::string err;
  const size_t opened = mhtest::check_hostile(bytes, [](std::span<const uint8_t> b) { return open_mh(b); },
                                              fields::small_test_scale() ? 300 : 2000, 17, err);
  EXPECT_EQ(err, "");
  EXPECT_LT(opened, 2000u);
}

TEST(MhQuadtree, ErrorsNameTheFieldAndOffset) {
  auto b = encode_mh(tiny());
  auto expect_error = [](std::vector<uint8_t> bad, const std::string& needle) {
    try {
      open_mh(bad);
      ADD_FAILURE() << "accepted, wanted " << needle;
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  auto bad = b;
  bad[20 + 2] = 0, bad[20 + 3] = 0;  // root child offset 0
  expect_error(bad, "child offset at byte 20");
  bad = b;
  bad[4] = 2;
  expect_error(bad, "version at byte 4");
  bad = b;
  bad[21] = 1;  // pad byte
  expect_error(bad, "pad byte at byte 20");
  bad = b;
  bad[8] = 4;
  expect_error(bad, "node_count at byte 8");
  bad = b;
  bad[20] = 0x31;  // child 2 claims to be an inner node: runs past the end
  expect_error(bad, "children block past the end");
  bad = b;
  std::memcpy(bad.data() + 28, "\x00\x00\xc0\x7f", 4);  // NaN leaf
  expect_error(bad, "value at byte 28");
  // open_mh reads MMH buffers too; open_mmh only MMH.
  const auto mmh = encode_mmh(tiny());
  EXPECT_EQ(open_mh(mmh)->depth(1, 0, 1), 0.75f);
  try {
    open_mmh(b);
    ADD_FAILURE() << "open_mmh accepted an MH buffer";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("this is an MH buffer"), std::string::npos) << e.what();
  }
}

TEST(MhQuadtree, MalformedHierarchiesAreRejected) {
  Hierarchy h = tiny();
  h.levels[1][1].morton = 1;  // child mask says slot 2
  EXPECT_THROW(encode_mh(h), Error);
  h = tiny();
  h.levels[1][0].has_value = 0;  // neither valued nor with children
  EXPECT_THROW(encode_mh(h), Error);
  h = tiny();
  h.levels[0][0].value = NAN;
  EXPECT_THROW(encode_mh(h), Error);
  h = tiny();
  h.levels[1].pop_back();
  EXPECT_THROW(encode_mh(h), Error);
}

}  // namespace
}  // namespace st

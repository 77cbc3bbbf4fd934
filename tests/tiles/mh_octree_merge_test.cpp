// The octree encoder's subtree merger (tiles/encode/mh_octree_merge.hpp, MHOCT.md
// "Version 3, merged subtrees measured"): compatible but unequal subtrees end up sharing one block,
// incompatible ones do not, and on random stacks every texel of every level of every slice
// decodes inside the interval (and the central window) of the node the builder answers
// it with.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <string>

#include "common/hash.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/encode/mh_internal.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/core/mh_octree.hpp"

namespace st {
namespace {

const OctEncodeOptions kMerge{.merge = true};  // the merger is off by default

// The deepest valued node on the path to (l, x, y, w): the node whose value depth_at
// answers (the builder's interval for that texel of level l).
const OctNode& answering(const OctHierarchy& h, uint32_t l, uint64_t x, uint64_t y, uint64_t w) {
  const OctNode* v = &h.levels[0][0];
  for (uint32_t j = 1; j <= l && j < h.levels.size(); ++j) {
    const uint64_t code = oct_code(h.geo, j, x >> (h.geo.xy_bits(l) - h.geo.xy_bits(j)),
                                   y >> (h.geo.xy_bits(l) - h.geo.xy_bits(j)), w >> (h.geo.w_bits(l) - h.geo.w_bits(j)));
    const auto& lv = h.levels[j];
    auto it = std::lower_bound(lv.begin(), lv.end(), code, [](const OctNode& n, uint64_t c) { return n.code < c; });
    if (it == lv.end() || it->code != code) break;
    if (it->has_value) v = &*it;
  }
  return *v;
}

// "" when every texel of every level q <= n of every slice decodes inside the interval
// and the central window of the node the hierarchy answers it with, else the first
// failure.
std::string first_level_violation(const OctHierarchy& h, const MhOctree& t) {
  for (uint32_t q = 0; q <= h.geo.n; ++q) {
    const uint32_t ol = h.geo.level_of_xy(q);
    for (uint32_t w = 0; w < h.slices; ++w)
      for (uint64_t y = 0; y < (uint64_t(1) << q); ++y)
        for (uint64_t x = 0; x < (uint64_t(1) << q); ++x) {
          const OctNode& nd = answering(h, ol, x, y, w >> (h.geo.k - h.geo.w_bits(ol)));
          float wl = 0, wh = 0;
          mh_detail::central_window(nd.lo, nd.hi, wl, wh);
          const float v = t.depth(x, y, w, q);
          if (!(nd.lo <= v && v <= nd.hi && wl <= v && v <= wh))
            return "level " + std::to_string(q) + " texel (" + std::to_string(x) + ", " + std::to_string(y) +
                   ") slice " + std::to_string(w) + ": " + std::to_string(v) + " outside [" + std::to_string(nd.lo) +
                   ", " + std::to_string(nd.hi) + "] or its window [" + std::to_string(wl) + ", " + std::to_string(wh) +
                   "]";
        }
  }
  return "";
}

// One 4x4 slice, all 0.5 but texels (0, 0) and (2, 0): quadrants 0 and 1 are empty nodes
// with one leaf each in slot 0 (MHOCT.md's shared-block example), here with unequal
// intervals whose central windows meet.
IntervalStack two_leaves(Interval a, Interval b) {
  IntervalStack s{2, 1, std::vector<Interval>(16, Interval{0.5f, 0.5f})};
  s.at(0, 0, 0) = a;
  s.at(2, 0, 0) = b;
  return s;
}

TEST(MhOctreeMerge, CompatibleUnequalSubtreesShareOneBlock) {
  // Central windows [0.2125, 0.2875] and [0.2525, 0.3275]: alone the leaves store their
  // windows' roundest floats, 0.25 and 0.3125; merged, the roundest of the intersection.
  const IntervalStack s = two_leaves({0.2f, 0.3f}, {0.24f, 0.34f});
  const OctHierarchy h = build_octree(s);
  ASSERT_EQ(h.levels[2].size(), 2u);
  ASSERT_NE(h.levels[2][0].value, h.levels[2][1].value);
  OctEncodeStats off_st, on_st;
  const std::vector<uint8_t> apart = encode_octree(h, &off_st);  // the default: no merging
  const std::vector<uint8_t> merged = encode_octree(h, &on_st, kMerge);
  EXPECT_EQ(apart.size(), 48u);
  EXPECT_EQ(off_st.shared_blocks, 0u);
  EXPECT_EQ(merged.size(), 44u);  // the leaf's block once, as for equal leaves
  EXPECT_EQ(on_st.shared_blocks, 1u);
  EXPECT_EQ(on_st.merges, 1u);
  EXPECT_EQ(on_st.merged_values, 2u);
  const MhOctree t = MhOctree::open(merged);
  EXPECT_EQ(t.node_count(), 4u);
  EXPECT_EQ(t.depth(0, 0, 0, 2), 0.28125f);
  EXPECT_EQ(t.depth(2, 0, 0, 2), 0.28125f);
  EXPECT_EQ(stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint64_t w) { return t.depth(x, y, uint32_t(w), 2); }),
            "");
  EXPECT_EQ(first_level_violation(h, t), "");
  // Without merging the values are the hierarchy's, bit for bit.
  const MhOctree u = MhOctree::open(apart);
  EXPECT_EQ(u.depth(0, 0, 0, 2), h.levels[2][0].value);
  EXPECT_EQ(u.depth(2, 0, 0, 2), h.levels[2][1].value);
}

TEST(MhOctreeMerge, SubtreesWhoseWindowsDoNotMeetStayApart) {
  // The intervals meet ([0.29, 0.3]) but their central windows ([0.2125, 0.2875] and
  // [0.3025, 0.3775]) do not.
  const OctHierarchy h = build_octree(two_leaves({0.2f, 0.3f}, {0.29f, 0.39f}));
  OctEncodeStats st;
  const std::vector<uint8_t> bytes = encode_octree(h, &st, kMerge);
  EXPECT_EQ(bytes.size(), 48u);
  EXPECT_EQ(st.merges, 0u);
  EXPECT_EQ(st.merged_values, 0u);
  const MhOctree t = MhOctree::open(bytes);
  EXPECT_EQ(t.depth(0, 0, 0, 2), h.levels[2][0].value);
  EXPECT_EQ(t.depth(2, 0, 0, 2), h.levels[2][1].value);
}

TEST(MhOctreeMerge, ValuesOutsideTheirIntervalAreKeptBitForBit) {
  // A hierarchy made by hand whose values do not lie in [lo, hi] (here lo = hi = 0): the
  // merger must not move them, so the compatible leaves stay apart.
  OctHierarchy h = build_octree(two_leaves({0.2f, 0.3f}, {0.24f, 0.34f}));
  for (auto& lv : h.levels)
    for (OctNode& n : lv) n.lo = n.hi = 0;
  OctEncodeStats st;
  const std::vector<uint8_t> bytes = encode_octree(h, &st, kMerge);
  const MhOctree t = MhOctree::open(bytes);  // a view: the buffer must outlive it
  EXPECT_EQ(st.merged_values, 0u);
  EXPECT_EQ(t.depth(0, 0, 0, 2), 0.25f);
  EXPECT_EQ(t.depth(2, 0, 0, 2), 0.3125f);
}

// Random and coherent stacks (non-cubic, N not a power of two) and a stack whose bottom
// half nearly repeats its top half: with merging, every texel of every level of every
// slice still decodes inside its interval; the merger does merge, the buffer is no larger
// than without, and the bytes are the same on a second run (deterministic).
TEST(MhOctreeMerge, EveryLevelOfEverySliceStaysInsideTheBuildersIntervals) {
  const std::pair<uint32_t, uint32_t> shapes[] = {{4, 8}, {5, 3}, {2, 12}, {3, 1}, {0, 5}, {6, 5}, {3, 20}};
  uint64_t merges = 0;
  uint64_t seed = 11;
  for (auto [level, slices] : shapes) {
    SCOPED_TRACE(std::to_string(level) + " " + std::to_string(slices));
    IntervalStack near = stacks::coherent_stack(level, slices, seed);
    // Widen every interval a little around its middle, differently per texel, so nearly
    // equal subtrees get unequal but compatible windows.
    uint64_t rng = seed;
    for (Interval& v : near.data) {
      const float r = float(unit_random(rng)) * 0.02f;
      v = {std::max(0.0f, v.lo - r), std::min(1.0f, v.hi + 0.02f - r)};
    }
    for (const IntervalStack& s :
         {stacks::random_stack(level, slices, seed), stacks::coherent_stack(level, slices, seed), near}) {
      const OctHierarchy h = build_octree(s);
      OctEncodeStats on_st, off_st;
      const std::vector<uint8_t> bytes = encode_octree(h, &on_st, kMerge);
      const std::vector<uint8_t> plain = encode_octree(h, &off_st);
      EXPECT_EQ(encode_octree(h, nullptr, kMerge), bytes);
      EXPECT_LE(bytes.size(), plain.size() + 8 * 4);  // layout may differ by a few padding words
      merges += on_st.merges;
      const MhOctree t = MhOctree::open(bytes);
      EXPECT_EQ(t.node_count(), on_st.nodes);
      EXPECT_EQ(stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint64_t w) {
                  return t.depth(x, y, uint32_t(w), level);
                }), "");
      MhOctree::Path p;
      EXPECT_EQ(stacks::first_violation(
                    s, [&](uint64_t x, uint64_t y, uint64_t w) { return t.depth_along(p, x, y, uint32_t(w)); }),
                "");
      EXPECT_EQ(first_level_violation(h, t), "");
    }
    ++seed;
  }
  EXPECT_GT(merges, 0u);
}

}  // namespace
}  // namespace st

// The MH octree buffer (tiles/core/MHOCT.md): the example pinned byte for byte, decoding
// equal to the hierarchy on every texel of every slice and every level, and hostile
// buffers (every truncation, flipped bits, hand-made offences) refused with one line.
#include <gtest/gtest.h>

#include <cstring>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/core/mh_octree.hpp"

namespace st {
namespace {

// MHOCT.md's example: two 2x2 slices, all 0.5 but texel (0, 0) of slice 0 (0.25) and
// texel (1, 0) of slice 1 (0.75): the root and two leaves, in slots 0 and 5.
IntervalStack example_stack() {
  IntervalStack s{1, 2, std::vector<Interval>(8, Interval{0.5f, 0.5f})};
  s.at(0, 0, 0) = {0.25f, 0.25f};
  s.at(1, 0, 1) = {0.75f, 0.75f};
  return s;
}

TEST(MhOctreeFormat, ExampleBufferIsPinnedByteForByte) {
  static_assert(moct::kOffMagic == 0 && moct::kOffVersion == 4 && moct::kOffXyLevel == 6 && moct::kOffWLevel == 7);
  static_assert(moct::kOffSlices == 8 && moct::kOffFlags == 10 && moct::kOffReserved == 11);
  static_assert(moct::kOffNodeCount == 12 && moct::kOffByteSize == 16 && moct::kOffShifts == 20);
  static_assert(moct::tree_offset(2) == 24 && moct::tree_offset(21) == 44);
  const std::vector<uint8_t> bytes = encode_octree(build_octree(example_stack()));
  auto f = [](float v) {
    uint8_t b[4];
    std::memcpy(b, &v, 4);
    return std::vector<uint8_t>(b, b + 4);
  };
  std::vector<uint8_t> want = {'S', 'T', 'O', 'C', 3, 0, 1, 1, 2, 0, 0, 0, 3, 0, 0, 0, 40, 0, 0, 0,
                               0, 0, 0, 0,                // shifts of levels 0, 1; padding
                               0x01, 0x04, 0x02, 0x00};  // root: slot 0 leaf, slot 5 leaf; off 2
  for (float v : {0.5f, 0.25f, 0.75f})
    for (uint8_t b : f(v)) want.push_back(b);
  EXPECT_EQ(bytes, want);
  const MhOctree t = MhOctree::open(bytes);
  EXPECT_EQ(t.depth(0, 0, 0, 1), 0.25f);
  EXPECT_EQ(t.depth(1, 0, 1, 1), 0.75f);
  EXPECT_EQ(t.depth(1, 0, 0, 1), 0.5f);
  EXPECT_EQ(t.depth(0, 0, 1, 0), 0.5f);  // level 0: the root
  EXPECT_EQ(t.depth(0, 0, 2, 1), kLitDepth);  // outside the stack
  EXPECT_EQ(t.depth(2, 0, 0, 1), kLitDepth);
}

// MHOCT.md's shared-block example: one 4x4 slice, all 0.5 but texels (0, 0) and (2, 0)
// (0.25): quadrants 0 and 1 hold equal children, stored once (44 bytes, not 48).
TEST(MhOctreeFormat, SharedBlockExampleIsPinnedByteForByte) {
  IntervalStack s{2, 1, std::vector<Interval>(16, Interval{0.5f, 0.5f})};
  s.at(0, 0, 0) = s.at(2, 0, 0) = {0.25f, 0.25f};
  OctEncodeStats st;
  const std::vector<uint8_t> bytes = encode_octree(build_octree(s), &st);
  const std::vector<uint8_t> want = {'S', 'T', 'O', 'C', 3, 0, 2, 0, 1, 0, 0, 0, 4, 0, 0, 0, 44, 0, 0, 0,
                                     0, 0, 0, 0,              // shifts of levels 0..2; padding
                                     0x0A, 0x00, 0x02, 0x00,  // root: slots 0, 1 empty; off 2
                                     0x00, 0x00, 0x00, 0x3F,  // root value 0.5
                                     0x01, 0x00, 0x02, 0x00,  // quadrant 0: slot 0 leaf, its block at word 4
                                     0x01, 0x00, 0x01, 0x00,  // quadrant 1: the same block (word 3 + 1)
                                     0x00, 0x00, 0x80, 0x3E};  // the shared leaf 0.25
  EXPECT_EQ(bytes, want);
  EXPECT_EQ(st.shared_blocks, 1u);
  const MhOctree t = MhOctree::open(bytes);
  EXPECT_EQ(t.node_count(), 4u);
  for (uint64_t y = 0; y < 4; ++y)
    for (uint64_t x = 0; x < 4; ++x) EXPECT_EQ(t.depth(x, y, 0, 2), (y == 0 && (x == 0 || x == 2)) ? 0.25f : 0.5f);
  // Hostile shared blocks: a reference to words that are not yet nodes is a claim that
  // overlaps (quadrant 1 naming its own word), or to a node of another level (the root's
  // block at level 1 for level-2 children), or before the tree.
  auto refused = [&](size_t word, uint16_t off, const char* what) {
    std::vector<uint8_t> b = bytes;
    std::memcpy(b.data() + 24 + 4 * word + 2, &off, 2);
    EXPECT_THROW(MhOctree::open(b), FormatError) << what;
  };
  refused(3, 0, "offset zero");
  refused(3, 0xFFFF, "quadrant 1 naming word 2 (quadrant 0, a level-1 node) as its level-2 children");
  refused(3, 0x8020, "a block before the tree (off -32736, the farthest near offset back)");
  refused(3, 0x8000, "a far word that is a node's word (word 4, the shared leaf)");
  refused(2, 3, "quadrant 0's block at word 5, past the end");
  refused(2, 1, "quadrant 0 naming word 3 (quadrant 1, not yet a validated leaf)");
}

// MHOCT.md's far-word example: the shared-block example's stack built by hand with
// quadrant 1 reaching the shared block through a far word (version 3): its offset is
// -32768 (code 0), so the block's word index is the far word at 3 + 1 + 0 = word 4, right
// after the level-1 block; the shared leaf moves to word 5.
std::vector<uint8_t> far_example() {
  return {'S', 'T', 'O', 'C', 3, 0, 2, 0, 1, 0, 0, 0, 4, 0, 0, 0, 48, 0, 0, 0,
          0, 0, 0, 0,              // shifts of levels 0..2; padding
          0x0A, 0x00, 0x02, 0x00,  // word 0, root: slots 0, 1 empty; off 2 (block at word 2)
          0x00, 0x00, 0x00, 0x3F,  // word 1, root value 0.5
          0x01, 0x00, 0x03, 0x00,  // word 2, quadrant 0: slot 0 leaf; off 3 (block at word 5)
          0x01, 0x00, 0x00, 0x80,  // word 3, quadrant 1: slot 0 leaf; off -32768: far code 0
          0x05, 0x00, 0x00, 0x00,  // word 4, quadrant 1's far word: block at word 5
          0x00, 0x00, 0x80, 0x3E};  // word 5, the shared leaf 0.25
}

TEST(MhOctreeFormat, FarSharedBlockExampleIsPinned) {
  static_assert(moct::kVersion == 3 && moct::kFarCodes == 32 && moct::kFarOffsetMin == -32768 &&
                moct::kFarLimit == -32736 && moct::kMaxBackOffset == 32736);
  EXPECT_EQ(moct::far_word(3, -32768), 4u);
  EXPECT_EQ(moct::far_word(3, -32737), 35u);
  EXPECT_EQ(moct::far_offset(3, 4), -32768);
  EXPECT_FALSE(moct::is_far(-32736));
  const std::vector<uint8_t> bytes = far_example();
  const MhOctree t = MhOctree::open(bytes);
  EXPECT_EQ(t.node_count(), 4u);
  for (uint64_t y = 0; y < 4; ++y)
    for (uint64_t x = 0; x < 4; ++x)
      EXPECT_EQ(t.depth(x, y, 0, 2), (y == 0 && (x == 0 || x == 2)) ? 0.25f : 0.5f) << x << "," << y;
  EXPECT_EQ(t.depth(1, 0, 0, 1), 0.5f);  // level 1: quadrant 1 (empty) inherits the root's value
  // The child step follows the far word: quadrant 1's slot 0 is word 5.
  MhOctree::Cursor q1, leaf;
  ASSERT_TRUE(t.child(t.root(), 1, q1));
  EXPECT_EQ(q1.pos, 3u);
  ASSERT_TRUE(t.child(q1, 0, leaf));
  EXPECT_EQ(leaf.pos, 5u);
  EXPECT_EQ(t.value(leaf), 0.25f);
  MhOctree::Path p;
  EXPECT_EQ(t.depth_along(p, 2, 0, 0), 0.25f);
  EXPECT_EQ(t.depth_along(p, 3, 0, 0), 0.5f);
}

// Hostile far words, each refused with one line: outside the buffer, claimed twice (by two
// nodes, or a far word laid over a node), and a far target that would loop back.
TEST(MhOctreeFormat, HostileFarWordsAreRefused) {
  const std::vector<uint8_t> good = far_example();
  ASSERT_NO_THROW(MhOctree::open(good));
  auto with = [&](size_t word, size_t byte, std::initializer_list<uint8_t> v) {
    std::vector<uint8_t> b = good;
    std::copy(v.begin(), v.end(), b.begin() + ptrdiff_t(24 + 4 * word + byte));
    return b;
  };
  auto refused = [](const std::vector<uint8_t>& b, const char* field, const char* what) {
    try {
      MhOctree::open(b);
      ADD_FAILURE() << "accepted: " << what;
    } catch (const FormatError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(field), std::string::npos) << what << ": " << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
  };
  refused(with(3, 2, {0x1F, 0x80}), "far word", "code 31: word 35, past the end of the 6-word tree");
  refused(with(3, 2, {0x02, 0x80}), "far word", "code 2: word 6, one past the end");
  refused(with(2, 2, {0x01, 0x80}), "far word", "quadrant 0 claiming word 4 too: claimed twice");
  refused(with(3, 2, {0x01, 0x80}), "far word", "code 1: word 5, the shared leaf (a node's word)");
  refused(with(4, 0, {0x02}), "child offset", "far target word 2: quadrant 1's own block, a loop");
  refused(with(4, 0, {0x00}), "child offset", "far target word 0: the root, a loop");
  refused(with(4, 0, {0x03}), "child offset", "far target word 3: quadrant 1 itself");
  refused(with(4, 0, {0x06}), "child offset", "far target word 6: outside the tree");
  refused(with(4, 3, {0x80}), "child offset", "far target beyond 2^31 words");
  // A far word claims its word: a node laid over it later is an overlap.
  std::vector<uint8_t> over = good;
  over[24 + 4 * 0 + 2] = 0x02;  // root keeps off 2
  over[24 + 4 * 2 + 2] = 0x00, over[24 + 4 * 2 + 3] = 0x80;  // quadrant 0 far, code 0: word 3 = quadrant 1
  refused(over, "MH octree: ", "quadrant 0's far word is quadrant 1's node word");
}

// A stack whose equal blocks lie far apart: the bottom half of every slice repeats the top
// half shifted down by two texels, so the 2x2x2 blocks of the finest step are equal while
// the coarser ones are not, and the equal pairs lie two root quadrants (about half the
// tree) apart in the depth-first order, beyond a 16-bit offset's reach (shift 0 at the
// finest levels).
IntervalStack far_repeat_stack(uint32_t level, uint32_t slices, uint64_t seed) {
  IntervalStack s = stacks::random_stack(level, slices, seed);
  const uint64_t side = s.side(), shift = 2;
  for (uint32_t w = 0; w < slices; ++w)
    for (uint64_t y = side / 2 + shift; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x) s.at(x, y, w) = s.at(x, y - side / 2 - shift, w);
  return s;
}

TEST(MhOctreeFormat, FarBlocksAreSharedLosslessly) {
  const uint32_t level = 7;
  const IntervalStack s = far_repeat_stack(level, 10, 3);
  const OctHierarchy h = build_octree(s);
  OctEncodeStats st;
  const std::vector<uint8_t> bytes = encode_octree(h, &st);
  EXPECT_GT(st.far_blocks, 100u) << "words " << st.words << " shared " << st.shared_blocks;
  EXPECT_GE(st.far_words, st.far_blocks);
  EXPECT_EQ(st.shift[h.geo.depth() - 1], 0u);
  const MhOctree t = MhOctree::open(bytes);
  EXPECT_EQ(t.node_count(), st.nodes);
  // Every texel of every slice keeps the invariant of the uncompressed bounds, by the plain
  // walk and by the resumed walk, and every level answers as the hierarchy.
  EXPECT_EQ(stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint64_t w) { return t.depth(x, y, uint32_t(w), level); }),
            "");
  MhOctree::Path p;
  EXPECT_EQ(stacks::first_violation(
                s, [&](uint64_t x, uint64_t y, uint64_t w) { return t.depth_along(p, x, y, uint32_t(w)); }),
            "");
  for (uint32_t q = 0; q <= level; ++q) {
    const uint32_t ol = h.geo.level_of_xy(q);
    for (uint32_t w = 0; w < s.slices; ++w)
      for (uint64_t y = 0; y < (uint64_t(1) << q); ++y)
        for (uint64_t x = 0; x < (uint64_t(1) << q); ++x)
          ASSERT_EQ(t.depth(x, y, w, q), h.depth_at(ol, x, y, w >> (h.geo.k - h.geo.w_bits(ol))))
              << "level " << q << " texel " << x << "," << y << " slice " << w;
  }
  // Smaller than the same tree with every out-of-reach block copied (version 2's layout).
  EXPECT_LT(st.out_of_reach, st.far_blocks);
}

TEST(MhOctreeFormat, DecodesLikeTheHierarchyOnEveryTexelSliceAndLevel) {
  const std::pair<uint32_t, uint32_t> shapes[] = {{4, 8}, {5, 3}, {2, 12}, {3, 1}, {0, 5}};
  for (auto [level, slices] : shapes) {
    SCOPED_TRACE(std::to_string(level) + " " + std::to_string(slices));
    for (const IntervalStack& s : {stacks::random_stack(level, slices, 5), stacks::coherent_stack(level, slices, 5)}) {
      const OctHierarchy h = build_octree(s);
      OctEncodeStats st;
      const std::vector<uint8_t> bytes = encode_octree(h, &st);
      const MhOctree t = MhOctree::open(bytes);
      EXPECT_EQ(t.node_count(), st.nodes);
      EXPECT_LE(t.node_count(), h.node_count());  // nodes under a shared block are stored once
      EXPECT_EQ(stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint64_t w) {
                  return t.depth(x, y, uint32_t(w), level);
                }), "");
      // Every coarser level answers what the hierarchy's level answers.
      for (uint32_t q = 0; q <= level; ++q) {
        const uint32_t ol = h.geo.level_of_xy(q);
        for (uint32_t w = 0; w < slices; ++w)
          for (uint64_t y = 0; y < (uint64_t(1) << q); ++y)
            for (uint64_t x = 0; x < (uint64_t(1) << q); ++x)
              ASSERT_EQ(t.depth(x, y, w, q), h.depth_at(ol, x, y, w >> (h.geo.k - h.geo.w_bits(ol))))
                  << "level " << q << " texel " << x << "," << y << " slice " << w;
      }
      // A finer query level reads the finest texel above it.
      EXPECT_EQ(t.depth(5, 3, 0, level + 2), t.depth(5 >> 2, 3 >> 2, 0, level));
    }
  }
}

TEST(MhOctreeFormat, LargeStacksScaleTheirOffsets) {
  // 1024 random 16x16 slices: the w-only levels near the root put ~10^5 words between a
  // node and its second child's block, beyond 16 bits.
  const uint32_t level = 4;
  const IntervalStack s = stacks::random_stack(level, 1024, 9);
  OctEncodeStats st;
  const std::vector<uint8_t> bytes = encode_octree(build_octree(s), &st);
  uint32_t shifts = 0;
  for (uint8_t v : st.shift) shifts += v;
  EXPECT_GT(shifts, 0u) << "a random 16^2 x 1024 stack needs scaled top offsets; words " << st.words << " nodes " << st.nodes;
  const MhOctree t = MhOctree::open(bytes);
  EXPECT_EQ(stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint64_t w) { return t.depth(x, y, uint32_t(w), level); }), "");
}

void expect_refused(const std::vector<uint8_t>& b, const char* what) {
  try {
    MhOctree::open(b);
    ADD_FAILURE() << "accepted: " << what;
  } catch (const FormatError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("MH octree: ", 0), 0u) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
}

TEST(MhOctreeFormat, HostileBuffersAreRefused) {
  const std::vector<uint8_t> good = encode_octree(build_octree(stacks::random_stack(3, 5, 2)));
  ASSERT_NO_THROW(MhOctree::open(good));
  for (size_t n = 0; n < good.size(); ++n) {  // every truncation, byte_size patched or not
    std::vector<uint8_t> b(good.begin(), good.begin() + ptrdiff_t(n));
    expect_refused(b, "truncated");
    if (n >= 20) {
      const uint32_t size = uint32_t(n);
      std::memcpy(b.data() + moct::kOffByteSize, &size, 4);
      expect_refused(b, "truncated with byte_size patched");
    }
  }
  auto patched = [&](size_t at, uint8_t v) {
    std::vector<uint8_t> b = good;
    b[at] = v;
    return b;
  };
  expect_refused(patched(0, 'X'), "magic");
  expect_refused(patched(4, 4), "version");
  for (uint8_t old_version : {1, 2}) {  // the versions before far words: one line saying what to do
    try {
      MhOctree::open(patched(4, old_version));
      ADD_FAILURE() << "accepted version " << int(old_version);
    } catch (const FormatError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("version " + std::to_string(old_version)), std::string::npos) << m;
      EXPECT_NE(m.find("rebuild the stack"), std::string::npos) << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
  }
  expect_refused(patched(6, 21), "xy_level");
  expect_refused(patched(7, 13), "w_level");
  expect_refused(patched(8, 9), "slices beyond the padding");
  expect_refused(patched(8, 4), "slices that pad to less");
  expect_refused(patched(10, 2), "flags");
  expect_refused(patched(11, 1), "reserved");
  expect_refused(patched(12, 0), "node_count");
  expect_refused(patched(20, 16), "shift");
  std::vector<uint8_t> trailing = good;
  trailing.insert(trailing.end(), {0, 0, 0, 0});
  const uint32_t size = uint32_t(trailing.size());
  std::memcpy(trailing.data() + moct::kOffByteSize, &size, 4);
  expect_refused(trailing, "trailing word");
  // A child in a slot the level does not split: slices 1 deep under a 2-level xy stack.
  const std::vector<uint8_t> flat = encode_octree(build_octree(stacks::random_stack(2, 1, 3)));
  std::vector<uint8_t> bad_slot = flat;
  const size_t root = moct::tree_offset(3);
  bad_slot[root + 1] |= 0x40;  // slot 7 (bits 14..15) := leaf
  expect_refused(bad_slot, "slot w in a stack of one slice");
  // Random bit flips: refused or, if accepted, every lookup stays in bounds (ASan).
  Rng rng(4);
  for (int i = 0; i < 2000; ++i) {
    std::vector<uint8_t> b = good;
    b[rng.next() % b.size()] ^= uint8_t(1u << (rng.next() % 8));
    try {
      const MhOctree t = MhOctree::open(b);
      for (uint32_t w = 0; w < 6; ++w)
        for (uint32_t q = 0; q <= 4; ++q) (void)t.depth(rng.next() % 9, rng.next() % 9, w, q);
    } catch (const FormatError&) {
    }
  }
}

}  // namespace
}  // namespace st

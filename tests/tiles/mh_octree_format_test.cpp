// The MH octree buffer (tiles/core/MHOCT.md): the example pinned byte for byte, decoding
// equal to the hierarchy on every texel of every slice and every level, and hostile
// buffers (every truncation, flipped bits, hand-made offences) refused with one line.
#include <gtest/gtest.h>

#include <cstring>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/build/mh_octree_encode.hpp"
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
  std::vector<uint8_t> want = {'S', 'T', 'O', 'C', 2, 0, 1, 1, 2, 0, 0, 0, 3, 0, 0, 0, 40, 0, 0, 0,
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
  const std::vector<uint8_t> want = {'S', 'T', 'O', 'C', 2, 0, 2, 0, 1, 0, 0, 0, 4, 0, 0, 0, 44, 0, 0, 0,
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
  refused(3, 0x8000, "a block before the tree");
  refused(2, 3, "quadrant 0's block at word 5, past the end");
  refused(2, 1, "quadrant 0 naming word 3 (quadrant 1, not yet a validated leaf)");
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
  expect_refused(patched(4, 3), "version");
  try {
    MhOctree::open(patched(4, 1));
    ADD_FAILURE() << "accepted version 1";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("version 1"), std::string::npos) << e.what();
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

// The sharing measure of stack octrees (mh_octree_share.hpp): exact counts on a stack
// whose second half repeats its first, and bounds that hold on any stack.
#include <gtest/gtest.h>

#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/encode/mh_octree_share.hpp"
#include "tiles/core/mh_octree.hpp"

namespace st {
namespace {

void expect_bounds(const OctreeSharing& s, const OctHierarchy& h) {
  EXPECT_EQ(s.nodes, h.node_count());
  EXPECT_LE(s.unique_subtrees, s.nodes);
  EXPECT_LE(s.unique_blocks, s.blocks);
  EXPECT_LE(s.dag_words, s.block_dag_words);  // a block shares only whole sibling sets
  EXPECT_LE(s.block_dag_words, s.words);
  EXPECT_GE(s.dag_words, 1u);
}

TEST(OctreeSharing, RandomStackHasLittleToShare) {
  const IntervalStack st = stacks::random_stack(4, 4, 11);
  const OctHierarchy h = build_octree(st);
  const OctreeSharing s = measure_octree_sharing(h);
  expect_bounds(s, h);
  // Words: the encoded sizes (leaf 1, empty 1, inner 2).
  uint64_t words = 0;
  for (const auto& level : h.levels)
    for (const OctNode& n : level) words += n.has_value && n.child_mask ? 2 : 1;
  EXPECT_EQ(s.words, words);
  EXPECT_GT(double(s.block_dag_words), 0.9 * double(s.words));
}

TEST(OctreeSharing, RepeatedHalfIsStoredOnce) {
  // Slices 4..7 repeat slices 0..3 exactly: the root's step halves w, and its two halves'
  // subtrees are equal node for node, so sharing by block stores about half the words.
  IntervalStack st = stacks::random_stack(2, 8, 5);
  const size_t half = st.data.size() / 2;
  std::copy(st.data.begin(), st.data.begin() + ptrdiff_t(half), st.data.begin() + ptrdiff_t(half));
  const OctHierarchy h = build_octree(st);
  ASSERT_EQ(h.geo.n, 2u);
  ASSERT_EQ(h.geo.k, 3u);
  const OctreeSharing s = measure_octree_sharing(h);
  expect_bounds(s, h);
  EXPECT_GE(s.repeated_inner, 1u);
  EXPECT_GE(2 * s.largest_repeated_words + 2, s.words);  // each half is one repeated subtree
  EXPECT_LE(2 * s.block_dag_words, s.words + 4);
}

TEST(OctreeSharing, EncoderStoresTheRepeatedHalfOnce) {
  // The same stack encoded (format version 3): the second half's blocks point at the
  // first half's, the buffer holds the measure's words (everything is within reach), and
  // every texel of every slice still decodes losslessly.
  IntervalStack st = stacks::random_stack(2, 8, 5);
  const size_t half = st.data.size() / 2;
  std::copy(st.data.begin(), st.data.begin() + ptrdiff_t(half), st.data.begin() + ptrdiff_t(half));
  const OctHierarchy h = build_octree(st);
  const OctreeSharing s = measure_octree_sharing(h);
  OctEncodeStats es;
  const std::vector<uint8_t> bytes = encode_octree(h, &es);
  EXPECT_GE(es.shared_blocks, 1u);
  EXPECT_EQ(es.out_of_reach, 0u);
  EXPECT_EQ(es.words, s.block_dag_words);
  const MhOctree t = MhOctree::open(bytes);
  EXPECT_EQ(stacks::first_violation(st, [&](uint64_t x, uint64_t y, uint64_t w) { return t.depth(x, y, uint32_t(w), 2); }),
            "");
}

}  // namespace
}  // namespace st

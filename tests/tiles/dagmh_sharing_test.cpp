// DAG-MH structure sharing (§3.1): identical topologies are stored once, whatever their
// values; merging needs full key equality, so a hash where everything collides changes
// nothing but speed.
#include <gtest/gtest.h>

#include "tests/tiles/dagmh_fixtures.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tiles/encode/dagmh_encode.hpp"
#include "tiles/encode/mh_build.hpp"

namespace st {
namespace {

// Levels 0..top full (empty except the root), and below every level-`top` node the same
// random pattern topology with fresh random intervals.
Hierarchy pattern_hierarchy(uint32_t top, uint32_t pattern_depth, uint64_t seed) {
  const Hierarchy pattern = dagmh_test::random_hierarchy(pattern_depth, seed, 0.45, 0.5,
                                                         dagmh_test::mixed_interval);
  Hierarchy h;
  h.depth = top + pattern_depth;
  h.levels.resize(h.depth + 1);
  for (uint32_t l = 0; l < top; ++l)
    for (uint64_t m = 0; m < (uint64_t(1) << (2 * l)); ++m) {
      HNode n;
      n.morton = m;
      n.child_mask = 0xF;
      n.has_value = l == 0;
      n.lo = n.hi = n.value = 0.5f;
      h.levels[l].push_back(n);
    }
  fields::Rng rng(seed + 1);
  for (uint64_t p = 0; p < (uint64_t(1) << (2 * top)); ++p)
    for (uint32_t d = 0; d <= pattern_depth; ++d)
      for (const HNode& q : pattern.levels[d]) {
        HNode n = q;
        n.morton = (p << (2 * d)) | q.morton;
        if (n.has_value) {
          const Interval iv = dagmh_test::mixed_interval(rng);
          n.lo = iv.lo, n.hi = iv.hi, n.value = iv.lo;
        }
        h.levels[top + d].push_back(n);
      }
  // Level top+d holds the blocks in order of p, each sorted: the encoder checks the order.
  return h;
}

TEST(DagmhSharing, RepeatedTopologyIsStoredOnce) {
  const Hierarchy h = pattern_hierarchy(4, 7, 3);
  dagmh::EncodeStats st;
  const auto bytes = dagmh::encode(h, &st);
  auto e = open_dagmh(bytes);
  // 256 copies of the pattern collapse to one: its inner nodes and treelets once, plus
  // the 4 full levels above (one node per level: they are identical too).
  EXPECT_GE(st.tree_inner + st.tree_treelets, 256 * (st.dag_inner + st.dag_treelets - 4) / 2);
  EXPECT_LE(st.dag_inner + st.dag_treelets, (st.tree_inner + st.tree_treelets) / 50);
  // An MH quadtree spends a 4-byte word per node (MH §3.2); the DAG far less.
  EXPECT_LT(st.node_bytes + st.treelet_bytes, 4 * h.node_count() / 50);
  const auto want = dagmh_test::admissible_levels(h);
  for (uint64_t y = 0; y < (1u << h.depth); y += 7)
    for (uint64_t x = 0; x < (1u << h.depth); ++x) {
      const float v = e->depth(h.depth, x, y);
      const Interval iv = want[h.depth][y * (1u << h.depth) + x];
      ASSERT_TRUE(iv.lo <= v && v <= iv.hi) << x << ", " << y;
    }
}

// A field made of one 32x32 random block repeated: the bottom-up construction gives every
// copy the same topology, so the structure is stored about once.
TEST(DagmhSharing, RepeatedPatternFieldSharesItsStructure) {
  const uint32_t side = fields::small_test_scale() ? 128 : 256, block = 32;
  const IntervalTile pattern = fields::uniform_field(block, 5);
  IntervalTile tile = fields::constant_field(side, Interval{});
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) tile.at(i, j) = pattern.at(i % block, j % block);
  const Hierarchy h = build_hierarchy(tile);
  dagmh::EncodeStats st;
  const auto bytes = dagmh::encode(h, &st);
  const uint64_t copies = (side / block) * (side / block);
  EXPECT_LE(st.dag_inner + st.dag_treelets, (st.tree_inner + st.tree_treelets) / (copies / 4));
  EXPECT_LT(st.node_bytes + st.treelet_bytes, 4 * h.node_count() / 20);  // MH: a word per node
  EXPECT_LT(bytes.size(), 4 * (h.node_count() + h.valued_count()));
  std::printf("repeated %ux%u block over %u^2: inner %llu -> %llu, treelets %llu -> %llu, structure %llu B "
              "for %zu nodes; total %zu B\n", block, block, side, (unsigned long long)st.tree_inner,
              (unsigned long long)st.dag_inner, (unsigned long long)st.tree_treelets,
              (unsigned long long)st.dag_treelets, (unsigned long long)(st.node_bytes + st.treelet_bytes),
              h.node_count(), bytes.size());
  auto e = open_dagmh(bytes);
  EXPECT_EQ(fields::first_violation(tile, [&](uint32_t i, uint32_t j) { return e->depth(h.depth, i, j); }), "");
}

uint64_t constant_hash(const uint32_t*, size_t) { return 42; }
uint64_t weak_hash(const uint32_t* w, size_t n) { return n ? w[0] & 3 : 0; }

TEST(DagmhSharing, MergesOnlyOnFullComparisonNeverOnHash) {
  for (uint64_t seed = 0; seed < 6; ++seed) {
    const Hierarchy h = seed < 3 ? pattern_hierarchy(3, 6, seed)
                                 : dagmh_test::random_hierarchy(9, seed, 0.5, 0.4, dagmh_test::mixed_interval);
    const auto good = dagmh::encode(h);
    EXPECT_EQ(dagmh::encode(h, nullptr, constant_hash), good) << seed;
    EXPECT_EQ(dagmh::encode(h, nullptr, weak_hash), good) << seed;
  }
}

}  // namespace
}  // namespace st

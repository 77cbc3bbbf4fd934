// The octree of a shadow-map stack (MH 2016 §4): structure, the lossless invariant on
// every texel of every slice (random, coherent and traced stacks), placeholders for
// non-cubic stacks, and the one-slice case equal to the 2D construction.
#include <gtest/gtest.h>

#include "common/error.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/encode/mh_build.hpp"

namespace st {
namespace {

// Levels sorted by code, masks naming exactly the next level's nodes, only the slots the
// geometry allows, empty nodes with children, valued nodes inside their intervals.
std::string check_structure(const OctHierarchy& h) {
  if (h.levels.size() != h.geo.levels() || h.levels[0].size() != 1 || !h.levels[0][0].has_value)
    return "bad root or level count";
  for (uint32_t l = 0; l < h.levels.size(); ++l) {
    size_t next = 0;
    for (size_t j = 0; j < h.levels[l].size(); ++j) {
      const OctNode& n = h.levels[l][j];
      const std::string at = "level " + std::to_string(l) + " node " + std::to_string(j);
      if (j && h.levels[l][j - 1].code >= n.code) return at + ": codes not increasing";
      if (n.has_value && !(n.lo <= n.value && n.value <= n.hi)) return at + ": value outside [lo, hi]";
      if (!n.has_value && !n.child_mask) return at + ": empty without children";
      if (n.child_mask & ~h.geo.slot_set(l)) return at + ": a slot the geometry does not split";
      if (l + 1 == h.levels.size() && n.child_mask) return at + ": children below the finest level";
      for (uint32_t c = 0; c < 8; ++c) {
        if (!(n.child_mask >> c & 1)) continue;
        uint64_t x = 0, y = 0, w = 0;
        oct_coords(h.geo, l, n.code, x, y, w);
        if (h.geo.splits_xy(l)) x = 2 * x + (c & 1), y = 2 * y + (c >> 1 & 1);
        if (h.geo.splits_w(l)) w = 2 * w + (c >> 2);
        if (next >= h.levels[l + 1].size() || h.levels[l + 1][next].code != oct_code(h.geo, l + 1, x, y, w))
          return at + ": child " + std::to_string(c) + " not where its code says";
        ++next;
      }
    }
    if (l + 1 < h.levels.size() && next != h.levels[l + 1].size()) return "level " + std::to_string(l + 1) + ": orphans";
  }
  return "";
}

std::string check_all(const OctHierarchy& h, const IntervalStack& s) {
  std::string e = check_structure(h);
  if (!e.empty()) return e;
  const uint32_t L = h.geo.depth();
  return stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint64_t w) { return h.depth_at(L, x, y, w); });
}

TEST(MhOctree, CodesRoundTripForEveryShape) {
  for (moct::Geometry g : {moct::Geometry{3, 3}, moct::Geometry{4, 2}, moct::Geometry{1, 4}, moct::Geometry{0, 0}})
    for (uint32_t l = 0; l <= g.depth(); ++l)
      for (uint64_t code = 0; code < (uint64_t(1) << (2 * g.xy_bits(l) + g.w_bits(l))); ++code) {
        uint64_t x, y, w;
        oct_coords(g, l, code, x, y, w);
        ASSERT_LT(x, uint64_t(1) << g.xy_bits(l));
        ASSERT_LT(w, uint64_t(1) << g.w_bits(l));
        ASSERT_EQ(oct_code(g, l, x, y, w), code) << g.n << " " << g.k << " level " << l;
      }
}

TEST(MhOctree, RandomStacksAreLosslessOnEveryTexelOfEverySlice) {
  // Cubic, shallower than wide (x, y only near the root), deeper than wide (w only),
  // and N not a power of two (placeholder slices).
  const std::pair<uint32_t, uint32_t> shapes[] = {{3, 8}, {5, 4}, {2, 16}, {4, 5}, {0, 3}, {4, 1}, {3, 13}};
  for (auto [level, slices] : shapes)
    for (uint64_t seed = 1; seed <= 3; ++seed) {
      SCOPED_TRACE("level " + std::to_string(level) + " slices " + std::to_string(slices));
      const IntervalStack s = stacks::random_stack(level, slices, seed);
      const OctHierarchy h = build_octree(s);
      EXPECT_EQ(check_all(h, s), "");
    }
}

TEST(MhOctree, CoherentStacksAreLosslessAndSmallerThanTheirSlices) {
  const uint32_t level = stacks::small_scale() ? 5 : 7;
  for (uint32_t slices : {16u, 12u}) {
    const IntervalStack s = stacks::coherent_stack(level, slices, 7);
    const OctHierarchy h = build_octree(s);
    ASSERT_EQ(check_all(h, s), "");
    size_t slice_nodes = 0;
    for (uint32_t w = 0; w < slices; ++w) slice_nodes += build_hierarchy(stacks::slice(s, w)).node_count();
    // Coherence along w is what the octree exploits (MH §4, Table 4).
    EXPECT_LT(h.node_count(), slice_nodes * 3 / 4) << h.node_count() << " vs " << slice_nodes;
  }
}

TEST(MhOctree, OneSliceIsTheQuadtreeOfThatSlice) {
  const IntervalStack s = stacks::coherent_stack(6, 1, 3);
  const OctHierarchy o = build_octree(s);
  const Hierarchy q = build_hierarchy(stacks::slice(s, 0));
  ASSERT_EQ(o.levels.size(), q.levels.size());
  for (size_t l = 0; l < q.levels.size(); ++l) {
    ASSERT_EQ(o.levels[l].size(), q.levels[l].size()) << "level " << l;
    for (size_t j = 0; j < q.levels[l].size(); ++j) {
      EXPECT_EQ(o.levels[l][j].code, q.levels[l][j].morton);
      EXPECT_EQ(o.levels[l][j].has_value, q.levels[l][j].has_value);
      if (!q.levels[l][j].has_value) continue;
      // The same admissible interval; the octree takes its roundest float (shared blocks),
      // the quadtree its midpoint.
      EXPECT_EQ(o.levels[l][j].lo, q.levels[l][j].lo);
      EXPECT_EQ(o.levels[l][j].hi, q.levels[l][j].hi);
      EXPECT_TRUE(o.levels[l][j].lo <= o.levels[l][j].value && o.levels[l][j].value <= o.levels[l][j].hi);
    }
  }
}

TEST(MhOctree, PlaceholderSlicesAreNeverStored) {
  // 5 slices pad to 8: no node lies wholly in slices 5..7.
  const IntervalStack s = stacks::random_stack(3, 5, 11);
  const OctHierarchy h = build_octree(s);
  EXPECT_EQ(h.geo.k, 3u);
  for (uint32_t l = 0; l < h.levels.size(); ++l)
    for (const OctNode& n : h.levels[l]) {
      uint64_t x, y, w;
      oct_coords(h.geo, l, n.code, x, y, w);
      EXPECT_LT(w << (h.geo.k - h.geo.w_bits(l)), 5u) << "level " << l;
    }
}

TEST(MhOctree, TracedStacksUnderSunPathsAndAreaLightsAreLossless) {
  const bool small = stacks::small_scale();
  struct Case { const char* scene; const char* light; uint32_t level; };
  const Case cases[] = {
      {"procedural:city,size=2", "sun-path:azimuth=80..140,elevation=30..50,samples=6", small ? 6u : 8u},
      {"procedural:hairball,count=8", "area:pos=3,12,2,target=0,0,0,size=2,2,samples=4,jitter=0.5", small ? 6u : 7u},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.light);
    const LightSet set = stacks::fitted_set(c.scene, c.light);
    const IntervalStack s = stacks::traced_stack(c.scene, set, c.level);
    const OctHierarchy h = build_octree(s);
    EXPECT_EQ(check_all(h, s), "");
  }
}

TEST(MhOctree, BadStacksAreRefusedNamingTheTexel) {
  IntervalStack s = stacks::random_stack(2, 3, 1);
  s.at(1, 2, 2) = {0.5f, 0.25f};
  try {
    build_octree(s);
    FAIL() << "accepted lo > hi";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("texel (1, 2) of slice 2"), std::string::npos) << e.what();
  }
  s.data.pop_back();
  EXPECT_THROW(build_octree(s), Error);
  EXPECT_THROW(build_octree(IntervalStack{2, 0, {}}), Error);
}

}  // namespace
}  // namespace st

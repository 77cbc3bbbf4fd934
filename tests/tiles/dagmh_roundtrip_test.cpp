// DAG-MH round trips: every texel of every level decodes to a value inside the admissible
// interval of the node answering for it, the full-resolution map satisfies the lossless
// invariant, and PCF equals the average of single lookups exactly.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <string>

#include "tests/tiles/dagmh_fixtures.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tiles/encode/dagmh_encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/dagmh_validate.hpp"

namespace st {
namespace {

using dagmh_test::admissible_levels;
using dagmh_test::encode_and_open;
using dagmh_test::random_hierarchy;

// "" if every texel of every level decodes inside its admissible interval.
std::string check_every_level(const Hierarchy& h, const Evaluator& e) {
  const auto want = admissible_levels(h);
  for (uint32_t l = 0; l <= h.depth; ++l) {
    const uint64_t side = uint64_t(1) << l;
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x) {
        const float v = e.depth(l, x, y);
        const Interval iv = want[l][y * side + x];
        if (!(iv.lo <= v && v <= iv.hi))
          return "level " + std::to_string(l) + " texel (" + std::to_string(x) + ", " +
                 std::to_string(y) + "): " + std::to_string(v) + " not in [" + std::to_string(iv.lo) +
                 ", " + std::to_string(iv.hi) + "]";
      }
  }
  return "";
}

uint32_t field_side() { return fields::small_test_scale() ? 64 : 256; }

TEST(DagmhRoundTrip, EveryFieldEveryLevelAdmissibleAndLossless) {
  for (uint32_t side : {1u, 2u, 8u, 16u, field_side()}) {
    for (const auto& f : fields::all_fields(side, 7 + side)) {
      SCOPED_TRACE(f.name + " side " + std::to_string(side));
      const Hierarchy h = build_hierarchy(f.tile);
      auto o = encode_and_open(h);
      ASSERT_EQ(o.eval->finest_level(), h.depth);
      EXPECT_EQ(check_every_level(h, *o.eval), "");
      EXPECT_EQ(fields::first_violation(f.tile, [&](uint32_t i, uint32_t j) {
                  return o.eval->depth(h.depth, i, j);
                }),
                "");
    }
  }
}

// Top-down and tiled (stitched) constructions give other node sets and intervals.
TEST(DagmhRoundTrip, TopDownAndStitchedHierarchies) {
  const uint32_t side = fields::small_test_scale() ? 64 : 128, grid = 4, part = side / grid;
  for (const auto& f : fields::all_fields(side, 5)) {
    SCOPED_TRACE(f.name);
    std::vector<Hierarchy> tiles;
    for (uint32_t tj = 0; tj < grid; ++tj)
      for (uint32_t ti = 0; ti < grid; ++ti) {
        IntervalTile t = fields::constant_field(part, Interval{});
        for (uint32_t j = 0; j < part; ++j)
          for (uint32_t i = 0; i < part; ++i) t.at(i, j) = f.tile.at(ti * part + i, tj * part + j);
        tiles.push_back(build_hierarchy(t));
      }
    for (const Hierarchy& h : {build_hierarchy(f.tile, MhConstruction::top_down), stitch_tiles(std::move(tiles), 2)}) {
      auto o = encode_and_open(h);
      EXPECT_EQ(check_every_level(h, *o.eval), "");
      EXPECT_EQ(fields::first_violation(f.tile, [&](uint32_t i, uint32_t j) { return o.eval->depth(h.depth, i, j); }), "");
    }
  }
}

TEST(DagmhRoundTrip, RandomHierarchiesWithArbitraryIntervals) {
  const int runs = fields::small_test_scale() ? 20 : 80;
  for (int seed = 0; seed < runs; ++seed) {
    const uint32_t depth = uint32_t(seed % 9);
    const Hierarchy h = random_hierarchy(depth, uint64_t(seed), 0.2 + 0.1 * (seed % 7),
                                         0.2 + 0.1 * (seed % 5), dagmh_test::mixed_interval);
    auto o = encode_and_open(h);
    EXPECT_EQ(check_every_level(h, *o.eval), "") << "seed " << seed;
  }
}

// Intervals made of special values: zero-width, [0,0], [1,1], subnormals, -0.0,
// 1e-30 .. 1e30 of both signs, the extreme floats.
Interval special_interval(fields::Rng& rng) {
  static const float pool[] = {0.0f, -0.0f, 1.0f, 1e-45f, 1.17549435e-38f, 5e-39f, 1e-30f,
                               -1e-30f, 1e30f, -1e30f, 3.4028235e38f, -3.4028235e38f, 0.5f,
                               0.50000006f, 0.99999994f, 1e-7f};
  const uint32_t n = sizeof(pool) / sizeof(pool[0]);
  float a = pool[rng.below(n)], b = pool[rng.below(n)];
  if (rng.below(3) == 0) b = a;
  if (b < a) std::swap(a, b);
  return {a, b};
}

TEST(DagmhRoundTrip, SpecialValuesAreKeptInsideTheirIntervals) {
  for (int seed = 0; seed < 30; ++seed) {
    const Hierarchy h = random_hierarchy(uint32_t(3 + seed % 5), uint64_t(1000 + seed), 0.5, 0.6,
                                         special_interval);
    auto o = encode_and_open(h);
    EXPECT_EQ(check_every_level(h, *o.eval), "") << "seed " << seed;
  }
  // Exactly-representable points must come back bit-exactly (incl. the sign of zero is
  // free: -0.0 == 0.0 is inside [-0, -0]).
  const auto tile = fields::special_values_field(64, 3);
  const Hierarchy h = build_hierarchy(tile);
  auto o = encode_and_open(h);
  EXPECT_EQ(fields::first_violation(tile, [&](uint32_t i, uint32_t j) { return o.eval->depth(6, i, j); }),
            "");
}

// Level-20 maps: a few random deep paths (texel coordinates up to 2^20, the skip table
// and every treelet depth exercised), checked on and around the paths at every level.
TEST(DagmhRoundTrip, DeepSparsePathsAtLevel20) {
  fields::Rng rng(99);
  Hierarchy h;
  h.depth = 20;
  h.levels.resize(21);
  std::vector<std::pair<uint64_t, uint64_t>> targets;
  for (int t = 0; t < 6; ++t) targets.push_back({rng.below(1u << 20), rng.below(1u << 20)});
  // Node set: every prefix of every target, valued at random levels.
  std::vector<std::vector<uint64_t>> codes(21);
  for (auto [x, y] : targets)
    for (uint32_t l = 0; l <= 20; ++l) codes[l].push_back(morton_encode(uint32_t(x >> (20 - l)), uint32_t(y >> (20 - l))));
  for (uint32_t l = 0; l <= 20; ++l) {
    std::sort(codes[l].begin(), codes[l].end());
    codes[l].erase(std::unique(codes[l].begin(), codes[l].end()), codes[l].end());
    for (uint64_t m : codes[l]) {
      HNode n;
      n.morton = m;
      n.has_value = l == 0 || l == 20 || rng.below(3) == 0;
      const Interval iv = dagmh_test::mixed_interval(rng);
      n.lo = iv.lo, n.hi = iv.hi, n.value = iv.lo;
      if (l < 20)
        for (uint64_t c : codes[l + 1])
          if ((c >> 2) == m) n.child_mask |= uint8_t(1u << (c & 3));
      h.levels[l].push_back(n);
    }
  }
  auto o = encode_and_open(h);
  for (auto [x, y] : targets)
    for (uint32_t l = 0; l <= 20; ++l)
      for (int dx = -2; dx <= 2; ++dx)
        for (int dy = -2; dy <= 2; ++dy) {
          const uint64_t side = uint64_t(1) << l;
          const uint64_t px = std::min<uint64_t>(side - 1, uint64_t(std::max<int64_t>(0, int64_t(x >> (20 - l)) + dx)));
          const uint64_t py = std::min<uint64_t>(side - 1, uint64_t(std::max<int64_t>(0, int64_t(y >> (20 - l)) + dy)));
          const Interval iv = dagmh_test::admissible_at(h, l, px, py);
          const float v = o.eval->depth(l, px, py);
          ASSERT_TRUE(iv.lo <= v && v <= iv.hi) << "level " << l << " (" << px << ", " << py << ")";
          for (uint32_t r : {2u, 5u, 9u})
            ASSERT_EQ(o.eval->pcf(l, px, py, r, 0.5f), o.eval->Evaluator::pcf(l, px, py, r, 0.5f));
        }
}

TEST(DagmhRoundTrip, FinerLevelsAndOutOfRangeCoordinatesAreClamped) {
  const Hierarchy h = random_hierarchy(6, 4, 0.6, 0.5, dagmh_test::mixed_interval);
  auto o = encode_and_open(h);
  for (uint64_t y = 0; y < 64; y += 3)
    for (uint64_t x = 0; x < 64; x += 5) {
      EXPECT_EQ(o.eval->depth(8, 4 * x + 3, 4 * y + 1), o.eval->depth(6, x, y));
      EXPECT_EQ(o.eval->depth(2, 1000 + x, y / 16), o.eval->depth(2, 3, y / 16));
    }
}

TEST(DagmhRoundTrip, PcfEqualsTheAverageOfSingleLookupsExactly) {
  const uint32_t side = fields::small_test_scale() ? 64 : 256;
  const auto tile = fields::scene_field(side, 11);
  const Hierarchy h = build_hierarchy(tile);
  auto o = encode_and_open(h);
  fields::Rng rng(5);
  const int taps = fields::small_test_scale() ? 300 : 3000;
  for (int t = 0; t < taps; ++t) {
    const uint32_t level = rng.below(h.depth + 1);
    const uint64_t s = uint64_t(1) << level;
    const uint64_t x = rng.below(uint32_t(s)), y = rng.below(uint32_t(s));
    const uint32_t r = 1 + rng.below(9);
    const float receiver = float(rng.uniform(-0.05, 1.05));
    const float fast = o.eval->pcf(level, x, y, r, receiver);
    const float slow = o.eval->Evaluator::pcf(level, x, y, r, receiver);
    ASSERT_EQ(fast, slow) << "level " << level << " (" << x << ", " << y << ") r " << r;
  }
  // Every kernel size at the corners (clamped taps) and at a node boundary.
  for (uint32_t r = 1; r <= 9; ++r)
    for (uint64_t c : {uint64_t(0), uint64_t(side / 2 - 1), uint64_t(side / 2), uint64_t(side - 1)})
      for (float receiver : {0.0f, 0.3f, 0.7f, 1.0f})
        ASSERT_EQ(o.eval->pcf(h.depth, c, c, r, receiver), o.eval->Evaluator::pcf(h.depth, c, c, r, receiver));
}

// View::finish_siblings (the tile batch's kept regions): every texel under the reported
// node whose child is in the mask has the walk's value index, the index is finish()'s,
// and some masks hold more than the region node (the sibling rule is not vacuous). Then
// pcf_batch over rows, zigzags and columns of sparse random trees (missing children at
// every level, whose kept region is every missing child of the parent) equals depth().
TEST(DagmhRoundTrip, SiblingRegionsShareTheAnswer) {
  const int runs = fields::small_test_scale() ? 6 : 24;
  uint64_t wider = 0;
  for (int seed = 0; seed < runs; ++seed) {
    const uint32_t depth = 3 + uint32_t(seed % 6);
    const Hierarchy h = random_hierarchy(depth, uint64_t(seed) + 900, 0.3 + 0.1 * (seed % 5), 0.3,
                                         dagmh_test::mixed_interval);
    auto o = encode_and_open(h);
    const dagmh::View v = dagmh::validate(o.bytes);
    fields::Rng rng{uint64_t(seed)};
    for (uint32_t level = 0; level <= depth; ++level)
      for (int k = 0; k < 40; ++k) {
        const uint64_t side = uint64_t(1) << level, x = rng.below(uint32_t(side)), y = rng.below(uint32_t(side));
        const dagmh::Cursor c = v.descend(v.start(level, level, x, y), level, level, x, y);
        const uint32_t tag = c.ref & dagmh::kRefTagMask;
        if (tag != dagmh::kRefInner && tag != dagmh::kRefTreelet) continue;  // the caller's case
        uint32_t s = 0, mask = 0;
        const uint32_t index = v.finish_siblings(c, level, x, y, s, mask);
        ASSERT_EQ(index, v.finish(c, level, x, y));
        ASSERT_TRUE(s >= 1 && s <= level + 1 && mask != 0 && mask < 16);
        wider += std::popcount(mask) > 1;
        const uint64_t half = uint64_t(1) << (s - 1), x0 = (x >> s) << s, y0 = (y >> s) << s;
        for (uint32_t ch = 0; ch < 4; ++ch) {
          if (!((mask >> ch) & 1)) continue;
          const uint64_t cx = x0 + (ch & 1) * half, cy = y0 + (ch >> 1) * half;
          for (uint64_t j = 0; j < half && cy + j < side; j += std::max<uint64_t>(1, half / 4))
            for (uint64_t i = 0; i < half && cx + i < side; i += std::max<uint64_t>(1, half / 4))
              ASSERT_EQ(v.lookup_index(level, cx + i, cy + j), index)
                  << "seed " << seed << " level " << level << " texel " << x << "," << y << " s " << s << " mask "
                  << mask << " child " << ch;
        }
      }
    std::vector<PcfQuery> q;
    const uint64_t side = uint64_t(1) << depth;
    auto tap = [&](uint64_t x, uint64_t y) {  // a receiver at the texel's depth or just behind it
      const float d = o.eval->depth(depth, x, y);
      q.push_back({x, y, depth, 1, q.size() & 1 ? d : std::nextafter(d, INFINITY)});
    };
    for (uint64_t y = 0; y < side; y += 1 + side / 16)
      for (uint64_t k = 0; k < side; ++k) tap(y & 1 ? side - 1 - k : k, y), tap(y, k);  // rows (zigzag), columns
    std::vector<float> got(q.size());
    o.eval->pcf_batch(q, got);
    for (size_t i = 0; i < q.size(); ++i)
      ASSERT_EQ(got[i], q[i].receiver <= o.eval->depth(depth, q[i].x, q[i].y) ? 1.0f : 0.0f)
          << "seed " << seed << " query " << i;
  }
  EXPECT_GT(wider, 0u);
}

TEST(DagmhRoundTrip, RealisticFieldBytesPerValuedNode) {
  const uint32_t side = fields::small_test_scale() ? 128 : 1024;
  const auto tile = fields::scene_field(side, 2);
  const Hierarchy h = build_hierarchy(tile);
  dagmh::EncodeStats st;
  const auto bytes = dagmh::encode(h, &st);
  auto e = open_dagmh(bytes);
  EXPECT_EQ(fields::first_violation(tile, [&](uint32_t i, uint32_t j) { return e->depth(h.depth, i, j); }), "");
  const double per_valued = double(bytes.size()) / double(h.valued_count());
  std::printf("scene_field %u^2: %zu nodes, %zu valued, %zu bytes = %.2f B/valued node "
              "(tree inner %llu -> dag %llu, treelets %llu -> %llu, skip L%u %llu B, nodes %llu B, "
              "treelets %llu B, chunks %llu B, multipliers %llu B; chunks %llu: base-only %llu, raw %llu, "
              "%llu multipliers avg %.1f bits)\n",
              side, h.node_count(), h.valued_count(), bytes.size(), per_valued,
              (unsigned long long)st.tree_inner, (unsigned long long)st.dag_inner,
              (unsigned long long)st.tree_treelets, (unsigned long long)st.dag_treelets, st.skip_level,
              (unsigned long long)st.skip_bytes, (unsigned long long)st.node_bytes,
              (unsigned long long)st.treelet_bytes, (unsigned long long)st.chunk_bytes,
              (unsigned long long)st.multiplier_bytes, (unsigned long long)st.values.chunks,
              (unsigned long long)st.values.base_only_chunks, (unsigned long long)st.values.raw_chunks,
              (unsigned long long)st.values.multipliers,
              st.values.multipliers ? double(st.values.multiplier_bits) / double(st.values.multipliers) : 0.0);
  // An MH quadtree spends at least 4 bytes per node + 4 per value (MH §3.2).
  EXPECT_LT(double(bytes.size()), 4.0 * double(h.node_count() + h.valued_count()));
}

}  // namespace
}  // namespace st

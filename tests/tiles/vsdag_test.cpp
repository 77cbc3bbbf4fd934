// Voxel shadow DAG (tiles/core/VSDAG.md): the exactness contract on every texel of small
// maps, depth values consistent with voxel lookups, popcount PCF equal to the average of
// single lookups for every kernel up to 17x17, common subtrees merged, and packs of vsdag
// tiles answering within the contract.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/encode/tile_cut.hpp"
#include "tiles/encode/vsdag_encode.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/vsdag_evaluator.hpp"

namespace st {
namespace {

uint32_t test_side() { return fields::small_test_scale() ? 32 : 128; }

// The slab of an interval bound, unclamped at the top (a bound of 1 is past every slab).
int64_t bound_slab(float v, uint32_t z) { return int64_t(std::floor(std::clamp(double(v), 0.0, 1.0) * (1u << z))); }

// Receivers worth testing at one texel: both bounds, their neighbours in float and in
// slabs, the ends of the range and a few random depths.
std::vector<float> receivers(Interval iv, uint32_t z, fields::Rng& rng) {
  const float slab = 1.0f / float(1u << z);
  std::vector<float> out{0.0f, 1.0f, -0.0f, float(rng.uniform()), float(rng.uniform())};
  for (float b : {iv.lo, iv.hi})
    for (float d : {0.0f, slab, 2 * slab, -slab, -2 * slab}) {
      const float v = b + d;
      out.push_back(v), out.push_back(std::nextafter(v, -2.0f)), out.push_back(std::nextafter(v, 2.0f));
    }
  return out;
}

// "" when every texel of `tile` answers within the contract (VSDAG.md "Exactness"):
// receivers in [0, 1] before lo in an earlier slab than lo's are lit, receivers past hi in
// a later slab than hi's are shadowed; and the lit test on depth() agrees with the voxel.
template <class Lit, class Depth>
std::string contract_violation(const IntervalTile& tile, uint32_t z, Lit&& lit, Depth&& depth, uint64_t seed) {
  fields::Rng rng(seed);
  for (uint32_t j = 0; j < tile.height; ++j)
    for (uint32_t i = 0; i < tile.width; ++i) {
      const Interval iv = tile.at(i, j);
      const float d = depth(i, j);
      for (float r : receivers(iv, z, rng)) {
        if (!(r >= 0.0f && r <= 1.0f)) continue;
        const bool got = lit(i, j, r);
        const int64_t k = std::min<int64_t>(int64_t(std::floor(double(r) * (1u << z))), (1 << z) - 1);
        const char* wrong = nullptr;
        if (r < iv.lo && k < bound_slab(iv.lo, z) && !got) wrong = "shadowed before lo's slab";
        if (r > iv.hi && k > bound_slab(iv.hi, z) && got) wrong = "lit past hi's slab";
        if (got != (r <= d)) wrong = "voxel and depth() disagree";
        if (wrong)
          return "texel (" + std::to_string(i) + ", " + std::to_string(j) + ") [" + std::to_string(iv.lo) + ", " +
                 std::to_string(iv.hi) + "] receiver " + std::to_string(r) + ": " + wrong;
      }
    }
  return "";
}

TEST(Vsdag, EveryTexelOfEveryFieldAnswersWithinTheContract) {
  for (uint32_t z : {3u, 9u, 16u})
    for (const fields::NamedField& f : fields::all_fields(test_side(), 7)) {
      const Hierarchy h = build_hierarchy(f.tile);
      const std::vector<uint8_t> bytes = encode_vsdag(h, VsdagOptions{z});
      const VsdagEvaluator ev(bytes);
      ASSERT_EQ(ev.finest_level(), h.depth);
      const std::string bad = contract_violation(
          f.tile, z, [&](uint32_t i, uint32_t j, float r) { return ev.lit_voxel(h.depth, i, j, r); },
          [&](uint32_t i, uint32_t j) { return ev.depth(h.depth, i, j); }, z);
      EXPECT_EQ(bad, "") << f.name << " z_bits " << z;
    }
}

TEST(Vsdag, DepthIsLosslessWhereASlabBoundaryLiesInsideTheInterval) {
  // A closed box wider than a slab: the transition lands inside [lo, hi], so depth() keeps
  // the lossless invariant there (the contract's exact case).
  const uint32_t side = 64, z = 8;
  IntervalTile t = fields::constant_field(side, Interval{0.30f, 0.70f});
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i)
      if ((i / 8 + j / 8) % 2) t.at(i, j) = Interval{0.1f + 0.01f * float(i % 8), 0.9f};
  const std::vector<uint8_t> bytes = encode_vsdag(build_hierarchy(t), VsdagOptions{z});
  const VsdagEvaluator ev(bytes);
  EXPECT_EQ(fields::first_violation(t, [&](uint32_t i, uint32_t j) { return ev.depth(t.level, i, j); }), "");
}

TEST(Vsdag, TransitionIsTheMostAlignedSlabInTheAdmissibleRange) {
  EXPECT_EQ(vsdag_transition(0.25f, 0.5f, 3), 4u);   // slabs [2, 5]: 4 has the most zero bits
  EXPECT_EQ(vsdag_transition(1.0f, 1.0f, 8), 256u);  // nothing hit: lit throughout
  EXPECT_EQ(vsdag_transition(0.0f, 0.0f, 8), 0u);
  EXPECT_EQ(vsdag_transition(0.5f, 0.5f, 8), 128u);  // on a boundary: receivers at 0.5 lie in slab 128
  const uint32_t t = vsdag_transition(0.3f, 0.3f, 16);
  EXPECT_TRUE(t == uint32_t(std::floor(0.3 * 65536)) || t == uint32_t(std::floor(0.3 * 65536)) + 1);
  EXPECT_THROW(vsdag_transition(0.6f, 0.5f, 8), Error);
  EXPECT_THROW(vsdag_transition(NAN, 0.5f, 8), Error);
}

TEST(Vsdag, PopcountPcfEqualsTheAverageOfSingleLookups) {
  const uint32_t side = test_side();
  for (const fields::NamedField& f : fields::all_fields(side, 3)) {
    const std::vector<uint8_t> bytes = encode_vsdag(build_hierarchy(f.tile), VsdagOptions{12});
    const VsdagEvaluator ev(bytes);
    fields::Rng rng(11);
    for (int q = 0; q < 300; ++q) {
      const uint64_t x = rng.below(side), y = rng.below(side);
      const Interval iv = f.tile.at(uint32_t(x), uint32_t(y));
      const float r = q % 3 == 0 ? float(rng.uniform()) : std::clamp(q % 3 == 1 ? iv.lo : iv.hi, 0.0f, 1.0f);
      for (uint32_t k : {1u, 2u, 3u, 8u, 9u, 16u, 17u}) {
        uint32_t lit = 0;
        for (uint32_t j = 0; j < k; ++j)
          for (uint32_t i = 0; i < k; ++i)
            lit += ev.lit_voxel(f.tile.level, pcf_tap(x, i, k, side), pcf_tap(y, j, k, side), r);
        const float want = float(lit) / float(k * k);
        ASSERT_EQ(ev.pcf_wide(x, y, k, r, true), want) << f.name << " " << k << " at " << x << "," << y;
        ASSERT_EQ(ev.pcf_wide(x, y, k, r, false), want) << f.name << " raster order " << k;
        if (k <= Evaluator::kMaxPcf) {
          ASSERT_EQ(ev.pcf(f.tile.level, x, y, k, r), want);
        }
      }
      // Coarser levels answer with each texel's first finest descendant.
      const uint32_t l = f.tile.level - 2;
      ASSERT_EQ(ev.lit_voxel(l, x / 4, y / 4, r), ev.lit_voxel(f.tile.level, x / 4 * 4, y / 4 * 4, r));
    }
  }
}

// Every node and every leaf of the buffer differs from every other: identical subtrees
// were merged (§3, "reduce to an optimal DAG").
void expect_merged(std::span<const uint8_t> bytes) {
  const VsdagEvaluator ev(bytes);
  const vsdag::View& v = ev.view();
  // The level of every node, from the grid down (validation made it unique).
  std::vector<int> level(v.node_words, -1);
  std::vector<uint32_t> todo;
  for (uint32_t c = 0; c < v.shape.grid_cells(); ++c)
    if ((v.grid_word(c) >> vsdag::kStateShift) == vsdag::kMixed) {
      level[v.grid_word(c) & vsdag::kIndexMask] = 0;
      todo.push_back(v.grid_word(c) & vsdag::kIndexMask);
    }
  while (!todo.empty()) {
    const uint32_t w = todo.back();
    todo.pop_back();
    if (uint32_t(level[w]) == v.shape.levels) continue;
    const uint32_t n = uint32_t(std::popcount(vsdag::mixed_bits(v.node_word(w))));
    for (uint32_t k = 1; k <= n; ++k)
      if (level[v.node_word(w + k)] < 0) level[v.node_word(w + k)] = level[w] + 1, todo.push_back(v.node_word(w + k));
  }
  std::set<std::vector<uint32_t>> nodes;
  for (uint32_t w = 0; w < v.node_words;) {
    const uint32_t n = 1 + uint32_t(std::popcount(vsdag::mixed_bits(v.node_word(w))));
    std::vector<uint32_t> words{uint32_t(level[w])};
    for (uint32_t k = 0; k < n; ++k) words.push_back(v.node_word(w + k));
    EXPECT_TRUE(nodes.insert(words).second) << "node at word " << w << " repeats an earlier one of its level";
    w += n;
  }
  std::set<uint64_t> leaves;
  for (uint32_t i = 0; i < v.leaf_count; ++i) EXPECT_TRUE(leaves.insert(v.leaf(i)).second) << "leaf " << i;
}

TEST(Vsdag, IdenticalSubtreesAreStoredOnce) {
  const uint32_t side = test_side();
  // A 32x32 pattern repeated over the tile: the DAG is the size of one copy (plus the
  // nodes above), while a same-size field without repeats is many times larger.
  const IntervalTile base = fields::city_field(32, 5);
  IntervalTile rep = fields::constant_field(side, Interval{});
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) rep.at(i, j) = base.at(i % 32, j % 32);
  const std::vector<uint8_t> once = encode_vsdag(build_hierarchy(base), VsdagOptions{10});
  const std::vector<uint8_t> many = encode_vsdag(build_hierarchy(rep), VsdagOptions{10});
  expect_merged(once);
  expect_merged(many);
  EXPECT_LT(many.size(), 2 * once.size() + 4096) << "repeated copies were not shared";
  for (const fields::NamedField& f : fields::all_fields(side, 9)) expect_merged(encode_vsdag(build_hierarchy(f.tile), VsdagOptions{16}));
}

TEST(Vsdag, ClosedObjectsNeedDetailOnlyAtTheirSilhouettes) {
  // The undefined inside of closed boxes (§6.1) lets whole columns share one transition:
  // a field of deep closed boxes encodes far smaller than the same boxes as open tops.
  const uint32_t side = test_side();
  const IntervalTile closed = fields::city_field(side, 2);
  IntervalTile open = closed;
  for (Interval& iv : open.data) iv.hi = iv.lo;
  const size_t c = encode_vsdag(build_hierarchy(closed), VsdagOptions{16}).size();
  const size_t o = encode_vsdag(build_hierarchy(open), VsdagOptions{16}).size();
  EXPECT_LT(c, o) << "closed " << c << " B, open " << o << " B";
}

TEST(Vsdag, PackOfVsdagTilesAnswersWithinTheContract) {
  const uint32_t side = fields::small_test_scale() ? 64 : 128, z = 16;
  for (const fields::NamedField& f : {fields::NamedField{"city", fields::city_field(side, 4)},
                                      fields::NamedField{"scene", fields::scene_field(side, 4)}}) {
    const Hierarchy h = build_hierarchy(f.tile);
    CutParams cut;
    cut.map_level = h.depth;
    cut.skip_level = 2;
    cut.tile_bytes = 2048;  // forces index tiles and several levels of cuts
    cut.codec = TileCodec::of(Encoding::vsdag);
    cut.codec.encode = [](const Hierarchy& sub) { return encode_vsdag(sub, VsdagOptions{z}); };
    PackParams pp = PackParams::from(LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"),
                                                     Aabb{{-10, 0, -10}, {10, 5, 10}}),
                                     cut);
    pp.build_params = {{"scene", f.name}};
    const std::string path = packtest::temp_path("vsdag_" + f.name + ".pack");
    write_pack(path, h, cut, pp);
    std::shared_ptr<PackReader> reader(PackReader::open(path));
    EXPECT_EQ(reader->header().encoding, Encoding::vsdag);
    PackEvaluator ev(reader, 16);
    const std::string bad = contract_violation(
        f.tile, z, [&](uint32_t i, uint32_t j, float r) { return ev.pcf(h.depth, i, j, 1, r) == 1.0f; },
        [&](uint32_t i, uint32_t j) { return ev.depth(h.depth, i, j); }, 5);
    EXPECT_EQ(bad, "") << f.name;
    std::filesystem::remove(path);
  }
}

}  // namespace
}  // namespace st

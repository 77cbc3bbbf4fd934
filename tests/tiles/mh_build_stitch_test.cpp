// Tiled construction (MH §3.1): a map built whole and built as 4 or 16 stitched tiles
// both satisfy the invariants on every texel.
#include <gtest/gtest.h>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/mh_build_checks.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"

namespace st {
namespace {

IntervalTile sub_tile(const IntervalTile& map, uint32_t ti, uint32_t tj, uint32_t side) {
  IntervalTile t;
  t.level = map.level;
  t.x0 = uint64_t(ti) * side, t.y0 = uint64_t(tj) * side;
  t.width = t.height = side;
  t.data.resize(size_t(side) * side);
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) t.at(i, j) = map.at(uint32_t(t.x0) + i, uint32_t(t.y0) + j);
  return t;
}

Hierarchy build_tiled(const IntervalTile& map, uint32_t grid_level, MhConstruction method) {
  const uint32_t grid = 1u << grid_level, side = map.width / grid;
  std::vector<Hierarchy> tiles;
  for (uint32_t tj = 0; tj < grid; ++tj)
    for (uint32_t ti = 0; ti < grid; ++ti) tiles.push_back(build_hierarchy(sub_tile(map, ti, tj, side), method));
  return stitch_tiles(std::move(tiles), grid_level, method);
}

class MhStitch : public ::testing::TestWithParam<MhConstruction> {};

TEST_P(MhStitch, WholeAndStitchedMapsBothSatisfyTheInvariants) {
  const MhConstruction method = GetParam();
  const bool exact = method == MhConstruction::bottom_up;
  const uint32_t side = fields::small_test_scale() ? 64 : 256;
  for (uint64_t seed : {3ull, 4ull})
    for (auto& f : fields::all_fields(side, seed)) {
      Hierarchy whole = build_hierarchy(f.tile, method);
      for (uint32_t grid_level : {0u, 1u, 2u, 3u}) {
        Hierarchy h = build_tiled(f.tile, grid_level, method);
        std::string what = f.name + " seed " + std::to_string(seed) + " as " + std::to_string(1u << grid_level) +
                           "² tiles, " + (exact ? "bottom-up" : "top-down");
        ASSERT_EQ(h.depth, whole.depth) << what;
        ASSERT_EQ(fields::check_well_formed(h), "") << what;
        ASSERT_EQ(fields::check_lossless(h, f.tile), "") << what;
        ASSERT_EQ(fields::check_levels_complete(h, f.tile), "") << what;
        ASSERT_EQ(fields::check_admissible(h, f.tile, exact), "") << what;
        // Stitching only loses cross-tile merges: a bounded growth over the whole build.
        EXPECT_LE(h.node_count(), whole.node_count() * 2 + (size_t(4) << (2 * grid_level))) << what;
      }
    }
}

TEST_P(MhStitch, SmallTilesAndDegenerateGrids) {
  // 1x1 tiles: the coarse hierarchy is the whole hierarchy.
  IntervalTile map = fields::special_values_field(16, 9);
  Hierarchy h = build_tiled(map, 4, GetParam());
  EXPECT_EQ(fields::check_well_formed(h), "");
  EXPECT_EQ(fields::check_lossless(h, map), "");
  // A constant map in 16 tiles collapses to one root.
  IntervalTile flat = fields::constant_field(32, {0.3f, 0.4f});
  Hierarchy c = build_tiled(flat, 2, GetParam());
  EXPECT_EQ(c.node_count(), 1u);
  EXPECT_EQ(fields::check_lossless(c, flat), "");
}

// A hand-made tile of depth `n`: root 0.5 (an exact point) with one deep texel at
// (x, y) holding 0.25 behind a chain of empty nodes.
Hierarchy deep_chain_tile(uint32_t n, uint32_t x, uint32_t y) {
  Hierarchy h;
  h.depth = n;
  h.levels.resize(n + 1);
  h.levels[0].push_back(HNode{0, 0.5f, 0.5f, 0.5f, 0, 1});
  for (uint32_t l = 1; l <= n; ++l) {
    uint64_t m = morton_encode(x >> (n - l), y >> (n - l));
    h.levels[l - 1].back().child_mask = uint8_t(1u << (m & 3));
    h.levels[l].push_back(l == n ? HNode{m, 0.25f, 0.25f, 0.25f, 0, 1} : HNode{m, 0, 0, 0, 0, 0});
  }
  return h;
}

TEST_P(MhStitch, ReachesLevel20) {
  // 16 tiles of depth 18: one 2^20 map, checked at the deep texels and their neighbours.
  constexpr uint32_t kTileDepth = 18, kGrid = 2;
  std::vector<Hierarchy> tiles;
  std::vector<std::pair<uint64_t, uint64_t>> deep;
  for (uint32_t t = 0; t < 16; ++t) {
    uint32_t x = (t * 40503u + 7) & ((1u << kTileDepth) - 1), y = (t * 9973u + 3) & ((1u << kTileDepth) - 1);
    tiles.push_back(deep_chain_tile(kTileDepth, x, y));
    deep.push_back({(uint64_t(t % 4) << kTileDepth) + x, (uint64_t(t / 4) << kTileDepth) + y});
  }
  Hierarchy h = stitch_tiles(std::move(tiles), kGrid, GetParam());
  ASSERT_EQ(h.depth, 20u);
  ASSERT_EQ(fields::check_well_formed(h), "");
  // Same roots everywhere: one coarse root, the tile roots turned empty.
  EXPECT_EQ(h.levels[0][0].value, 0.5f);
  EXPECT_EQ(h.levels[kGrid].size(), 16u);
  for (const HNode& n : h.levels[kGrid]) EXPECT_FALSE(n.has_value);
  for (auto [x, y] : deep) {
    EXPECT_EQ(h.depth_at(20, x, y), 0.25f) << x << "," << y;
    EXPECT_EQ(h.depth_at(20, x ^ 1, y), 0.5f) << x << "," << y;
    EXPECT_EQ(h.depth_at(19, x >> 1, y >> 1), 0.5f);
  }
}

TEST_P(MhStitch, RejectsInconsistentTiles) {
  auto tile = [](uint32_t side) { return build_hierarchy(fields::uniform_field(side, 1)); };
  std::vector<Hierarchy> three;
  for (int i = 0; i < 3; ++i) three.push_back(tile(4));
  EXPECT_THROW(stitch_tiles(std::move(three), 1, GetParam()), Error);
  std::vector<Hierarchy> mixed;
  for (int i = 0; i < 4; ++i) mixed.push_back(tile(i == 2 ? 8 : 4));
  try {
    stitch_tiles(std::move(mixed), 1, GetParam());
    ADD_FAILURE() << "mixed depths accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("tile 2"), std::string::npos) << e.what();
  }
  std::vector<Hierarchy> rootless;
  for (int i = 0; i < 4; ++i) rootless.push_back(tile(4));
  rootless[1].levels[0][0].has_value = 0;
  EXPECT_THROW(stitch_tiles(std::move(rootless), 1, GetParam()), Error);
  std::vector<Hierarchy> too_deep;
  for (int i = 0; i < 4; ++i) {
    Hierarchy h;
    h.depth = 20;
    h.levels.resize(21);
    h.levels[0].push_back(HNode{0, 0.5f, 0.5f, 0.5f, 0, 1});
    too_deep.push_back(std::move(h));
  }
  EXPECT_THROW(stitch_tiles(std::move(too_deep), 1, GetParam()), Error);
}

INSTANTIATE_TEST_SUITE_P(Constructions, MhStitch,
                         ::testing::Values(MhConstruction::bottom_up, MhConstruction::top_down),
                         [](const auto& info) {
                           return std::string(info.param == MhConstruction::bottom_up ? "bottom_up" : "top_down");
                         });

}  // namespace
}  // namespace st

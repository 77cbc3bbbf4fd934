// The cut (tile_cut.hpp, tile_cut_grid.hpp): tile ids, the grid format, splitting a
// hierarchy at a level, and cutting cells into tiles and index tiles.
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <set>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/mh_build_checks.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/tile_cut.hpp"

namespace st {
namespace {

using packtest::bits;

TEST(TileId, RoundTripsEveryLevelUpTo20) {
  fields::Rng rng(5);
  for (uint32_t level = 0; level <= kMaxLevel; ++level) {
    const uint32_t side = 1u << level;
    std::vector<std::pair<uint32_t, uint32_t>> xy = {{0, 0}, {side - 1, side - 1}, {side - 1, 0}, {0, side - 1}};
    for (int i = 0; i < 200; ++i) xy.push_back({rng.below(side), rng.below(side)});
    for (auto [x, y] : xy) {
      uint64_t id = make_tile_id(level, x, y);
      ASSERT_TRUE(is_valid_tile_id(id));
      EXPECT_EQ(tile_address(id), (TileAddress{level, x, y})) << describe_tile(id);
      EXPECT_EQ(id >> kTileIdLevelShift, level);
    }
  }
  // Ordering: level first, then the Z curve.
  EXPECT_LT(make_tile_id(3, 7, 7), make_tile_id(4, 0, 0));
  EXPECT_LT(make_tile_id(4, 1, 0), make_tile_id(4, 0, 1));
}

// tile_parent(id, j) is the tile whose root covers id's root j levels up (coordinates
// halved j times), tile_child_morton(id, j) id's place inside it, and together they give
// id back: the decoding GpuMap's pointer words and the client's wants rely on.
TEST(TileId, ParentAndChildWithinItRebuildTheId) {
  fields::Rng rng(9);
  for (uint32_t level = 0; level <= kMaxLevel; ++level)
    for (int i = 0; i < 50; ++i) {
      const uint32_t x = rng.below(1u << level), y = rng.below(1u << level);
      const uint64_t id = make_tile_id(level, x, y);
      EXPECT_EQ(tile_level(id), level);
      EXPECT_EQ(tile_parent(id, 0), id);
      for (uint32_t j = 1; j <= level; ++j) {
        const uint64_t parent = tile_parent(id, j);
        ASSERT_EQ(parent, make_tile_id(level - j, x >> j, y >> j)) << describe_tile(id) << " j " << j;
        const uint64_t low = tile_child_morton(id, j);
        ASSERT_LT(low, uint64_t(1) << (2 * j));
        EXPECT_EQ(make_tile_id(level, ((x >> j) << j), ((y >> j) << j)) + low, id);
        EXPECT_EQ((uint64_t(level) << kTileIdLevelShift) | (tile_morton(parent) << (2 * j)) | low, id);
      }
    }
}

TEST(TileId, RejectsInvalidIds) {
  EXPECT_FALSE(is_valid_tile_id(uint64_t(21) << kTileIdLevelShift));
  EXPECT_FALSE(is_valid_tile_id((uint64_t(2) << kTileIdLevelShift) | 16));  // morton >= 4^2
  EXPECT_FALSE(is_valid_tile_id(~uint64_t(0)));
  EXPECT_THROW(tile_address((uint64_t(1) << kTileIdLevelShift) | 4), FormatError);
  EXPECT_NE(describe_tile(make_tile_id(20, 1048575, 3)).find("level 20, x 1048575, y 3"), std::string::npos);
}

CutGrid sample_grid() {
  CutGrid g = CutGrid::constant(2, 0.25f);
  g.coarse_at(1, 1, 0) = 0.5f;
  g.entry(3, 1) = GridEntry{0.75f, EntryKind::tile, 0};
  g.entry(0, 2) = GridEntry{-0.0f, EntryKind::index, 3};
  return g;
}

TEST(CutGridFormat, OffsetsArePinned) {
  CutGrid g = sample_grid();
  std::vector<uint8_t> b = g.serialize();
  ASSERT_EQ(b.size(), CutGrid::serialized_size(2));
  ASSERT_EQ(b.size(), 8u + 4 * 5 + 8 * 16);
  auto u32 = [&](size_t o) { uint32_t v; std::memcpy(&v, &b[o], 4); return v; };
  EXPECT_EQ(std::memcmp(b.data(), "STGR", 4), 0);
  EXPECT_EQ(u32(4), 2u);
  EXPECT_EQ(u32(8), bits(0.25f));                 // level 0
  EXPECT_EQ(u32(8 + 4 * (1 + 1)), bits(0.5f));    // level 1, (1, 0)
  const size_t entries = 8 + 4 * 5;
  const size_t e31 = entries + 8 * (1 * 4 + 3), e02 = entries + 8 * (2 * 4 + 0);
  EXPECT_EQ(u32(e31), bits(0.75f));
  EXPECT_EQ(b[e31 + 4], 1);
  EXPECT_EQ(u32(e02), bits(-0.0f));
  EXPECT_EQ(b[e02 + 4], 2);
  EXPECT_EQ(b[e02 + 5], 3);
  CutGrid back = CutGrid::parse(b, "grid");
  EXPECT_EQ(back.serialize(), b);
  EXPECT_EQ(back.entries, g.entries);
}

TEST(CutGridFormat, EveryTruncationAndBadFieldIsAFormatError) {
  std::vector<uint8_t> b = sample_grid().serialize();
  for (size_t n = 0; n < b.size(); ++n)
    EXPECT_THROW(CutGrid::parse(std::span(b).first(n), "grid"), FormatError) << n;
  std::vector<uint8_t> longer = b;
  longer.push_back(0);
  EXPECT_THROW(CutGrid::parse(longer, "grid"), FormatError);
  const size_t entries = 8 + 4 * 5;
  for (auto [off, val] : std::vector<std::pair<size_t, uint8_t>>{
           {0, 'X'}, {4, 11}, {entries + 4, 3}, {entries + 5, 1}, {entries + 6, 1}, {entries + 8 * 8 + 5, 0}}) {
    std::vector<uint8_t> bad = b;
    bad[off] = val;
    try {
      CutGrid::parse(bad, "grid g");
      ADD_FAILURE() << "byte " << off << " accepted";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("grid g"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("at byte"), std::string::npos) << e.what();
    }
  }
  std::vector<uint8_t> nan = b;
  float q = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&nan[8], &q, 4);
  EXPECT_THROW(CutGrid::parse(nan, "grid"), FormatError);
}

// Splitting at every level d: levels <= d come from the grid, finer ones from the
// subtrees, all equal to depth_at of the whole hierarchy; subtrees are well formed.
TEST(SplitHierarchy, AnswersExactlyAtEveryLevel) {
  for (auto& f : fields::all_fields(32, 3)) {
    Hierarchy h = build_hierarchy(f.tile);
    for (uint32_t d = 0; d <= h.depth; ++d) {
      SplitResult s = split_hierarchy(h, d);
      const std::string what = f.name + " d=" + std::to_string(d);
      for (uint32_t l = 0; l <= h.depth; ++l)
        for (uint32_t y = 0; y < (1u << l); ++y)
          for (uint32_t x = 0; x < (1u << l); ++x) {
            float want = h.depth_at(l, x, y), got;
            if (l <= d) {
              got = s.grid.value_at(l, x, y);
            } else {
              uint32_t r = l - d;
              size_t i = size_t(y >> r) * (1u << d) + (x >> r);
              const auto& sub = s.subtrees[i];
              got = sub ? sub->depth_at(r, x & ((1u << r) - 1), y & ((1u << r) - 1)) : s.grid.entries[i].value;
            }
            ASSERT_EQ(bits(got), bits(want)) << what << " level " << l << " (" << x << ", " << y << ")";
          }
      for (size_t i = 0; i < s.subtrees.size(); ++i) {
        if (!s.subtrees[i]) continue;
        ASSERT_EQ(fields::check_well_formed(*s.subtrees[i]), "") << what;
        const HNode& root = s.subtrees[i]->levels[0][0];
        EXPECT_TRUE(root.lo <= root.value && root.value <= root.hi) << what;
        EXPECT_EQ(bits(root.value), bits(s.grid.entries[i].value)) << what;
      }
    }
  }
}

CutParams params_for(Encoding e, uint32_t level, uint32_t skip, uint32_t tile_bytes) {
  CutParams p;
  p.map_level = level;
  p.skip_level = skip;
  p.tile_bytes = tile_bytes;
  p.codec = TileCodec::of(e);
  return p;
}

TEST(TileCutter, ConstantAndEmptyCellsProduceNoTiles) {
  for (Encoding e : packtest::available_encodings()) {
    IntervalTile t = fields::constant_field(16, Interval{0.25f, 0.5f});
    TileCutter cutter(params_for(e, 4, 2, kDefaultTileBytes));
    for (uint32_t cy = 0; cy < 4; ++cy)
      for (uint32_t cx = 0; cx < 4; ++cx) {
        CutCell c = cutter.cut_cell(cx, cy, build_hierarchy(packtest::sub_tile(t, cx * 4, cy * 4, 4)));
        EXPECT_EQ(c.entry.kind, EntryKind::constant);
        EXPECT_TRUE(c.tiles.empty());
        EXPECT_TRUE(c.lo <= c.entry.value && c.entry.value <= c.hi);
      }
  }
}

// A tiny tile bound forces index tiles; every tile stays within the bound, ids are
// unique, children come before the index tile that names them and the cell's own tile last.
TEST(TileCutter, SmallTileBytesCutsDeeperWithinTheBound) {
  for (Encoding e : packtest::available_encodings()) {
    IntervalTile t = fields::uniform_field(64, 9);
    TileCutter cutter(params_for(e, 6, 1, 256));
    size_t index_tiles = 0;
    for (uint32_t cy = 0; cy < 2; ++cy)
      for (uint32_t cx = 0; cx < 2; ++cx) {
        CutCell c = cutter.cut_cell(cx, cy, build_hierarchy(packtest::sub_tile(t, cx * 32, cy * 32, 32)));
        ASSERT_EQ(c.entry.kind, EntryKind::index) << to_string(e);
        ASSERT_FALSE(c.tiles.empty());
        EXPECT_EQ(c.tiles.back().id, make_tile_id(1, cx, cy));
        std::set<uint64_t> seen;
        for (const CutTile& tile : c.tiles) {
          EXPECT_LE(tile.raw.size(), 256u) << describe_tile(tile.id);
          EXPECT_TRUE(seen.insert(tile.id).second) << describe_tile(tile.id);
          TileAddress a = tile_address(tile.id);
          EXPECT_EQ(a.x >> (a.level - 1), cx);
          EXPECT_EQ(a.y >> (a.level - 1), cy);
          if (tile.kind == TileKind::index) {
            ++index_tiles;
            CutGrid g = CutGrid::parse(tile.raw, "index", kMaxIndexLevels);
            for (uint32_t j = 0; j < (1u << g.levels); ++j)
              for (uint32_t i = 0; i < (1u << g.levels); ++i)
                if (g.entry(i, j).kind != EntryKind::constant) {
                  EXPECT_TRUE(seen.count(make_tile_id(a.level + g.levels, (a.x << g.levels) + i, (a.y << g.levels) + j)))
                      << "child of " << describe_tile(tile.id) << " not before it";
                }
          }
        }
      }
    EXPECT_GT(index_tiles, 4u) << to_string(e);
  }
}

TEST(TileCutter, RejectsBadInput) {
  if (packtest::available_encodings().empty()) GTEST_SKIP() << "no encoding linked";
  Encoding e = packtest::available_encodings()[0];
  EXPECT_THROW(TileCutter(params_for(e, 4, 5, kDefaultTileBytes)), Error);
  EXPECT_THROW(TileCutter(params_for(e, 4, 2, 10)), Error);
  EXPECT_THROW(TileCutter(params_for(e, 21, 2, kDefaultTileBytes)), Error);
  TileCutter cutter(params_for(e, 4, 2, kDefaultTileBytes));
  IntervalTile t = fields::uniform_field(4, 1);
  EXPECT_THROW(cutter.cut_cell(4, 0, build_hierarchy(t)), Error);
  EXPECT_THROW(cutter.cut_cell(0, 0, build_hierarchy(fields::uniform_field(8, 1))), Error);  // wrong depth
  Hierarchy broken = build_hierarchy(t);
  ASSERT_GT(broken.levels[2].size(), 1u);
  std::swap(broken.levels[2][0], broken.levels[2][1]);
  EXPECT_THROW(cutter.cut_cell(0, 0, std::move(broken)), Error);
}

TEST(DefaultSkipLevel, BoundsTheGridSize) {
  EXPECT_EQ(default_skip_level(0), 0u);
  EXPECT_EQ(default_skip_level(1), 1u);
  EXPECT_EQ(default_skip_level(6), 3u);
  EXPECT_EQ(default_skip_level(20), 8u);
  for (uint32_t l = 0; l <= kMaxLevel; ++l) {
    EXPECT_LE(default_skip_level(l), l);
    EXPECT_LE(CutGrid::serialized_size(default_skip_level(l)), size_t(1) << 20);
  }
}

}  // namespace
}  // namespace st

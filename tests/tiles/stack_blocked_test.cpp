// The out-of-core stack build (tiles/encode/stack_blocked.hpp): a stack spilled in octree
// blocks and reduced one block at a time gives the one-shot cut_stack(build_octree(...))
// grid and tiles byte for byte, and the same pack file, for wide and deep stacks, padded
// slice counts, every block level down to the skip level and a cut that must move deeper;
// and the traced sun slices (the rasterizer) are the canonical definition's bounds.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <fstream>
#include <iterator>

#include "common/error.hpp"
#include "common/parallel.hpp"
#include "tests/test_tmp.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/bake/stack_build.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/stack_map.hpp"
#include "tiles/core/stack_slices.hpp"

namespace st {
namespace {

std::string tmp(const std::string& name) { return std::string(SHADOWTILE_TEST_TMP) + "/" + name; }

std::unique_ptr<StackSpill> spill_of(const IntervalStack& s, uint32_t block_level, const std::string& name) {
  auto spill = std::make_unique<StackSpill>(tmp(name), s.level, s.slices, block_level);
  const size_t area = size_t(s.side() * s.side());
  for (uint32_t w = 0; w < s.slices; ++w)
    spill->write_rows(w, 0, s.side(), std::span<const Interval>(s.data.data() + w * area, area));
  return spill;
}

std::vector<uint8_t> file_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

void fill_lights(StackGrid& g, uint32_t n) {
  const LightSet set = LightSet::fit(
      LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=" + std::to_string(n)),
      Aabb{{-10, 0, -10}, {10, 5, 10}});
  g.light_kind = set.samples[0].kind();
  g.lights.clear();
  for (const LightSpace& l : set.samples) g.lights.push_back(l.to_array());
  g.spec = set.spec.to_string();
}

// Blocked and one-shot cuts of `s` at every block level from 0 to the skip level.
// Returns the skip level both chose.
uint32_t expect_blocked_equals_one_shot(const IntervalStack& s, std::optional<uint32_t> K, uint32_t tile_bytes,
                                        const std::string& what) {
  SCOPED_TRACE(what);
  StackCut one = cut_stack(build_octree(s), K, tile_bytes);
  fill_lights(one.grid, s.slices);
  StackPackParams p;
  p.tile_bytes = tile_bytes < kMinTileBytes ? kMinTileBytes : tile_bytes;
  write_stack_pack(tmp("one.pack"), one, p);
  const std::vector<uint8_t> one_file = file_bytes(tmp("one.pack"));
  const uint32_t Kc = K.value_or(default_stack_skip_level(one.grid.geo));
  for (uint32_t B = 0; B <= Kc; ++B) {
    SCOPED_TRACE("block level " + std::to_string(B));
    auto spill = spill_of(s, B, "blocked.spill");
    BlockedStackCut blocked(*spill, Kc, tile_bytes, tmp("blocked.tiles"));
    EXPECT_EQ(blocked.grid.skip_level, one.grid.skip_level);
    EXPECT_EQ(blocked.grid.entries, one.grid.entries);
    EXPECT_EQ(blocked.grid.coarse.size(), one.grid.coarse.size());
    for (size_t l = 0; l < one.grid.coarse.size(); ++l)
      EXPECT_EQ(0, std::memcmp(blocked.grid.coarse[l].data(), one.grid.coarse[l].data(), one.grid.coarse[l].size() * 4))
          << "level " << l;
    EXPECT_EQ(blocked.tile_count(), one.tiles.size());
    for (size_t i = 0; i < std::min(one.tiles.size(), blocked.tile_count()); ++i)
      if (blocked.tile(i) != one.tiles[i]) {
        ADD_FAILURE() << "tile " << i << " differs";
        break;
      }
    EXPECT_EQ(blocked.max_tile_bytes, one.max_tile_bytes);
    fill_lights(blocked.grid, s.slices);
    write_stack_pack(tmp("blocked.pack"), blocked.grid, blocked.tile_count(), [&](size_t i) { return blocked.tile(i); }, p);
    EXPECT_EQ(file_bytes(tmp("blocked.pack")), one_file);
  }
  return one.grid.skip_level;
}

TEST(StackBlocked, SameGridTilesAndPackAsTheOneShotBuild) {
  // Wide (n > k), deep (k > n), padded slice counts, random and coherent.
  expect_blocked_equals_one_shot(stacks::coherent_stack(5, 7, 1), std::nullopt, 1 << 20, "coherent 32^2 x 7");
  expect_blocked_equals_one_shot(stacks::random_stack(4, 5, 2), std::nullopt, 1 << 20, "random 16^2 x 5");
  expect_blocked_equals_one_shot(stacks::coherent_stack(2, 19, 3), std::nullopt, 1 << 20, "coherent 4^2 x 19");
  expect_blocked_equals_one_shot(stacks::random_stack(4, 3, 4), 3u, 1 << 20, "random 16^2 x 3, K = 3");
  // A tile bound (200 B) the default cut exceeds: both move the cut deeper.
  const IntervalStack r = stacks::random_stack(5, 6, 5);
  EXPECT_GT(expect_blocked_equals_one_shot(r, std::nullopt, 200, "random 32^2 x 6, 200-byte tiles"),
            default_stack_skip_level(build_octree(r).geo));
  // Two levels deeper (3 -> 5): one probing pass finds it.
  const IntervalStack r2 = stacks::random_stack(6, 4, 6);
  EXPECT_EQ(expect_blocked_equals_one_shot(r2, std::nullopt, 100, "random 64^2 x 4, 100-byte tiles"),
            default_stack_skip_level(build_octree(r2).geo) + 2);
}

TEST(StackBlocked, SpillRegionsAndRowsLandOnTheSameTexels) {
  const IntervalStack s = stacks::random_stack(4, 2, 8);
  StackSpill spill(tmp("regions.spill"), 4, 2, 2);  // blocks of 4 x 4 texels
  spill.write_rows(1, 0, 16, std::span<const Interval>(s.data.data() + 256, 256));
  for (uint64_t y0 = 0; y0 < 16; y0 += 8)
    for (uint64_t x0 = 0; x0 < 16; x0 += 8) {
      std::vector<Interval> part;
      for (uint64_t y = y0; y < y0 + 8; ++y)
        for (uint64_t x = x0; x < x0 + 8; ++x) part.push_back(s.at(x, y, 0));
      spill.write_region(0, x0, y0, 8, 8, part);
    }
  for (uint32_t w = 0; w < 2; ++w)
    for (uint64_t y = 0; y < 16; ++y)
      for (uint64_t x = 0; x < 16; ++x) {
        const Interval a = spill.texel(x, y, w), b = s.at(x, y, w);
        ASSERT_TRUE(a.lo == b.lo && a.hi == b.hi) << x << ", " << y << ", " << w;
      }
  EXPECT_THROW(spill.write_region(0, 2, 0, 4, 4, std::vector<Interval>(16)), Error);
}

TEST(StackBlocked, SpillRefusesRowsOffTheBlockLayout) {
  StackSpill spill(tmp("bad.spill"), 4, 2, 2);  // blocks of 4 x 4 texels
  std::vector<Interval> rows(16 * 2, Interval{0.5f, 0.5f});
  EXPECT_THROW(spill.write_rows(0, 0, 2, rows), Error);
  EXPECT_THROW(spill.write_rows(2, 0, 4, std::vector<Interval>(64)), Error);
  EXPECT_THROW(StackSpill(tmp("bad2.spill"), 4, 0, 0), Error);
}

TEST(StackBlocked, SunSlicesByTheRasterizerAreTheCanonicalBounds) {
  const std::string scene_spec = "procedural:city,size=2";
  const LightSet set = stacks::fitted_set(scene_spec, "sun-path:azimuth=60..150,elevation=25..55,samples=3");
  const uint32_t level = stacks::small_scale() ? 4 : 5;
  const Scene scene = load_scene(scene_spec);
  const IntervalStack raster = trace_stack(scene, set, level);
  for (uint32_t w = 0; w < set.size(); ++w) {
    const RasterBounds reference(scene, set.samples[w]);
    for (uint64_t y = 0; y < raster.side(); ++y)
      for (uint64_t x = 0; x < raster.side(); ++x) {
        const Interval a = reference.brute_force_texel(level, x, y), b = raster.at(x, y, w);
        ASSERT_TRUE(a.lo == b.lo && a.hi == b.hi) << x << ", " << y << ", " << w;
      }
  }
  // And through the spill in strips: the same texels.
  StackSpill spill(tmp("traced.spill"), level, set.size(), 1);
  EXPECT_EQ(trace_stack_to_spill(scene, set, spill), "raster");
  for (uint32_t w = 0; w < set.size(); ++w)
    for (uint64_t y = 0; y < raster.side(); y += 7)
      for (uint64_t x = 0; x < raster.side(); x += 3) {
        const Interval a = spill.texel(x, y, w), b = raster.at(x, y, w);
        ASSERT_TRUE(a.lo == b.lo && a.hi == b.hi) << x << ", " << y << ", " << w;
      }
}

}  // namespace
}  // namespace st

namespace st {
namespace {

// Split cells (stack_grid.hpp, MHOCT.md "Split cells"): with a tile bound the default cut
// overflows, the blocked cut keeps K and splits only the overflowing cells (several levels
// down where needed), every tile within the bound; the pack carries feature
// stack_split_cells and grid version 2, opens, verifies, answers every texel within its
// interval and (octree cells) every level of every slice like the uncut octree, and its
// gathered soft lookups (their own cell walk) equal the per-sample lit(), for block levels 0
// and K and two cell forms; the grid round-trips.
TEST(StackBlocked, SplitCellsKeepTheSkipLevelAndAnswerLikeTheOctree) {
  const IntervalStack s = stacks::random_stack(5, 6, 5);
  const OctHierarchy h = build_octree(s);
  const uint32_t K = default_stack_skip_level(h.geo);
  for (const StackCells cells : {StackCells::octree, StackCells::smaller}) {
    for (const uint32_t B : {0u, K}) {
      SCOPED_TRACE("cells " + std::to_string(int(cells)) + ", block level " + std::to_string(B));
      auto spill = spill_of(s, B, "split.spill");
      BlockedStackCut cut(*spill, std::nullopt, 200, tmp("split.tiles"), nullptr, cells, true);
      EXPECT_EQ(cut.grid.skip_level, K);
      EXPECT_TRUE(cut.grid.split());
      EXPECT_GT(cut.split_cells, 0u);
      EXPECT_LE(cut.max_tile_bytes, 200u);
      uint32_t deepest = 0;
      for (const StackEntry& e : cut.grid.entries) deepest = std::max<uint32_t>(deepest, e.level);
      EXPECT_GT(deepest, K);
      for (size_t i = 0; i < cut.tile_count(); ++i) {
        const auto [cell, bytes] = cut.tile(i);
        EXPECT_LE(bytes.size(), 200u);
        // Where the tile lies (the bytes bench's accounting): its own level, its form, and
        // the level-K cell it is (level K) or lies below (a split one).
        const BlockedStackCut::TilePlace at = cut.tile_place(i);
        EXPECT_EQ(at.level, cut.grid.entries[cell].level) << "tile " << i;
        EXPECT_EQ(at.octree, !is_slice_tiles(bytes)) << "tile " << i;
        ASSERT_LT(at.root, cut.grid.cells(K)) << "tile " << i;
        EXPECT_EQ(cut.grid.entries[at.root].kind, at.level == K ? 1 : kStackSplit) << "tile " << i;
        if (at.level == K) {
          EXPECT_EQ(at.root, cell) << "tile " << i;
        }
      }
      fill_lights(cut.grid, s.slices);
      const StackGrid back = StackGrid::parse(cut.grid.serialize(), "split");
      ASSERT_EQ(back.entries.size(), cut.grid.entries.size());
      for (size_t i = 0; i < back.entries.size(); ++i)
        ASSERT_TRUE(back.entries[i] == cut.grid.entries[i] && back.entries[i].level == cut.grid.entries[i].level &&
                    back.entries[i].first == cut.grid.entries[i].first)
            << "entry " << i;
      StackPackParams p;
      p.tile_bytes = 200;
      write_stack_pack(tmp("split.pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, p);
      const auto r = PackReader::open(tmp("split.pack"));
      EXPECT_TRUE(r->header().flags & kFeatureStackSplitCells);
      r->verify();
      const ResidentStack rs(*r);
      if (cells == StackCells::octree) {
        EXPECT_EQ(stacks::first_octree_difference(h, rs.map()), "");
      }
      // Per-slice cells answer their own 2D tiles' values: within every texel's interval.
      EXPECT_EQ(stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint32_t w) { return rs.map().depth(x, y, w, s.level); }),
                "");
      // The soft lookups (lit_samples' own cell walk) equal the per-sample lit().
      uint64_t state = 7;
      auto next = [&] { return double((state = state * 6364136223846793005ull + 1442695040888963407ull) >> 11) / 9007199254740992.0; };
      for (int i = 0; i < 300; ++i) {
        const Vec3d p3{-10 + 20 * next(), 5 * next(), -10 + 20 * next()};
        uint32_t lit = 0;
        for (uint32_t w = 0; w < s.slices; ++w) lit += rs.map().lit(p3, w);
        ASSERT_EQ(rs.map().soft_visibility(p3), float(lit) / float(s.slices)) << i;
      }
    }
  }
  // Without splitting, the same bound moves the whole cut deeper (the earlier packs).
  auto spill = spill_of(s, 0, "split.spill");
  BlockedStackCut uniform(*spill, std::nullopt, 200, tmp("split.tiles"), nullptr, StackCells::octree, false);
  EXPECT_GT(uniform.grid.skip_level, K);
  EXPECT_FALSE(uniform.grid.split());
}

// The version-2 layout, pinned: two 2x2 slices (n = k = 1), K = 0, the one cell split into
// its 8 children (level 1: x, y and w halve). Entries from byte 312 (24 + 2 x 144, no
// spec, no coarse level): the split root, then its children in (w, y, x) order; X = 8 at
// byte 20; ids at level ceil(bits(8) / 2) = 2.
TEST(StackBlocked, SplitGridLayoutIsPinned) {
  StackGrid g;
  g.geo = moct::Geometry{1, 1};
  g.slices = 2;
  g.skip_level = 0;
  fill_lights(g, 2);
  g.spec.clear();
  g.entries.assign(9, StackEntry{0.5f, 0});
  g.entries[0].kind = kStackSplit;
  for (uint32_t i = 1; i < 9; ++i) g.entries[i].value = 0.1f * float(i);
  g.link();
  EXPECT_EQ(g.entries[0].first, 1u);
  EXPECT_EQ(g.entries[8].level, 1u);
  const std::vector<uint8_t> b = g.serialize();
  ASSERT_EQ(b.size(), 384u);
  EXPECT_EQ(b[4], 2u);   // version 2
  EXPECT_EQ(b[20], 8u);  // X
  EXPECT_EQ(b[312 + 4], kStackSplit);
  float v;
  std::memcpy(&v, b.data() + 320 + 8 * 6, 4);  // child (x 0, y 1, w 1): offset (1 * 2 + 1) * 2 + 0
  EXPECT_EQ(v, 0.1f * 7.0f);
  const StackGrid back = StackGrid::parse(b, "pinned");
  uint32_t level = 0;
  EXPECT_EQ(back.cell_at(1, 1, 0, 1, 1, level), 7u);
  EXPECT_EQ(level, 1u);
  EXPECT_EQ(back.cell_at(0, 1, 0, 1, 1, level), 0u);  // level 0 stops at the split root
  EXPECT_EQ(back.tile_id(7), (uint64_t(2) << 58) | 7);
  uint64_t cell = 0;
  EXPECT_TRUE(back.cell_of(back.tile_id(8), cell));
  EXPECT_EQ(cell, 8u);
  EXPECT_FALSE(back.cell_of(back.tile_id(8) + 1, cell));
  size_t visited = 0;
  back.visit([&](uint64_t, uint32_t, uint64_t, uint64_t, uint64_t) { ++visited; });
  EXPECT_EQ(visited, 9u);
}

// A split grid's hostile forms are refused in one line each; a pack whose grid splits
// cells without the feature bit (or the bit without a split grid) does not open.
TEST(StackBlocked, HostileSplitGridsAreRefused) {
  const IntervalStack s = stacks::random_stack(4, 3, 11);
  auto spill = spill_of(s, 0, "hsplit.spill");
  BlockedStackCut cut(*spill, 1u, 120, tmp("hsplit.tiles"), nullptr, StackCells::octree, true);
  ASSERT_TRUE(cut.grid.split());
  fill_lights(cut.grid, s.slices);
  const std::vector<uint8_t> grid = cut.grid.serialize();
  auto refused = [&](std::vector<uint8_t> bad, const std::string& what, const std::string& says) {
    try {
      StackGrid::parse(bad, "t");
      ADD_FAILURE() << what << ": parsed";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << what << ": " << e.what();
    }
  };
  const size_t entries = grid.size() - 8 * cut.grid.entries.size();
  uint64_t split = 0;
  while (cut.grid.entries[split].kind != kStackSplit) ++split;
  {
    std::vector<uint8_t> bad = grid;
    bad[20] = bad[21] = bad[22] = bad[23] = 0;  // version 2, no split entries
    refused(bad, "no extra", "version 2 without split entries");
  }
  {
    std::vector<uint8_t> bad = grid;
    bad[4] = 1;  // version 1 with a split count
    refused(bad, "version 1", "nonzero reserved field");
  }
  {
    std::vector<uint8_t> bad = grid;
    bad[entries + 8 * split + 4] = 0;  // a split cell made constant: its children dangle
    refused(bad, "dangling children", "split");
  }
  {
    std::vector<uint8_t> bad = grid;
    uint64_t j = cut.grid.entries.size() - 1;  // the last entry not split, split: more children than entries
    while (cut.grid.entries[j].kind == kStackSplit) --j;
    bad[entries + 8 * j + 4] = kStackSplit;
    refused(bad, "one split more", "split");
  }
  {
    std::vector<uint8_t> bad = grid;
    bad[entries + 8 * split + 4] = 3;
    refused(bad, "kind 3", "bad entry kind");
  }
  {
    // A split at the finest level (a leaf's children): a grid of one cell at level L.
    StackGrid g = cut.grid;
    g.skip_level = g.geo.depth();
    g.coarse.assign(g.geo.depth(), {});
    for (uint32_t l = 0; l < g.geo.depth(); ++l) g.coarse[l].assign(g.cells(l), 0.5f);
    g.entries.assign(g.cells(g.skip_level) + 1, StackEntry{0.5f, 0});
    g.entries[0].kind = kStackSplit;
    refused(g.serialize(), "finest", "split cell at the finest level");
  }
  // The bit and the grid must agree.
  StackPackParams p;
  p.tile_bytes = 120;
  p.compress_grid = false;
  write_stack_pack(tmp("hsplit.pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, p);
  std::vector<uint8_t> file = file_bytes(tmp("hsplit.pack"));
  PackHeader head = PackHeader::parse(std::span<const uint8_t>(file.data(), kPackHeaderBytes), "t");
  ASSERT_TRUE(head.flags & kFeatureStackSplitCells);
  head.flags &= ~uint32_t(kFeatureStackSplitCells);
  const auto hb = head.serialize();
  std::memcpy(file.data(), hb.data(), hb.size());
  try {
    PackReader::open_memory(file, "nobit");
    ADD_FAILURE() << "a split grid without the bit opened";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("without feature stack_split_cells"), std::string::npos) << e.what();
  }
}

}  // namespace
// The blocked cut weighs a block's cells with for_each_index: every index once, whatever
// the threads, and a cell's failure rethrown to the cut (on one thread, nothing after it runs).
TEST(ForEachIndex, EveryIndexOnceAndTheFirstFailureRethrown) {
  for (size_t threads : {size_t(0), size_t(1), size_t(4)}) {
    std::vector<std::atomic<int>> seen(1000);
    for_each_index(seen.size(), threads, [&](size_t i) { ++seen[i]; });
    for (size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(seen[i].load(), 1) << i << " threads " << threads;
    std::atomic<size_t> after{0};
    EXPECT_THROW(for_each_index(1000, threads,
                                [&](size_t i) {
                                  if (i == 5) throw Error("cell 5");
                                  if (i > 500) ++after;
                                }),
                 Error);
    if (threads == 1) {
      EXPECT_EQ(after.load(), 0u);  // one thread: nothing after the failure runs
    }
  }
  for_each_index(0, 0, [](size_t) { FAIL(); });
}

}  // namespace st

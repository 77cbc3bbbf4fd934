// The out-of-core stack build (tiles/encode/stack_blocked.hpp): a stack spilled in octree
// blocks and reduced one block at a time gives the one-shot cut_stack(build_octree(...))
// grid and tiles byte for byte, and the same pack file, for wide and deep stacks, padded
// slice counts, every block level down to the skip level and a cut that must move deeper;
// and the traced sun slices (the rasterizer) are the canonical definition's bounds.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>

#include "common/error.hpp"
#include "tests/test_tmp.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/bake/stack_build.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"

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

// The one page-table walk (tiles/core/page_table.hpp) on a pack cut deep enough to have
// index tiles: the region visit reaches exactly the tiles the point walks of its texels
// pass through; a walk that lacks an index tile stops there with that entry's value;
// the out-of-range rule is the same for the pack evaluator and the walk's users.
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/page_table.hpp"

namespace st {
namespace {

struct IndexedPack {
  std::shared_ptr<PackReader> reader;
  std::map<uint64_t, CutGrid> index_tiles;
  const CutGrid* index_tile(uint64_t id) const {
    auto it = index_tiles.find(id);
    return it == index_tiles.end() ? nullptr : &it->second;
  }
};

IndexedPack indexed_pack() {
  IntervalTile t = fields::uniform_field(64, 4);
  Hierarchy h = build_hierarchy(t);
  CutParams cut;
  cut.map_level = h.depth;
  cut.skip_level = 2;
  cut.tile_bytes = 128;  // small: most cells become index tiles
  cut.codec = TileCodec::of(Encoding::mh);
  PackParams pp = PackParams::from(
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-10, 0, -10}, {10, 5, 10}}), cut);
  pp.build_params = {{"scene", "page-table"}};
  const std::string path = packtest::temp_path("page_table.pack");
  write_pack(path, h, cut, pp);
  IndexedPack p{std::shared_ptr<PackReader>(PackReader::open(path)), {}};
  // Read every index tile through the walk itself, coarse to fine (ids sort by level).
  for (const TileIndexEntry& e : p.reader->tiles()) {
    if (e.kind != TileKind::index) continue;
    const TileAddress a = tile_address(e.id);
    const uint32_t below = a.level + 1;  // a texel just under the tile's root
    const PageHit hit = walk_page_table(p.reader->grid(), below, uint64_t(a.x) << 1, uint64_t(a.y) << 1,
                                        [&](uint64_t id, const GridEntry&) { return p.index_tile(id); });
    EXPECT_EQ(hit.kind, PageHit::Kind::absent);
    EXPECT_EQ(hit.tile, e.id);
    p.index_tiles.emplace(e.id, p.reader->read_index_tile(e.id, hit.entry));
  }
  return p;
}

TEST(PageTable, RegionVisitReachesExactlyTheTilesOfItsTexelsWalks) {
  const IndexedPack p = indexed_pack();
  ASSERT_GT(p.index_tiles.size(), 4u);
  const uint32_t map_level = p.reader->map_level();
  std::mt19937_64 rng(7);
  auto have = [&](uint64_t id, const GridEntry&) { return p.index_tile(id); };
  for (int round = 0; round < 200; ++round) {
    const uint32_t level = uint32_t(rng() % (map_level + 1));
    const uint64_t side = uint64_t(1) << level;
    const uint64_t x0 = rng() % side, y0 = rng() % side;
    const uint64_t x1 = x0 + 1 + rng() % (side - x0), y1 = y0 + 1 + rng() % (side - y0);
    std::set<uint64_t> walked;
    for (uint64_t y = y0; y < y1; ++y)
      for (uint64_t x = x0; x < x1; ++x) {
        const PageHit hit = walk_page_table(p.reader->grid(), level, x, y, [&](uint64_t id, const GridEntry& e) {
          walked.insert(id);
          return have(id, e);
        });
        if (hit.kind == PageHit::Kind::tile) walked.insert(hit.tile);
        ASSERT_NE(hit.kind, PageHit::Kind::absent);
      }
    std::set<uint64_t> visited;
    visit_page_tiles(p.reader->grid(), level, x0, y0, x1, y1, have,
                     [&](uint64_t id, const GridEntry&, uint32_t l, uint64_t ex, uint64_t ey) {
                       EXPECT_EQ(id, make_tile_id(l, uint32_t(ex), uint32_t(ey)));
                       EXPECT_TRUE(visited.insert(id).second) << "visited twice: " << describe_tile(id);
                       return true;
                     });
    ASSERT_EQ(visited, walked) << "level " << level << " region [" << x0 << ", " << x1 << ") x [" << y0 << ", "
                               << y1 << ")";
  }
}

TEST(PageTable, AWalkWithoutItsIndexTileAnswersTheEntrysValue) {
  const IndexedPack p = indexed_pack();
  const uint32_t map_level = p.reader->map_level();
  PackEvaluator full(p.reader);
  size_t absent = 0;
  for (uint64_t y = 0; y < (uint64_t(1) << map_level); y += 3)
    for (uint64_t x = 0; x < (uint64_t(1) << map_level); x += 5) {
      const PageHit hit = walk_page_table(p.reader->grid(), map_level, x, y,
                                          [](uint64_t, const GridEntry&) -> const CutGrid* { return nullptr; });
      if (hit.kind != PageHit::Kind::absent) continue;
      ++absent;
      // The coarse answer is the value the full walk gives at the index tile's root level.
      const TileAddress a = tile_address(hit.tile);
      const uint32_t up = map_level - a.level;
      EXPECT_EQ(packtest::bits(hit.value), packtest::bits(full.depth(a.level, x >> up, y >> up)));
      EXPECT_EQ(hit.entry.kind, EntryKind::index);
    }
  EXPECT_GT(absent, 0u);
}

TEST(PageTable, OneOutOfRangeRule) {
  EXPECT_TRUE(texel_in_map(6, 6, 63, 63));
  EXPECT_FALSE(texel_in_map(6, 6, 64, 0));
  EXPECT_FALSE(texel_in_map(6, 6, 0, 64));
  EXPECT_FALSE(texel_in_map(6, 7, 0, 0));
  EXPECT_TRUE(texel_in_map(20, 20, (1u << 20) - 1, 0));
  const IndexedPack p = indexed_pack();
  PackEvaluator ev(p.reader);
  const uint32_t L = p.reader->map_level();
  EXPECT_EQ(ev.depth(L + 1, 0, 0), kLitDepth);
  EXPECT_EQ(ev.depth(L, uint64_t(1) << L, 0), kLitDepth);
  EXPECT_EQ(ev.depth(3, 0, 8), kLitDepth);
}

}  // namespace
}  // namespace st

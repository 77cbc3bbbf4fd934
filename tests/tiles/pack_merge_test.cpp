// Sharded builds (pack_merge.hpp) and the cell spans they move between processes
// (pack_writer.hpp): shards partition the cells; a span with any byte flipped or cut
// short is refused before anything is appended.
#include <gtest/gtest.h>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_merge.hpp"
#include "tiles/encode/pack_writer.hpp"

namespace st {
namespace {

TEST(BuildShard, ShardsPartitionTheCells) {
  for (uint32_t k = 0; k <= 4; ++k)
    for (uint32_t n = 1; n <= 9; ++n) {
      const uint32_t side = 1u << k;
      uint64_t total = 0;
      for (uint32_t i = 0; i < n; ++i) total += BuildShard{i, n}.cell_count(k);
      EXPECT_EQ(total, uint64_t(side) * side);
      for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x) {
          int holders = 0;
          for (uint32_t i = 0; i < n; ++i) holders += BuildShard{i, n}.holds(x, y);
          EXPECT_EQ(holders, 1) << "cell " << x << "," << y << " of K " << k << ", N " << n;
        }
    }
}

TEST(BuildShard, ParseRefusesWhatIsNotIOfN) {
  EXPECT_EQ(BuildShard::parse("3/16").index, 3u);
  EXPECT_EQ(BuildShard::parse("3/16").count, 16u);
  for (const char* bad : {"", "3", "3/3", "a/2", "1/0", "-1/2", "1/2x", "/2", "1/", "1/99999999999", "1/2097152"})
    EXPECT_THROW(BuildShard::parse(bad), Error) << bad;
}

TEST(CellBytes, EveryFlippedOrMissingByteIsRefused) {
  for (Encoding e : packtest::available_encodings()) {
    IntervalTile field = fields::city_field(32, 5);
    CutParams cut;
    cut.map_level = 5;
    cut.skip_level = 1;
    cut.tile_bytes = 256;
    cut.codec = TileCodec::of(e);
    PackParams pp = PackParams::from(
        LightSpace::fit(LightSpec::parse("sun:azimuth=10,elevation=70"), Aabb{{0, 0, 0}, {1, 1, 1}}), cut);
    std::vector<CutCell> cells;
    cut_hierarchy(build_hierarchy(field), cut, [&](CutCell&& c) { cells.push_back(std::move(c)); });
    for (const CutCell& c : cells) {
      const std::vector<uint8_t> span = encode_cell_bytes(c, pp);
      std::vector<TileIndexEntry> tiles;
      const CellRecord rec = parse_cell_bytes(span, pp, "span", tiles);
      EXPECT_EQ(rec.cx, c.cx);
      EXPECT_EQ(rec.cy, c.cy);
      EXPECT_EQ(tiles.size(), c.tiles.size());
      for (size_t len = 0; len < span.size(); ++len)
        EXPECT_THROW(parse_cell_bytes(std::span(span).first(len), pp, "span", tiles), Error) << len;
      const size_t step = fields::small_test_scale() ? 7 : 1;
      for (size_t i = 0; i < span.size(); i += step) {
        std::vector<uint8_t> bad = span;
        bad[i] ^= 0x10;
        EXPECT_THROW(parse_cell_bytes(bad, pp, "span", tiles), Error) << "byte " << i;
      }
    }
  }
}

}  // namespace
}  // namespace st

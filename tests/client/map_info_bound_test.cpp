// The tile bound a server publishes (MapInfo's pack header, tile_bytes): the largest tile
// the pack holds (rounded up to 64 bytes), not the build's target, so that a client's cache slots, sized by it,
// hold as many tiles as its memory allows. The file's own header keeps the target; the
// client is served bit for bit as before.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace map_info_bound_test {

TEST(ServerLoopback, MapInfoBoundsTilesByTheLargestThePackHolds) {
  auto p = looptest::build_pack("bound", 6, 17, looptest::first_encoding(), 3, 1u << 16);  // a 64 KiB target
  uint32_t largest = 0;
  for (const TileIndexEntry& t : p.reader->tiles()) largest = std::max(largest, t.raw_size);
  ASSERT_GT(largest, 0u);
  ASSERT_LT(largest, p.reader->header().tile_bytes) << "the test wants tiles smaller than the target";
  auto srv = looptest::start_server({p.path});
  ClientOptions o = looptest::quick_options();
  o.cache_bytes = 8u << 20;
  Client c({"127.0.0.1", srv.port}, o);
  Map m = c.open("bound");
  EXPECT_EQ(pack_header(m).tile_bytes, (largest + 63) / 64 * 64);
  EXPECT_EQ(p.reader->header().tile_bytes, 1u << 16) << "the file is untouched";
  EXPECT_LT(m.slot_bytes(), 1u << 16);
  EXPECT_GE(m.slot_bytes(), largest);
  const uint32_t side = 1u << 6;
  m.request_region(6, 0, 0, side, side, 1);
  ASSERT_TRUE(looptest::wait_until([&] { return m.region_resident(6, 0, 0, side, side); }));
  EXPECT_EQ(m.stats().tiles_received, p.reader->tiles().size());
  PackEvaluator local(p.reader);
  for (uint32_t level = 0; level <= 6; ++level)
    for (uint64_t y = 0; y < (1u << level); ++y)
      for (uint64_t x = 0; x < (1u << level); ++x) {
        const float a = m.depth(level, x, y), b = local.depth(level, x, y);
        ASSERT_EQ(std::memcmp(&a, &b, sizeof a), 0) << level << " " << x << " " << y;
      }
}

}  // namespace map_info_bound_test
}  // namespace st::client

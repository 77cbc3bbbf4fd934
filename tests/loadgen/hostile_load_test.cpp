// `load` against servers that never deliver (tests/client/hostile_server.hpp): a run in
// which no tile arrives, or tiles come under wrong ids, reports errors (the tool then
// exits non-zero), never "errors 0"; and its duration holds.
#include <gtest/gtest.h>

#include <chrono>

#include "loadgen/load_report.hpp"
#include "loadgen/load_run.hpp"
#include "tests/client/hostile_server.hpp"
#include "tests/loadgen/load_fixture.hpp"

namespace st::loadgen {
namespace {

using looptest::HostileServer;

LoadResult run_against(HostileServer::Tiles mode) {
  const std::shared_ptr<const PackReader> pack = PackReader::open(loadtest::city_pack(9).path);
  HostileServer::Script s;
  s.header = {pack->header_bytes().begin(), pack->header_bytes().end()};
  s.grid = {pack->grid_bytes().begin(), pack->grid_bytes().end()};
  s.pack = pack;
  s.tiles = mode;
  HostileServer srv(s);
  LoadOptions o;
  o.endpoint = {"127.0.0.1", srv.port()};
  o.map = "city";
  o.cameras = 2;
  o.duration = 1.0;
  o.rate = 20;
  o.cache_mb = 8;
  o.workers = 1;
  o.io_threads = 1;
  const auto t0 = std::chrono::steady_clock::now();
  LoadResult r = run_load(o);
  // The duration (+1 s for stalled frames) plus the final drain's bound (5 s) at most.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(8));
  return r;
}

TEST(HostileLoad, NoTileEverDeliveredIsAnError) {
  const LoadResult r = run_against(HostileServer::Tiles::none);
  EXPECT_GT(r.map.tiles_requested, 0u);
  EXPECT_EQ(r.map.tiles_received, 0u);
  EXPECT_TRUE(r.no_tile_received());
  EXPECT_GT(r.errors(), 0u) << load_table(r);
  EXPECT_NE(load_table(r).find("no tile received at all"), std::string::npos);
}

TEST(HostileLoad, TilesUnderWrongIdsAreErrors) {
  const LoadResult r = run_against(HostileServer::Tiles::wrong_id);
  EXPECT_EQ(r.map.tiles_received, 0u);
  EXPECT_GT(r.map.tiles_unanswered, 0u);
  EXPECT_GT(r.errors(), 0u) << load_table(r);
}

}  // namespace
}  // namespace st::loadgen

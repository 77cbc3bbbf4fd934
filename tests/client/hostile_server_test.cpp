// The client against a lying server (hostile_server.hpp): a MapInfo whose light the pack
// reader refuses, a MapInfo that does not decode, a silent handshake, tiles refused or
// answered under wrong ids, and every legal tile bound under a byte budget. Each case ends
// with one clear line or bounded counters, never a hang, a storm or unbounded memory.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>

#include "client/map_access.hpp"
#include "tests/client/hostile_server.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace hostile_server_test {

using namespace std::chrono_literals;
using looptest::HostileServer;

// A small honest pack (built once per test binary) whose header and grid section the
// scripts start from.
const looptest::TestPack& honest_pack() {
  static const looptest::TestPack p = looptest::build_pack("hostile", 9, 31, looptest::first_encoding(), 4, 4096);
  return p;
}

std::vector<uint8_t> bytes_of(std::span<const uint8_t> s) { return {s.begin(), s.end()}; }

std::vector<uint8_t> patched_header(const std::function<void(PackHeader&)>& patch) {
  PackHeader h = PackHeader::parse(honest_pack().reader->header_bytes(), "test");
  patch(h);
  const auto b = h.serialize();
  return {b.begin(), b.end()};
}

HostileServer::Script honest_script() {
  HostileServer::Script s;
  s.header = bytes_of(honest_pack().reader->header_bytes());
  s.grid = bytes_of(honest_pack().reader->grid_bytes());
  s.pack = honest_pack().reader;
  return s;
}

ClientOptions fast_options() {
  ClientOptions o = looptest::quick_options();
  o.request_timeout = 5s;
  o.connect_timeout = 500ms;
  return o;
}

std::string open_error(uint16_t port, const ClientOptions& o = fast_options()) {
  Client c({"127.0.0.1", port}, o);
  try {
    c.open("hostile");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// The pack reader refuses these lights (LightSpace::check_array); so must the client.
TEST(HostileServer, MapInfoLightThePackReaderRefusesFailsOpenInOneLine) {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const std::vector<std::function<void(PackHeader&)>> lies = {
      [&](PackHeader& h) { h.light[0] = nan; },  // a NaN coordinate
      [&](PackHeader& h) { h.light[12] = inf; },  // an infinite extent
      [&](PackHeader& h) {                       // zero axes
        for (size_t i = 3; i < 12; ++i) h.light[i] = 0;
      },
      [&](PackHeader& h) { std::swap(h.light[13], h.light[14]); },  // near > far
  };
  for (size_t i = 0; i < lies.size(); ++i) {
    HostileServer::Script s = honest_script();
    s.header = patched_header(lies[i]);
    HostileServer srv(s);
    const auto t0 = std::chrono::steady_clock::now();
    const std::string why = open_error(srv.port());
    EXPECT_NE(why.find("the light is not one a build makes"), std::string::npos) << "lie " << i << ": " << why;
    EXPECT_EQ(why.find('\n'), std::string::npos) << why;
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s) << "lie " << i;
  }
}

TEST(HostileServer, MalformedMapInfoIsNamedNotATimeout) {
  HostileServer::Script s = honest_script();
  s.trailing_byte = true;
  HostileServer srv(s);
  const auto t0 = std::chrono::steady_clock::now();
  const std::string why = open_error(srv.port());
  EXPECT_NE(why.find("map_info does not decode"), std::string::npos) << why;
  EXPECT_EQ(why.find("no answer"), std::string::npos) << why;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);
}

TEST(HostileServer, SilentServerIsNamedAsSilent) {
  HostileServer::Script s = honest_script();
  s.silent_hello = true;
  HostileServer srv(s);
  ClientOptions o = fast_options();
  o.request_timeout = 1500ms;
  o.connect_timeout = 300ms;
  const std::string why = open_error(srv.port(), o);
  EXPECT_NE(why.find("sent nothing within 300 ms"), std::string::npos) << why;
  EXPECT_EQ(why.find("closed the connection"), std::string::npos) << why;
}

// Every legal tile bound (1 byte to 64 MiB), claimed by a MapInfo: the map opens within
// the byte budget (metadata and everything per slot counted) or is refused in one line;
// the memory it accounts never exceeds the budget, and its slot pool is within it.
TEST(HostileServer, EveryLegalTileBoundStaysWithinTheCacheBudget) {
  const uint64_t budget = 16u << 20;
  for (uint32_t tile_bytes : {1u, 8u, 64u, 256u, 4096u, 65536u, 1u << 20, 4u << 20, 15u << 20, 16u << 20, 64u << 20}) {
    HostileServer::Script s = honest_script();
    s.header = patched_header([&](PackHeader& h) { h.tile_bytes = tile_bytes; });
    HostileServer srv(s);
    ClientOptions o = fast_options();
    o.cache_bytes = budget;
    o.max_slot_bytes = 64u << 20;
    Client c({"127.0.0.1", srv.port()}, o);
    try {
      const Map m = c.open("hostile");
      const MapStats st = m.stats();
      const uint64_t slots = uint64_t(st.cache.resident) + st.cache.pinned + st.cache.free;
      EXPECT_LE(st.accounted_bytes, budget) << tile_bytes;
      EXPECT_LE(slots * (m.slot_bytes() + kSlotOverheadBytes), budget) << tile_bytes;
      EXPECT_GE(m.slot_bytes(), tile_bytes);
      EXPECT_GE(slots, kMinTileSlots);
    } catch (const std::exception& e) {
      // Refused only when kMinTileSlots slots cannot fit beside the metadata, and then saying so.
      const std::string why = e.what();
      EXPECT_GT(uint64_t(kMinTileSlots) * (uint64_t(tile_bytes) + kSlotOverheadBytes), budget / 2)
          << tile_bytes << ": " << why;
      EXPECT_NE(why.find("cannot hold its metadata"), std::string::npos) << why;
    }
  }
}

// A server refusing every tile: each is asked for once, remembered (constant: the coarse
// answer), and asking again for the same region sends nothing more.
TEST(HostileServer, RefusedTilesAreRememberedNotAskedAgain) {
  HostileServer::Script s = honest_script();
  s.tiles = HostileServer::Tiles::unknown_tile;
  HostileServer srv(s);
  Client c({"127.0.0.1", srv.port()}, fast_options());
  Map m = c.open("hostile");
  const uint32_t L = m.finest_level();
  const uint64_t side = uint64_t(1) << L;
  const size_t tiles = honest_pack().reader->tiles().size();
  ASSERT_GT(tiles, 8u);
  for (int round = 0; round < 50; ++round) {
    m.request_region(L, 0, 0, side, side, 10);
    if (looptest::wait_until([&] { return m.region_resident(L, 0, 0, side, side); }, 50ms) && round > 5) break;
  }
  ASSERT_TRUE(looptest::wait_until([&] { return m.region_resident(L, 0, 0, side, side); }, 5s));
  const uint64_t asked = srv.tiles_asked();
  for (int round = 0; round < 20; ++round) {
    m.request_region(L, 0, 0, side, side, 10);
    for (uint64_t y = 0; y < side; y += 7) m.depth(L, y, y);
    std::this_thread::sleep_for(2ms);
  }
  std::this_thread::sleep_for(100ms);
  EXPECT_EQ(srv.tiles_asked(), asked);
  EXPECT_EQ(srv.most_asks_of_one_tile(), 1u);
  EXPECT_GT(m.stats().tiles_failed, 0u);
  EXPECT_LE(m.stats().tiles_failed, tiles);
}

// A map with more tiles than kMaxFailedTiles, every one refused: the client asks for at
// most that many (plus what was already on the wire), then asks for nothing more, however
// often lookups and regions want the rest.
TEST(HostileServer, RefusalsPastTheFailureBoundStopTheRequests) {
  static const looptest::TestPack big = looptest::build_pack("hostile_big", 10, 33, looptest::first_encoding(), 7, 4096);
  const size_t tiles = big.reader->tiles().size();
  ASSERT_GT(tiles, kMaxFailedTiles + 1024) << "the pack must have more tiles than the bound";
  HostileServer::Script s;
  s.header = bytes_of(big.reader->header_bytes());
  s.grid = bytes_of(big.reader->grid_bytes());
  s.pack = big.reader;
  s.tiles = HostileServer::Tiles::unknown_tile;
  HostileServer srv(s);
  ClientOptions o = fast_options();
  o.want_capacity = 1u << 15;  // every tile of the map can be queued at once
  Client c({"127.0.0.1", srv.port()}, o);
  Map m = c.open("hostile_big");
  const uint32_t L = m.finest_level();
  const uint64_t side = uint64_t(1) << L;
  const uint64_t on_the_wire = uint64_t(o.max_in_flight) * o.tiles_per_request;
  for (int round = 0; round < 40; ++round) {
    m.request_region(L, 0, 0, side, side, 10);
    std::this_thread::sleep_for(20ms);
  }
  ASSERT_TRUE(looptest::wait_until([&] { return m.stats().tiles_failed >= kMaxFailedTiles; }, 10s));
  std::this_thread::sleep_for(200ms);
  const uint64_t asked = srv.tiles_asked();
  EXPECT_LE(asked, kMaxFailedTiles + on_the_wire);
  for (int round = 0; round < 20; ++round) {
    m.request_region(L, 0, 0, side, side, 10);
    std::this_thread::sleep_for(5ms);
  }
  std::this_thread::sleep_for(100ms);
  EXPECT_EQ(srv.tiles_asked(), asked);
  EXPECT_EQ(srv.most_asks_of_one_tile(), 1u);
}

// Tiles answered under other tiles' ids: nothing of it is taken, the request's own tiles
// are counted unanswered, asked again a bounded number of times, then given up.
TEST(HostileServer, AnswersUnderWrongIdsAreCountedAndBounded) {
  HostileServer::Script s = honest_script();
  s.tiles = HostileServer::Tiles::wrong_id;
  HostileServer srv(s);
  ClientOptions o = fast_options();
  Client c({"127.0.0.1", srv.port()}, o);
  Map m = c.open("hostile");
  const uint32_t L = m.finest_level();
  const uint64_t side = uint64_t(1) << L;
  m.request_region(L, 0, 0, side, side, 10);
  ASSERT_TRUE(looptest::wait_until([&] { return m.stats().tiles_failed > 0; }, 5s));
  ASSERT_TRUE(looptest::wait_until([&] { return srv.most_asks_of_one_tile() >= o.max_tile_retries + 1; }, 5s));
  std::this_thread::sleep_for(200ms);
  const MapStats st = m.stats();
  EXPECT_GT(st.tiles_unanswered, 0u);
  EXPECT_EQ(st.tiles_received, 0u);
  EXPECT_LE(srv.most_asks_of_one_tile(), o.max_tile_retries + 1);
}

}  // namespace hostile_server_test
}  // namespace st::client

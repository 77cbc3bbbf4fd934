// Fault injection over loopback: the server killed mid-stream and
// restarted; a pack truncated or bit-flipped on disk while it is served; a client that
// drips one byte at a time; a client that opens connections without end. Every case ends
// with zero lost or wrong tiles for the well-behaved clients: each texel is compared
// bit-exactly with the pack (or, under a tile the server reports corrupt, with the
// coarser level the client answers from instead).
#include <gtest/gtest.h>

#include <sys/types.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>

#include "client/map_access.hpp"
#include "proto/proto.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::client {
namespace fault_test {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::error_code_of;
using looptest::RawFrame;
using looptest::RawSocket;
using looptest::read_frame;
using looptest::start_server;
using looptest::wait_until;

uint32_t bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

uint32_t test_level() { return looptest::small_scale() ? 6 : 7; }

ClientOptions options_for(const looptest::TestPack& p) {
  ClientOptions o = looptest::quick_options();
  o.cache_slots = uint32_t(p.reader->tiles().size()) + 8;  // everything stays resident
  return o;
}

using looptest::first_encoding;

std::unique_ptr<server::Server> serve_on(uint16_t port, const std::string& path,
                                         server::ServerOptions so = {}) {
  so.port = port;
  so.log = [](const std::string&) {};
  auto s = std::make_unique<server::Server>(server::Catalog::scan(std::vector<std::string>{path}), so);
  s->start();
  return s;
}

uint16_t free_port(const std::string& path) {
  auto probe = start_server({path});
  const uint16_t port = probe.port;
  probe.stop();
  return port;
}

// Every texel of every level answers like the pack.
void expect_exact_everywhere(const Map& m, const looptest::TestPack& p) {
  PackEvaluator local(p.reader);
  const uint32_t top = m.finest_level();
  for (uint32_t level = 0; level <= top; ++level)
    for (uint64_t y = 0; y < (1u << level); ++y)
      for (uint64_t x = 0; x < (1u << level); ++x)
        ASSERT_EQ(bits(m.depth(level, x, y)), bits(local.depth(level, x, y)))
            << "level " << level << " (" << x << ", " << y << ")";
}

TEST(Faults, ServerKilledMidStreamAndRestartedEndsWithTheSameAnswers) {
  const uint32_t level = test_level(), side = 1u << level;
  auto p = build_pack("midstream", level, 31, first_encoding(), 3, 512);  // index tiles too
  const size_t total = p.reader->tiles().size();
  ASSERT_GT(total, 20u);
  const uint16_t port = free_port(p.path);
  server::ServerOptions slow;  // so that the kill lands while answers are in flight
  slow.tile_source =
      std::make_shared<looptest::WatchedTiles>([](uint64_t, std::span<uint8_t>) { std::this_thread::sleep_for(2ms); });
  auto srv = serve_on(port, p.path, slow);
  Client c({"127.0.0.1", port}, options_for(p));
  Map m = c.open("midstream");
  m.request_region(level, 0, 0, side, side, 1);
  ASSERT_TRUE(wait_until([&] { return m.stats().tiles_received >= total / 4; }));
  srv.reset();  // killed mid-stream: connections cut, queued answers lost
  const uint64_t before = m.stats().tiles_received;
  EXPECT_LT(before, total) << "the whole map arrived before the kill: nothing was in flight";
  ASSERT_TRUE(wait_until([&] { return !c.connected(); }, 5s));
  srv = serve_on(port, p.path);  // back, same pack
  ASSERT_TRUE(wait_until([&] {
    m.request_region(level, 0, 0, side, side, 1);  // index tiles open up deeper requests
    return m.region_resident(level, 0, 0, side, side);
  }));
  const MapStats s = m.stats();
  EXPECT_EQ(s.tiles_failed, 0u);
  EXPECT_EQ(s.crc_errors, 0u);
  EXPECT_EQ(s.tiles_received, total);  // each tile once: nothing lost, nothing twice
  EXPECT_GE(c.stats().connects, 2u);
  expect_exact_everywhere(m, p);
}

// A pack with tiles only directly below the skip grid (no index tiles), so a tile the
// server reports corrupt leaves exactly its cell answering from level k.
struct DiskFaultCase {
  looptest::TestPack pack;
  uint32_t level, k = 3;
  TileIndexEntry victim;
};

DiskFaultCase disk_fault_pack(const std::string& name, bool last_in_file) {
  DiskFaultCase c;
  c.level = test_level();
  c.pack = build_pack(name, c.level, 41, first_encoding(), c.k, 1 << 20);
  const auto& tiles = c.pack.reader->tiles();
  ST_CHECK(tiles.size() >= 4);
  if (last_in_file) {
    c.victim = *std::max_element(tiles.begin(), tiles.end(),
                                 [](const auto& a, const auto& b) { return a.offset < b.offset; });
  } else {
    c.victim = tiles[tiles.size() / 2];
  }
  return c;
}

// Fetches everything with a fresh client; checks the answers around the corrupt tile.
void expect_served_except_victim(uint16_t port, const DiskFaultCase& c) {
  Client cl({"127.0.0.1", port}, options_for(c.pack));
  Map m = cl.open(std::filesystem::path(c.pack.path).stem().string());
  const uint32_t side = 1u << c.level;
  const size_t total = c.pack.reader->tiles().size();
  m.request_region(c.level, 0, 0, side, side, 1);
  ASSERT_TRUE(wait_until([&] {
    const MapStats s = m.stats();
    return s.tiles_received + s.tiles_failed == total;
  }));
  EXPECT_EQ(m.stats().tiles_failed, 1u);
  EXPECT_EQ(m.stats().tiles_received, total - 1);
  const TileAddress a = tile_address(c.victim.id);
  ASSERT_EQ(a.level, c.k);
  PackEvaluator local(c.pack.reader);
  const uint32_t s = c.level - c.k;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const bool under = (x >> s) == a.x && (y >> s) == a.y;
      const float want = under ? local.depth(c.k, a.x, a.y) : local.depth(c.level, x, y);
      ASSERT_EQ(bits(m.depth(c.level, x, y)), bits(want)) << "(" << x << ", " << y << ")";
    }
}

TEST(Faults, TileBitFlippedOnDiskWhileServedIsReportedAndTheRestServed) {
  DiskFaultCase c = disk_fault_pack("flipped", false);
  auto srv = start_server({c.pack.path});
  {  // the server is up and has validated the pack; now the disk goes bad under it
    std::fstream f(c.pack.path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(std::streamoff(c.victim.offset + c.victim.stored_size / 2));
    char b = 0;
    f.read(&b, 1);
    b = char(b ^ 0x10);
    f.seekp(std::streamoff(c.victim.offset + c.victim.stored_size / 2));
    f.write(&b, 1);
  }
  expect_served_except_victim(srv.port, c);
  EXPECT_GE(srv.server->stats().tiles_corrupt, 1u);
  expect_served_except_victim(srv.port, c);  // still serving: a second client, same answers
}

TEST(Faults, PackTruncatedOnDiskWhileServedFailsOnlyTheCutTile) {
  DiskFaultCase c = disk_fault_pack("truncated", true);
  auto srv = start_server({c.pack.path});
  ASSERT_EQ(::truncate(c.pack.path.c_str(), off_t(c.victim.offset + c.victim.stored_size / 2)), 0);
  expect_served_except_victim(srv.port, c);
  EXPECT_GE(srv.server->stats().tiles_corrupt, 1u);
}

TEST(Faults, ClientDrippingOneByteAtATimeIsCutOffByTheReadTimeout) {
  const uint32_t level = test_level(), side = 1u << level;
  auto p = build_pack("drip", level, 51, first_encoding(), 3, 1024);
  server::ServerOptions so;
  so.read_timeout = 400ms;
  auto srv = start_server({p.path}, so);
  RawSocket drip(srv.port);
  ASSERT_TRUE(drip.send(looptest::hello_frame()));
  ASSERT_EQ(read_frame(drip).header.type, proto::MessageType::hello_ack);
  // One GetTiles frame, sent a byte every 40 ms: it would take ~3 s to complete, and each
  // byte keeps the connection "active", so only a per-frame deadline can end it.
  proto::GetTiles g;
  g.map_id = 1;
  for (uint64_t i = 0; i < 6; ++i) g.tiles.push_back({i, 1});
  std::vector<uint8_t> frame;
  ASSERT_TRUE(proto::encode_message(g, 5, proto::kFlagFinal, proto::Limits{}, frame));
  std::atomic<size_t> sent{0};
  std::thread dripper([&] {
    for (uint8_t b : frame) {
      if (!drip.send({b})) return;
      ++sent;
      std::this_thread::sleep_for(40ms);
    }
  });
  // Meanwhile a normal client is served in full.
  Client good({"127.0.0.1", srv.port}, options_for(p));
  Map m = good.open("drip");
  m.request_region(level, 0, 0, side, side, 1);
  ASSERT_TRUE(wait_until([&] {
    m.request_region(level, 0, 0, side, side, 1);
    return m.region_resident(level, 0, 0, side, side);
  }));
  ASSERT_TRUE(wait_until([&] { return srv.server->stats().timeouts >= 1; }, 10s));
  dripper.join();
  EXPECT_LT(sent.load(), frame.size()) << "the dripping client was never cut off";
  expect_exact_everywhere(m, p);
}

TEST(Faults, ConnectionFloodFromOneAddressIsCappedWhileOthersAreServed) {
  {  // 127.0.0.2 plays the flooder; loopback answers the whole 127/8 on Linux.
    try {
      RawSocket probe(1, 100ms, "127.0.0.2");
    } catch (const Error& e) {
      if (std::string(e.what()).find("bind") != std::string::npos)
        GTEST_SKIP() << "cannot bind 127.0.0.2 here: " << e.what();
    }
  }
  const uint32_t level = test_level(), side = 1u << level;
  auto p = build_pack("flood", level, 61, first_encoding(), 3, 1024);
  server::ServerOptions so;
  so.max_connections_per_address = 8;
  so.handshake_timeout = 1500ms;
  auto srv = start_server({p.path}, so);
  const size_t flood = looptest::small_scale() ? 40 : 120;
  std::vector<std::unique_ptr<RawSocket>> held;
  size_t refused = 0;
  for (size_t i = 0; i < flood; ++i) {
    auto s = std::make_unique<RawSocket>(srv.port, 2s, "127.0.0.2");
    if (i >= 8) {  // over the bound: one Error(overloaded) frame, then closed
      RawFrame f = read_frame(*s);
      if (f.ok && error_code_of(f) == proto::ErrorCode::overloaded && s->wait_closed()) ++refused;
    }
    held.push_back(std::move(s));
  }
  EXPECT_EQ(refused, flood - 8);
  // Another address is served in full while the flooder holds its 8 connections.
  Client good({"127.0.0.1", srv.port}, options_for(p));
  Map m = good.open("flood");
  ASSERT_TRUE(wait_until([&] {
    m.request_region(level, 0, 0, side, side, 1);
    return m.region_resident(level, 0, 0, side, side);
  }));
  expect_exact_everywhere(m, p);
  // The 8 that never said Hello are closed by the handshake timeout.
  for (size_t i = 0; i < 8; ++i) EXPECT_TRUE(held[i]->wait_closed()) << i;
  EXPECT_GE(srv.server->stats().connections_rejected, flood - 8);
  EXPECT_TRUE(wait_until([&] { return srv.server->stats().connections_open == 1; }, 5s))
      << srv.server->stats().connections_open << " open; the good client alone should be";
}

}  // namespace fault_test
}  // namespace st::client

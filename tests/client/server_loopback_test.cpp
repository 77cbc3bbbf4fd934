// The server under hostile and unlucky clients (loopback, in-process): malformed frames,
// an oversized length, an unknown map, a client that disconnects or stalls mid-frame;
// each is answered or dropped while a well-behaved client keeps being served. Also:
// reconnect with backoff, priorities, Cancel, ListMaps and Stats over the protocol.
#include <gtest/gtest.h>

#include <algorithm>
#include <mutex>
#include <thread>
#include <ctime>

#include "client/map_access.hpp"
#include "proto/proto.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::error_code_of;
using looptest::RawFrame;
using looptest::read_frame;
using looptest::RawSocket;
using looptest::start_server;
using looptest::wait_until;

using looptest::quick_options;

using looptest::first_encoding;

// A handshaken raw connection.
void handshake(RawSocket& s) {
  ASSERT_TRUE(s.send(looptest::hello_frame()));
  RawFrame ack = read_frame(s);
  ASSERT_TRUE(ack.ok);
  ASSERT_EQ(ack.header.type, proto::MessageType::hello_ack);
}

// The well-behaved client fetches the whole map again from scratch (a fresh client, so
// nothing is cached) and checks a few texels.
void good_client_still_served(uint16_t port, const std::string& name, const PackReader& reader) {
  Client c({"127.0.0.1", port}, quick_options());
  Map m = c.open(name);
  const uint32_t level = m.finest_level(), side = 1u << level;
  m.request_region(level, 0, 0, side, side, 1);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(level, 0, 0, side, side); }));
  EXPECT_EQ(m.stats().tiles_received, reader.tiles().size());
}

TEST(ServerLoopback, HostileClientsLeaveOthersServed) {
  auto p = build_pack("hostile", 6, 3, first_encoding(), 3, 1024);
  server::ServerOptions so;
  so.read_timeout = 300ms;
  auto srv = start_server({p.path}, so);
  // A client connected throughout, fetching while the others misbehave.
  Client steady({"127.0.0.1", srv.port}, quick_options());
  Map sm = steady.open("hostile");

  {  // Garbage instead of a frame: Error(bad_magic), then closed.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(std::vector<uint8_t>(48, 'X')));
    RawFrame e = read_frame(s);
    ASSERT_TRUE(e.ok);
    EXPECT_EQ(e.header.type, proto::MessageType::error);
    EXPECT_EQ(error_code_of(e), proto::ErrorCode::bad_magic);
    EXPECT_TRUE(s.wait_closed());
  }
  {  // A request before the handshake: Error(handshake_required), closed.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(looptest::open_map_frame("hostile", 1)));
    RawFrame e = read_frame(s);
    EXPECT_EQ(error_code_of(e), proto::ErrorCode::handshake_required);
    EXPECT_TRUE(s.wait_closed());
  }
  {  // An oversized length: rejected from the header alone, nothing buffered.
    RawSocket s(srv.port);
    handshake(s);
    proto::FrameHeader h;
    h.type = proto::MessageType::get_tiles;
    h.flags = proto::kFlagFinal;
    h.request_id = 7;
    h.payload_length = 1u << 30;
    std::vector<uint8_t> bytes(proto::kHeaderSize);
    proto::write_header(h, std::span<uint8_t, proto::kHeaderSize>(bytes.data(), proto::kHeaderSize));
    ASSERT_TRUE(s.send(bytes));
    RawFrame e = read_frame(s);
    EXPECT_EQ(error_code_of(e), proto::ErrorCode::oversized_frame);
    EXPECT_TRUE(s.wait_closed());
  }
  {  // An unknown map (and a path): a request error; the connection stays usable.
    RawSocket s(srv.port);
    handshake(s);
    ASSERT_TRUE(s.send(looptest::open_map_frame("nope", 2)));
    RawFrame e = read_frame(s);
    EXPECT_EQ(e.header.request_id, 2u);
    EXPECT_EQ(error_code_of(e), proto::ErrorCode::unknown_map);
    ASSERT_TRUE(s.send(looptest::open_map_frame("hostile", 3)));
    RawFrame info = read_frame(s);
    EXPECT_EQ(info.header.type, proto::MessageType::map_info);
    EXPECT_EQ(info.header.request_id, 3u);
  }
  {  // Disconnects mid-frame.
    RawSocket s(srv.port);
    handshake(s);
    auto f = looptest::open_map_frame("hostile", 4);
    f.resize(f.size() / 2);
    ASSERT_TRUE(s.send(f));
    s.close();
  }
  {  // Stalls mid-frame: closed after read_timeout.
    RawSocket s(srv.port);
    handshake(s);
    auto f = looptest::open_map_frame("hostile", 5);
    f.resize(10);
    ASSERT_TRUE(s.send(f));
    auto t0 = std::chrono::steady_clock::now();
    EXPECT_TRUE(s.wait_closed());
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 4s);
  }
  // The steady client never noticed; new clients are served.
  const uint32_t side = 1u << sm.finest_level();
  sm.request_region(sm.finest_level(), 0, 0, side, side, 1);
  ASSERT_TRUE(wait_until([&] { return sm.region_resident(sm.finest_level(), 0, 0, side, side); }));
  EXPECT_EQ(steady.stats().disconnects, 0u);
  good_client_still_served(srv.port, "hostile", *p.reader);
  const server::StatsSnapshot st = srv.server->stats();
  EXPECT_GE(st.protocol_errors, 3u);
  EXPECT_GE(st.timeouts, 1u);
  EXPECT_GE(st.errors, 4u);
}

TEST(ServerLoopback, ProtocolViolationsCloseTheConnection) {
  auto p = build_pack("violations", 5, 3, first_encoding(), 2, 1024);
  auto srv = start_server({p.path});
  proto::Limits l;  // what hello_frame proposes; the server grants the same
  {  // A second Hello: unexpected_type, closed (PROTOCOL.md §5).
    RawSocket s(srv.port);
    handshake(s);
    ASSERT_TRUE(s.send(looptest::hello_frame(2)));
    EXPECT_EQ(error_code_of(read_frame(s)), proto::ErrorCode::unexpected_type);
    EXPECT_TRUE(s.wait_closed());
  }
  {  // A payload that does not decode (ListMaps carries nothing): trailing_bytes, closed.
    RawSocket s(srv.port);
    handshake(s);
    std::vector<uint8_t> out;
    const uint8_t junk[] = {1, 2, 3};
    ASSERT_TRUE(proto::append_frame(proto::MessageType::list_maps, proto::kFlagFinal, 3, junk, l, out));
    ASSERT_TRUE(s.send(out));
    RawFrame e = read_frame(s);
    EXPECT_EQ(e.header.request_id, 0u);
    EXPECT_EQ(error_code_of(e), proto::ErrorCode::trailing_bytes);
    EXPECT_TRUE(s.wait_closed());
  }
  {  // A request id reused while in flight: duplicate_request_id, closed.
    RawSocket s(srv.port);
    handshake(s);
    ASSERT_TRUE(s.send(looptest::open_map_frame("violations", 4)));
    ASSERT_EQ(read_frame(s).header.type, proto::MessageType::map_info);
    proto::GetTiles g;
    g.map_id = 1;
    for (auto& t : p.reader->tiles()) g.tiles.push_back({t.id, 0});
    std::vector<uint8_t> out;
    ASSERT_TRUE(proto::encode_message(g, 9, proto::kFlagFinal, l, out));
    ASSERT_TRUE(proto::encode_message(g, 9, proto::kFlagFinal, l, out));  // same id, same read
    ASSERT_TRUE(s.send(out));
    bool saw_duplicate = false;
    for (RawFrame f = read_frame(s); f.ok; f = read_frame(s))
      if (f.header.type == proto::MessageType::error && f.header.request_id == 0)
        saw_duplicate = error_code_of(f) == proto::ErrorCode::duplicate_request_id;
    EXPECT_TRUE(saw_duplicate);
  }
  // Unknown tiles fail alone.
  {
    RawSocket s(srv.port);
    handshake(s);
    ASSERT_TRUE(s.send(looptest::open_map_frame("violations", 4)));
    ASSERT_EQ(read_frame(s).header.type, proto::MessageType::map_info);
    proto::GetTiles g;
    g.map_id = 1;
    g.tiles.push_back({make_tile_id(2, 3, 3) + 12345, 0});
    std::vector<uint8_t> out;
    ASSERT_TRUE(proto::encode_message(g, 5, proto::kFlagFinal, l, out));
    ASSERT_TRUE(s.send(out));
    RawFrame f = read_frame(s);
    EXPECT_EQ(f.header.type, proto::MessageType::tile_error);
    EXPECT_TRUE(f.header.final());
    proto::TileError te;
    ASSERT_TRUE(proto::decode_payload(f.payload, l, te));
    EXPECT_EQ(te.code, proto::ErrorCode::unknown_tile);
  }
}

TEST(ServerLoopback, ClientsCanNameOnlyCatalogMaps) {
  auto p = build_pack("catalog", 5, 1, first_encoding(), 2, 1024);
  auto srv = start_server({p.path});
  Client c({"127.0.0.1", srv.port}, quick_options());
  auto maps = c.list_maps();
  ASSERT_EQ(maps.size(), 1u);
  EXPECT_EQ(maps[0].name, "catalog");
  EXPECT_EQ(maps[0].resolution_log2, 5u);
  EXPECT_EQ(maps[0].tile_count, p.reader->tiles().size());
  EXPECT_THROW(c.open("missing"), Error);
  EXPECT_THROW(c.open("../loopback/catalog"), Error);  // refused by the name rules
  EXPECT_THROW(c.open("/etc/passwd"), Error);
  EXPECT_NO_THROW(c.open("catalog"));
}

TEST(ServerLoopback, StatsAnsweredOverTheProtocol) {
  auto p = build_pack("stats", 6, 2, first_encoding(), 3, 1024);
  auto srv = start_server({p.path});
  Client c({"127.0.0.1", srv.port}, quick_options());
  Map m = c.open("stats");
  m.request_region(6, 0, 0, 64, 64, 1);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(6, 0, 0, 64, 64); }));
  client::ServerStats s = c.server_stats();
  auto counter = [&](const std::string& name) -> uint64_t {
    for (auto& x : s.counters)
      if (x.name == name) return x.value;
    return ~uint64_t(0);
  };
  EXPECT_EQ(counter("tiles_sent"), p.reader->tiles().size());
  EXPECT_EQ(counter("connections_open"), 1u);
  EXPECT_GT(counter("tile_bytes_sent"), 0u);
  ASSERT_EQ(s.histograms.size(), 1u);
  uint64_t samples = 0;
  for (auto& b : s.histograms[0].buckets) samples += b.count;
  EXPECT_EQ(samples, p.reader->tiles().size());
}

TEST(ServerLoopback, ClientRetriesWithBackoffAndResumesAfterServerRestart) {
  auto p = build_pack("restart", 6, 4, first_encoding(), 3, 1024);
  uint16_t port;
  {  // find a free port, then give it back
    auto probe = start_server({p.path});
    port = probe.port;
    probe.stop();
  }
  Client c({"127.0.0.1", port}, quick_options());
  ASSERT_TRUE(wait_until([&] { return c.stats().connect_failures >= 2; }, 5s));
  EXPECT_FALSE(c.connected());
  server::ServerOptions so;
  so.port = port;
  so.log = [](const std::string&) {};
  auto srv = std::make_unique<server::Server>(server::Catalog::scan(std::vector<std::string>{p.path}), so);
  srv->start();
  Map m = c.open("restart");
  ASSERT_TRUE(wait_until([&] { return m.region_resident(6, 0, 0, 32, 64) || (m.request_region(6, 0, 0, 32, 64, 1), false); }));
  // The server goes away and comes back: the map is reopened and fetching resumes.
  srv->stop();
  srv.reset();
  ASSERT_TRUE(wait_until([&] { return !c.connected(); }, 5s));
  srv = std::make_unique<server::Server>(server::Catalog::scan(std::vector<std::string>{p.path}), so);
  srv->start();
  m.request_region(6, 0, 0, 64, 64, 1);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(6, 0, 0, 64, 64); }));
  EXPECT_GE(c.stats().connects, 2u);
  PackEvaluator local(p.reader);
  for (uint64_t y = 0; y < 64; ++y)
    for (uint64_t x = 0; x < 64; ++x) ASSERT_EQ(m.depth(6, x, y), local.depth(6, x, y));
}

// A slow server (each tile send waits a little) so requests queue up on it.
server::ServerOptions slow_server(std::shared_ptr<std::pair<std::mutex, std::vector<uint64_t>>> order,
                                  std::chrono::milliseconds delay) {
  server::ServerOptions so;
  so.tile_source = std::make_shared<looptest::WatchedTiles>([order, delay](uint64_t id, std::span<uint8_t>) {
    {
      std::lock_guard lock(order->first);
      order->second.push_back(id);
    }
    std::this_thread::sleep_for(delay);
  });
  return so;
}

TEST(ServerLoopback, HigherPriorityRequestsAreServedFirst) {
  auto p = build_pack("prio", 7, 9, first_encoding(), 4, 1 << 20);  // 256 cells, no index tiles
  ASSERT_GT(p.reader->tiles().size(), 40u);
  auto order = std::make_shared<std::pair<std::mutex, std::vector<uint64_t>>>();
  auto srv = start_server({p.path}, slow_server(order, 2ms));
  ClientOptions o = quick_options();
  o.cache_slots = uint32_t(p.reader->tiles().size());
  Client c({"127.0.0.1", srv.port}, o);
  Map m = c.open("prio");
  // The left half at low priority: all of it goes out at once and queues on the server.
  m.request_region(7, 0, 0, 64, 128, 1);
  ASSERT_TRUE(wait_until([&] { return m.stats().tiles_received >= 2; }));
  // Then the right half, urgent.
  m.request_region(7, 64, 0, 64, 128, 100);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(7, 0, 0, 128, 128); }, 60s));
  std::lock_guard lock(order->first);
  auto is_right = [](uint64_t id) { return tile_address(id).x >= 8; };
  const size_t right = size_t(std::count_if(order->second.begin(), order->second.end(), is_right));
  ASSERT_GT(right, 0u);
  // The urgent tiles were sent before the tail of the low-priority ones.
  size_t last_right = 0, last_left = 0;
  for (size_t i = 0; i < order->second.size(); ++i) (is_right(order->second[i]) ? last_right : last_left) = i;
  EXPECT_LT(last_right, last_left);
}

TEST(ServerLoopback, CancelledTilesAreAnsweredAndNotSent) {
  auto p = build_pack("cancel", 7, 9, first_encoding(), 4, 1 << 20);
  auto order = std::make_shared<std::pair<std::mutex, std::vector<uint64_t>>>();
  auto srv = start_server({p.path}, slow_server(order, 3ms));
  ClientOptions o = quick_options();
  o.cache_slots = uint32_t(p.reader->tiles().size());
  Client c({"127.0.0.1", srv.port}, o);
  Map m = c.open("cancel");
  m.request_region(7, 0, 0, 128, 128, 1);
  ASSERT_TRUE(wait_until([&] { return m.stats().tiles_received >= 2; }));
  m.cancel_outside(7, 0, 0, 16, 16);  // keep one corner
  ASSERT_TRUE(wait_until([&] {
    MapStats s = m.stats();
    return s.tiles_cancelled > 0 && s.tiles_received + s.tiles_cancelled == s.tiles_requested;
  }, 30s));
  EXPECT_GT(srv.server->stats().tiles_cancelled, 0u);
  std::lock_guard lock(order->first);
  EXPECT_LT(order->second.size(), p.reader->tiles().size());  // not everything was read and sent
}

}  // namespace
}  // namespace st::client

namespace st::client {
namespace {

TEST(ServerLoopback, StopEndsConnectionsAndWakesTheSignalWaiter) {
  auto p = build_pack("lifecycle", 5, 6, first_encoding(), 2, 1024);
  auto srv = start_server({p.path});
  Client c({"127.0.0.1", srv.port}, quick_options());
  Map m = c.open("lifecycle");
  ASSERT_TRUE(c.connected());
  std::atomic<int> waited{-1};
  std::thread waiter([&] { waited = srv.server->wait_for_signal(); });
  std::this_thread::sleep_for(50ms);  // let it register
  const auto t0 = std::chrono::steady_clock::now();
  srv.server->stop();
  waiter.join();
  EXPECT_EQ(waited.load(), 0);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);
  ASSERT_TRUE(wait_until([&] { return !c.connected(); }, 5s));
  // The map keeps answering (coarsely) without a server.
  EXPECT_NO_THROW((void)m.depth(5, 1, 1));
  srv.server->stop();  // idempotent
}

// The low-latency mode (I/O threads poll before they sleep) serves the same bytes, lets
// the threads sleep once clients go quiet, and still stops promptly.
TEST(ServerLoopback, BusyPollingServesTheMapAndStops) {
  auto p = build_pack("busypoll", 6, 9, first_encoding(), 2, 1024);
  server::ServerOptions so;
  so.busy_poll = std::chrono::microseconds(200);
  so.threads = 2;
  auto srv = start_server({p.path}, so);
  {
    Client c({"127.0.0.1", srv.port}, quick_options());
    Map m = c.open("busypoll");
    const uint32_t level = m.finest_level(), side = 1u << level;
    m.request_region(level, 0, 0, side, side, 1);
    ASSERT_TRUE(wait_until([&] { return m.region_resident(level, 0, 0, side, side); }));
    EXPECT_EQ(m.stats().tiles_received, p.reader->tiles().size());
    PackEvaluator local(p.reader);
    for (uint64_t i = 0; i < 256; ++i) {
      const uint64_t x = (i * 37) % side, y = (i * 91) % side;
      EXPECT_EQ(m.depth(level, x, y), local.depth(level, x, y));
    }
  }
  // Quiet now: the I/O threads must be asleep in the reactor, not spinning. The
  // process's CPU time over 300 ms of silence stays far below the wall time.
  std::this_thread::sleep_for(50ms);
  timespec a{}, b{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &a);
  std::this_thread::sleep_for(300ms);
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &b);
  const double cpu_s = double(b.tv_sec - a.tv_sec) + double(b.tv_nsec - a.tv_nsec) * 1e-9;
  EXPECT_LT(cpu_s, 0.15) << "the polling threads kept spinning with no client";
  const auto t0 = std::chrono::steady_clock::now();
  srv.server->stop();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 3s);
}

}  // namespace
}  // namespace st::client

namespace st::client {
namespace {

TEST(ServerLoopback, ClientThatStopsReadingIsCutOffWithoutStarvingOthers) {
  // Big, incompressible tiles so that the answers owed overflow the socket buffers.
  auto p = build_pack("stalled", 9, 21, first_encoding(), 3, 1 << 20);
  uint64_t stored = 0;
  for (auto& t : p.reader->tiles()) stored += t.stored_size;
  server::ServerOptions so;
  so.write_timeout = 300ms;
  auto srv = start_server({p.path}, so);
  RawSocket greedy(srv.port);
  handshake(greedy);
  ASSERT_TRUE(greedy.send(looptest::open_map_frame("stalled", 2)));
  ASSERT_EQ(read_frame(greedy).header.type, proto::MessageType::map_info);
  proto::Limits l;
  std::vector<uint8_t> out;
  uint64_t owed = 0;
  for (uint32_t id = 10; id < 10u + l.max_in_flight - 1u; ++id) {
    proto::GetTiles g;
    g.map_id = 1;
    for (auto& t : p.reader->tiles()) g.tiles.push_back({t.id, 0});
    ASSERT_TRUE(proto::encode_message(g, id, proto::kFlagFinal, l, out));
    owed += stored;
  }
  ASSERT_GT(owed, 24u << 20) << "not enough to fill the socket buffers (tcp_wmem + tcp_rmem maxima)";
  ASSERT_TRUE(greedy.send(out));  // ... and never read the answers
  // Meanwhile another client is served in full.
  good_client_still_served(srv.port, "stalled", *p.reader);
  // The greedy one is cut off by the write timeout.
  ASSERT_TRUE(wait_until([&] { return srv.server->stats().timeouts >= 1; }, 10s));
  ASSERT_TRUE(wait_until([&] { return srv.server->stats().connections_open == 0; }, 10s));
}

TEST(ServerLoopback, AnswersStayWholeWhenUnpipelinedRequestsFillTheSocket) {
  // Requests sent one at a time to a client that does not read: each is answered from
  // the reader with a non-blocking send until the socket buffers fill mid-batch; the rest
  // of that batch (the spill) and every later answer must follow in order, frames whole.
  auto p = build_pack("spill", 9, 21, first_encoding(), 3, 1 << 20);
  auto srv = start_server({p.path});
  RawSocket s(srv.port, 20s);
  s.set_receive_buffer(64 << 10);  // with the server's send buffer (4 MiB at most): full after ~4 MiB
  handshake(s);
  ASSERT_TRUE(s.send(looptest::open_map_frame("spill", 2)));
  ASSERT_EQ(read_frame(s).header.type, proto::MessageType::map_info);
  const auto& tiles = p.reader->tiles();
  const uint32_t per_request = 16, requests = 60;  // one inline batch each; under max_in_flight (64)
  proto::Limits l;
  uint64_t owed = 0;
  for (uint32_t r = 0; r < requests; ++r) {
    proto::GetTiles g;
    g.map_id = 1;
    for (uint32_t i = 0; i < per_request; ++i) {
      const auto& t = tiles[(r * per_request + i) % tiles.size()];
      g.tiles.push_back({t.id, 0});
      owed += t.stored_size;
    }
    std::vector<uint8_t> out;
    ASSERT_TRUE(proto::encode_message(g, 10 + r, proto::kFlagFinal, l, out));
    ASSERT_TRUE(s.send(out));
    std::this_thread::sleep_for(1ms);  // its own read on the server
  }
  ASSERT_GT(owed, 8u << 20) << "not enough to fill the socket buffers";
  for (uint32_t r = 0; r < requests; ++r)
    for (uint32_t i = 0; i < per_request; ++i) {
      RawFrame f = read_frame(s);
      ASSERT_TRUE(f.ok) << "request " << r << " tile " << i;
      ASSERT_EQ(f.header.type, proto::MessageType::tile_data);
      ASSERT_EQ(f.header.request_id, 10 + r);
      ASSERT_EQ(f.header.final(), i + 1 == per_request);
      ASSERT_EQ(proto::crc32(f.payload), f.header.payload_crc32);
      const auto want = p.reader->read_stored(tiles[(r * per_request + i) % tiles.size()].id);
      ASSERT_GE(f.payload.size(), want.size());
      ASSERT_TRUE(std::equal(want.begin(), want.end(), f.payload.end() - std::ptrdiff_t(want.size())));
    }
  EXPECT_TRUE(wait_until([&] { return srv.server->stats().tiles_sent == uint64_t(requests) * per_request; }));
}

}  // namespace
}  // namespace st::client

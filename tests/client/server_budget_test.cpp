// The server's budgets against a laptop attacker, over loopback: pending connections
// (never authenticated, or idle after Hello) from several addresses cannot keep a client
// holding the key out; a stranger's frames are bounded by the handshake limit however
// large a header claims; pipelined OpenMaps of a big skip grid do not multiply memory; a
// server at its descriptor limit refuses with Error(overloaded) instead of leaving clients
// hanging; stopping the server tells clients shutting_down; a refused client names why.
#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <thread>

#include "client/map_access.hpp"
#include "proto/proto.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::error_code_of;
using looptest::RawFrame;
using looptest::RawSocket;
using looptest::read_frame;
using looptest::start_server;
using looptest::wait_until;

const std::vector<uint8_t> kKey = proto::parse_key("0f1e2d3c4b5a69788796a5b4c3d2e1f0", "test key");

std::vector<uint8_t> hello_with(uint32_t features) {
  proto::Limits l;
  l.max_frame_bytes = proto::kMinFrameBytes;
  proto::Hello h = proto::make_hello(proto::Limits{}, "raw");
  h.features = features;
  std::vector<uint8_t> out;
  ST_CHECK(proto::encode_message(h, 1, proto::kFlagFinal, l, out));
  return out;
}

size_t rss_bytes() {
  std::ifstream f("/proc/self/statm");
  size_t pages = 0, resident = 0;
  f >> pages >> resident;
  return resident * size_t(::sysconf(_SC_PAGESIZE));
}

// Every tile of the map arrives through a Client holding `key`.
void expect_served(uint16_t port, const looptest::TestPack& p, const std::string& name,
                   std::vector<uint8_t> key = {}) {
  ClientOptions o = looptest::quick_options();
  o.key = std::move(key);
  o.cache_slots = uint32_t(p.reader->tiles().size()) + 8;
  Client c({"127.0.0.1", port}, o);
  Map m = c.open(name);
  const uint32_t level = m.finest_level(), side = 1u << level;
  ASSERT_TRUE(wait_until([&] {
    m.request_region(level, 0, 0, side, side, 1);
    return m.region_resident(level, 0, 0, side, side);
  }));
  EXPECT_EQ(m.stats().tiles_failed, 0u);
}

struct Flood {
  std::vector<std::unique_ptr<RawSocket>> sockets;
  // `per_address` connections from each of 127.0.0.2..(1 + addresses); with `hello`,
  // each sends a Hello (and nothing after).
  void open(uint16_t port, int addresses, int per_address, bool hello) {
    for (int a = 0; a < addresses; ++a) {
      const std::string from = "127.0.0." + std::to_string(2 + a);
      for (int i = 0; i < per_address; ++i) {
        auto s = std::make_unique<RawSocket>(port, 2s, from.c_str());
        if (hello) s->send(hello_with(0));
        sockets.push_back(std::move(s));
      }
    }
  }
};

server::ServerOptions small_budgets() {
  server::ServerOptions o;
  o.max_connections = 48;
  o.max_pending_per_address = 6;
  o.max_pending_per_prefix = 16;
  o.max_pending_connections = 24;
  o.pending_grace = std::chrono::milliseconds(0);  // the flood below is opened in a burst
  o.log = [](const std::string&) {};
  return o;
}

TEST(ServerBudget, StrangersFromFourAddressesCannotKeepTheKeyHolderOut) {
  auto p = build_pack("budget_keyed", 6, 3, looptest::first_encoding(), 3, 512);
  server::ServerOptions o = small_budgets();
  o.key = kKey;
  auto srv = start_server({p.path}, o);
  Flood flood;  // 4 x 30 connections that never say a word: 2.5x max_connections
  flood.open(srv.port, 4, 30, false);
  expect_served(srv.port, p, "budget_keyed", kKey);
  const auto st = srv.server->stats();
  EXPECT_GE(st.connections_evicted, 120u - 24u);  // all but a budget's worth were evicted
  EXPECT_LE(st.connections_open, 48u);
}

TEST(ServerBudget, IdleAfterHelloWithoutAKeyCannotFillTheServer) {
  auto p = build_pack("budget_open", 6, 4, looptest::first_encoding(), 3, 512);
  auto srv = start_server({p.path}, small_budgets());
  Flood flood;
  flood.open(srv.port, 4, 30, true);
  expect_served(srv.port, p, "budget_open");
  EXPECT_GE(srv.server->stats().connections_evicted, 120u - 24u);
  // The flood's connections still open are within the pending budget.
  EXPECT_LE(srv.server->stats().connections_open, 24u + 1u);
}

TEST(ServerBudget, AFloodYoungerThanTheGraceCannotHoldTheServerFull) {
  // Every flood connection is younger than the grace, and there are more of them than
  // max_connections: the grace shields only addresses within their budget, so the key
  // holder still gets a slot (refused with overloaded before).
  auto p = build_pack("budget_young", 6, 3, looptest::first_encoding(), 3, 512);
  server::ServerOptions o = small_budgets();
  o.pending_grace = std::chrono::seconds(30);
  o.key = kKey;
  auto srv = start_server({p.path}, o);
  Flood flood;
  flood.open(srv.port, 4, 20, false);  // 80 > max_connections 48
  expect_served(srv.port, p, "budget_young", kKey);
  EXPECT_GE(srv.server->stats().connections_evicted, 80u - 48u);
  EXPECT_LE(srv.server->stats().connections_open, 48u);
}

TEST(ServerBudget, AnHonestBurstFromOneHostIsNotEvicted) {
  auto p = build_pack("budget_burst", 5, 10, looptest::first_encoding(), 3, 512);
  server::ServerOptions o = small_budgets();
  o.pending_grace = std::chrono::seconds(30);  // every connection of the burst is young
  o.max_connections = 200;
  o.max_connections_per_address = 0;
  auto srv = start_server({p.path}, o);
  std::vector<std::unique_ptr<RawSocket>> socks;
  auto open = looptest::hello_frame(1);
  auto om = looptest::open_map_frame("budget_burst", 2);
  open.insert(open.end(), om.begin(), om.end());
  for (int i = 0; i < 100; ++i) {  // 100 at once from 127.0.0.1: 16x the per-address budget
    socks.push_back(std::make_unique<RawSocket>(srv.port, 5s));
    ASSERT_TRUE(socks.back()->send(open));
  }
  for (auto& s : socks) {
    ASSERT_EQ(read_frame(*s).header.type, proto::MessageType::hello_ack);
    ASSERT_EQ(read_frame(*s).header.type, proto::MessageType::map_info);
  }
  EXPECT_EQ(srv.server->stats().connections_evicted, 0u);
  EXPECT_EQ(srv.server->stats().connections_open, 100u);
}

// Useful connections (they opened a map) from several addresses of one /24 are bounded
// by the network's budget, not only each address's: 127.0.0.2-3 fill 127.0.0.0/24's 6,
// a third address's OpenMap gets Error(overloaded) and a close, while another /24
// (127.0.1.x) is still served; a network's connection that closes makes room for the
// next. Pending connections (a Hello, nothing else) do not count against it.
TEST(ServerBudget, UsefulConnectionsAreBoundedPerNetwork) {
  auto p = build_pack("budget_prefix", 5, 9, looptest::first_encoding(), 3, 512);
  server::ServerOptions o;
  o.max_connections = 64;
  o.max_connections_per_address = 3;
  o.max_connections_per_prefix = 6;
  o.log = [](const std::string&) {};
  auto srv = start_server({p.path}, o);
  auto open = looptest::hello_frame(1);
  auto om = looptest::open_map_frame("budget_prefix", 2);
  open.insert(open.end(), om.begin(), om.end());
  // A fresh connection from `from` that opens the map: the socket if served, null if
  // refused with Error(overloaded) (at accept, or answering the OpenMap).
  auto connect = [&](const char* from) {
    auto s = std::make_unique<RawSocket>(srv.port, 5s, from);
    EXPECT_TRUE(s->send(open));
    RawFrame f = read_frame(*s);
    if (f.header.type == proto::MessageType::hello_ack) f = read_frame(*s);
    if (f.header.type == proto::MessageType::map_info) return s;
    EXPECT_EQ(error_code_of(f), proto::ErrorCode::overloaded);
    return std::unique_ptr<RawSocket>();
  };
  RawSocket idle(srv.port, 5s, "127.0.0.5");  // pending: not counted against the network
  ASSERT_TRUE(idle.send(looptest::hello_frame(1)));
  ASSERT_EQ(read_frame(idle).header.type, proto::MessageType::hello_ack);
  std::vector<std::unique_ptr<RawSocket>> held;
  for (const char* from : {"127.0.0.2", "127.0.0.3"})
    for (int i = 0; i < 3; ++i) {
      held.push_back(connect(from));
      ASSERT_TRUE(held.back()) << from << " #" << i;
    }
  EXPECT_FALSE(connect("127.0.0.4")) << "a third address of a full /24";
  EXPECT_FALSE(connect("127.0.0.3")) << "an address at its own bound";
  auto other = connect("127.0.1.2");
  EXPECT_TRUE(other) << "another /24";
  EXPECT_EQ(srv.server->stats().connections_rejected, 2u);
  held.pop_back();  // one of 127.0.0.3's closes: the network has room again
  ASSERT_TRUE(wait_until([&] { return srv.server->stats().connections_open == 6 + 1; }));
  EXPECT_TRUE(connect("127.0.0.4"));
}

TEST(ServerBudget, AStrangerCannotClaimAPostAuthFrame) {
  auto p = build_pack("budget_preauth", 5, 5, looptest::first_encoding(), 3, 512);
  server::ServerOptions o;
  o.key = kKey;
  o.log = [](const std::string&) {};
  auto srv = start_server({p.path}, o);
  const size_t before = rss_bytes();
  std::vector<std::unique_ptr<RawSocket>> socks;
  for (int i = 0; i < 32; ++i) {
    auto s = std::make_unique<RawSocket>(srv.port, 5s);
    ASSERT_TRUE(s->send(hello_with(proto::kFeatureAuth)));
    RawFrame ack = read_frame(*s);
    ASSERT_EQ(ack.header.type, proto::MessageType::hello_ack);
    // An Auth header claiming 4,194,280 payload bytes, and 1 KiB of them.
    proto::FrameHeader h;
    h.type = proto::MessageType::auth;
    h.request_id = 2;
    h.flags = proto::kFlagFinal;
    h.payload_length = (4u << 20) - 24;
    std::array<uint8_t, proto::kHeaderSize> bytes{};
    proto::write_header(h, bytes);
    std::vector<uint8_t> out(bytes.begin(), bytes.end());
    out.resize(out.size() + 1024, 0xAB);
    s->send(out);
    RawFrame e = read_frame(*s);
    ASSERT_EQ(e.header.type, proto::MessageType::error);
    EXPECT_EQ(error_code_of(e), proto::ErrorCode::oversized_frame);
    socks.push_back(std::move(s));
  }
  EXPECT_LT(rss_bytes(), before + (32u << 20));  // was 32 x 4 MiB zero-filled
}

TEST(ServerBudget, FramesAreBufferedAsTheirBytesArrive) {
  proto::Limits l;
  l.max_frame_bytes = proto::kMaxFrameBytesCeiling;
  proto::FrameParser parser(l, proto::Receiver::any);
  proto::FrameHeader h;
  h.type = proto::MessageType::ping;
  h.payload_length = (64u << 20) - 24;  // claims the ceiling (a Ping is 8 bytes: decoding would refuse it)
  std::array<uint8_t, proto::kHeaderSize> bytes{};
  proto::write_header(h, bytes);
  const size_t before = rss_bytes();
  std::vector<proto::FrameParser> many(64, parser);
  for (auto& p : many) {
    auto r = p.feed(bytes);
    ASSERT_EQ(r.state, proto::FrameParser::State::need_more);
    std::vector<uint8_t> some(1000, 1);
    ASSERT_EQ(p.feed(some).state, proto::FrameParser::State::need_more);
  }
  EXPECT_LT(rss_bytes(), before + (16u << 20));  // 64 x 64 MiB claimed, 64 x 1000 B sent
}

uint32_t big_skip() { return looptest::small_scale() ? 6 : 8; }

TEST(ServerBudget, PipelinedOpenMapsShareTheSkipGrid) {
  const uint32_t k = big_skip();
  auto p = build_pack("budget_grid", k + 1, 6, looptest::first_encoding(), k, 4096);
  server::ServerOptions o;
  o.log = [](const std::string&) {};
  auto srv = start_server({p.path}, o);
  const size_t grid = p.reader->grid_bytes().size();
  const size_t before = rss_bytes();
  std::vector<std::unique_ptr<RawSocket>> socks;
  const int conns = 30, per_conn = 64;
  for (int c = 0; c < conns; ++c) {
    auto s = std::make_unique<RawSocket>(srv.port, 5s);
    std::vector<uint8_t> out = looptest::hello_frame(1);
    for (int i = 0; i < per_conn; ++i) {
      auto f = looptest::open_map_frame("budget_grid", uint32_t(2 + i));
      out.insert(out.end(), f.begin(), f.end());
    }
    ASSERT_TRUE(s->send(out));  // and never read
    socks.push_back(std::move(s));
  }
  std::this_thread::sleep_for(300ms);
  // Copies would be conns x per_conn x grid (1.1 GiB at skip level 8).
  EXPECT_LT(rss_bytes(), before + std::max<size_t>(64u << 20, size_t(conns) * per_conn * grid / 16))
      << "grid " << grid << " B";
  // And they are all answered once read.
  RawFrame ack = read_frame(*socks[0]);
  ASSERT_EQ(ack.header.type, proto::MessageType::hello_ack);
  for (int i = 0; i < per_conn; ++i) {
    RawFrame f = read_frame(*socks[0]);
    ASSERT_EQ(f.header.type, proto::MessageType::map_info) << i;
    proto::MapInfo info;
    proto::Limits big;
    big.max_frame_bytes = proto::kMaxFrameBytesCeiling;
    ASSERT_TRUE(proto::decode_payload(f.payload, big, info));
    EXPECT_EQ(info.skip_grid.size(), grid);
    EXPECT_TRUE(std::equal(info.skip_grid.begin(), info.skip_grid.end(), p.reader->grid_bytes().begin()));
  }
}

TEST(ServerBudget, StoppingTellsClientsShuttingDownBetweenFrames) {
  auto p = build_pack("budget_stop", 6, 7, looptest::first_encoding(), 3, 512);
  server::ServerOptions o;
  o.log = [](const std::string&) {};
  auto srv = start_server({p.path}, o);
  RawSocket s(srv.port, 5s);
  ASSERT_TRUE(s.send(looptest::hello_frame(1)));
  ASSERT_EQ(read_frame(s).header.type, proto::MessageType::hello_ack);
  std::thread stopper([&] { srv.stop(); });
  RawFrame f = read_frame(s);
  stopper.join();
  ASSERT_TRUE(f.ok);
  EXPECT_EQ(f.header.type, proto::MessageType::error);
  EXPECT_EQ(f.header.request_id, proto::kNoRequest);
  EXPECT_EQ(error_code_of(f), proto::ErrorCode::shutting_down);
  EXPECT_TRUE(s.wait_closed());
}

TEST(ServerBudget, ARefusedClientNamesTheRefusal) {
  auto p = build_pack("budget_refused", 5, 8, looptest::first_encoding(), 3, 512);
  server::ServerOptions o;
  o.max_connections = 1;
  o.max_pending_connections = 0;  // no eviction: the one slot is held
  o.max_pending_per_address = 0;
  o.max_pending_per_prefix = 0;
  o.log = [](const std::string&) {};
  auto srv = start_server({p.path}, o);
  RawSocket holder(srv.port, 5s);  // a useful connection (it opened a map): not evicted
  auto open = looptest::hello_frame(1);
  auto om = looptest::open_map_frame("budget_refused", 2);
  open.insert(open.end(), om.begin(), om.end());
  ASSERT_TRUE(holder.send(open));
  ASSERT_EQ(read_frame(holder).header.type, proto::MessageType::hello_ack);
  ASSERT_EQ(read_frame(holder).header.type, proto::MessageType::map_info);
  ClientOptions co = looptest::quick_options();
  co.request_timeout = 1500ms;
  Client c({"127.0.0.1", srv.port}, co);
  try {
    (void)c.open("budget_refused");
    ADD_FAILURE() << "opened a map on a full server";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("overloaded"), std::string::npos) << e.what();
  }
}

// A server whose process may hold only ~120 descriptors: it lowers its connection limit
// to fit (so the excess gets Error(overloaded)), and out of descriptors altogether it
// still refuses newcomers with an Error instead of leaving them in the backlog. The
// server runs in a child process, which alone gets the low limit.
TEST(ServerBudget, DescriptorLimitMeansOverloadedNotAHang) {
  auto p = build_pack("budget_fds", 5, 9, looptest::first_encoding(), 3, 512);
  int to_parent[2], to_child[2];
  ASSERT_EQ(::pipe(to_parent), 0);
  ASSERT_EQ(::pipe(to_child), 0);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::close(to_parent[0]);
    ::close(to_child[1]);
    rlimit r{120, 120};
    if (::setrlimit(RLIMIT_NOFILE, &r) != 0) ::_exit(3);
    try {
      server::ServerOptions o;
      o.port = 0;
      o.max_connections_per_address = 0;
      o.max_pending_connections = o.max_pending_per_address = o.max_pending_per_prefix = 0;
      o.log = [](const std::string&) {};
      server::Server s(server::Catalog::scan(std::vector<std::string>{p.path}), o);
      s.start();
      const uint16_t port = s.port();
      if (::write(to_parent[1], &port, sizeof port) != sizeof port) ::_exit(4);
      char cmd = 0;
      std::vector<int> burned;
      burned.reserve(128);
      while (::read(to_child[0], &cmd, 1) == 1)
        if (cmd == 'b')  // burn every descriptor left
          for (int fd; (fd = ::open("/dev/null", O_RDONLY)) >= 0;) burned.push_back(fd);
      for (int fd : burned) ::close(fd);  // stopping is not what this test is about
      s.stop();
    } catch (...) {
      ::_exit(5);
    }
    ::_exit(0);
  }
  ::close(to_parent[1]);
  ::close(to_child[0]);
  uint16_t port = 0;
  ASSERT_EQ(::read(to_parent[0], &port, sizeof port), ssize_t(sizeof port));
  std::vector<std::unique_ptr<RawSocket>> socks;
  int acked = 0, overloaded = 0, silent = 0;
  auto open = looptest::hello_frame(1);  // useful connections: never evicted to make room
  auto om = looptest::open_map_frame("budget_fds", 2);
  open.insert(open.end(), om.begin(), om.end());
  for (int i = 0; i < 100; ++i) {
    auto s = std::make_unique<RawSocket>(port, 3s);
    s->send(open);
    RawFrame f = read_frame(*s);
    if (f.ok && f.header.type == proto::MessageType::hello_ack) ++acked;
    else if (f.ok && error_code_of(f) == proto::ErrorCode::overloaded) ++overloaded;
    else ++silent;
    socks.push_back(std::move(s));
  }
  EXPECT_EQ(silent, 0);
  EXPECT_GT(acked, 20);
  EXPECT_GT(overloaded, 0);
  socks.resize(10);  // room again; then the child burns every descriptor it has left
  std::this_thread::sleep_for(200ms);
  ASSERT_EQ(::write(to_child[1], "b", 1), 1);
  std::this_thread::sleep_for(200ms);
  for (int i = 0; i < 5; ++i) {
    RawSocket s(port, 3s);
    s.send(looptest::hello_frame(1));
    RawFrame f = read_frame(s);
    ASSERT_TRUE(f.ok) << "connection " << i << " got nothing out of descriptors";
    EXPECT_EQ(error_code_of(f), proto::ErrorCode::overloaded);
  }
  socks.clear();
  ::close(to_child[1]);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
}

}  // namespace
}  // namespace st::client

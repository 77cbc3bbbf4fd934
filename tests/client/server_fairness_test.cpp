// The server's connection budgets against many small networks (PROTOCOL.md §11, SECURITY.md):
// a pending-connection churn spread over many addresses, each within its own budget,
// recycling connections faster than the grace, does not lock honest clients out; and
// useful-looking idle connections of a few networks that fill max_connections give way
// to a newcomer from a network that holds little. Loopback addresses 127.0.x.2 play the
// networks; every socket is bounded in time and count.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "proto/proto.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace {

using namespace std::chrono_literals;
using looptest::RawFrame;
using looptest::RawSocket;
using looptest::read_frame;

std::vector<uint8_t> list_maps_frame(uint32_t id) {
  std::vector<uint8_t> out;
  proto::Limits l;
  ST_CHECK(proto::encode_message(proto::ListMaps{}, id, proto::kFlagFinal, l, out));
  return out;
}

// Hello then ListMaps on a fresh connection from `source`: true if both were answered
// (HelloAck, MapList); the socket is returned open in `keep` when given.
bool handshake_and_list(uint16_t port, const char* source, std::unique_ptr<RawSocket>* keep = nullptr,
                        proto::ErrorCode* refused = nullptr) {
  auto s = std::make_unique<RawSocket>(port, 2s, source);
  if (!s->send(looptest::hello_frame(1))) return false;
  RawFrame ack = read_frame(*s);
  if (!ack.ok || ack.header.type != proto::MessageType::hello_ack) {
    if (refused && ack.ok) *refused = looptest::error_code_of(ack);
    return false;
  }
  if (!s->send(list_maps_frame(2))) return false;
  RawFrame list = read_frame(*s);
  if (!list.ok || list.header.type != proto::MessageType::map_list) return false;
  if (keep) *keep = std::move(s);
  return true;
}

// 16 addresses in 16 /24s, each within its pending budget (4), reopen Hello-only
// connections every 600 ms (younger than the 1 s grace): 64 would-be pending, 4x the
// global pending budget and more than max_connections. Honest clients still get in, every
// one of them, because past the global budget the grace no longer shields the flood.
TEST(ServerFairness, PendingChurnFromManyNetworksCannotLockHonestClientsOut) {
  const auto pack = looptest::build_pack("fair_churn", 8, 5, looptest::first_encoding(), 4, 4096);
  server::ServerOptions so;
  so.max_connections = 40;  // fewer than the flood's 64: it holds the server full
  so.max_pending_connections = 16;
  so.max_pending_per_address = 4;
  so.max_pending_per_prefix = 8;
  so.pending_grace = 1000ms;
  looptest::TestServer srv = looptest::start_server({pack.path}, so);
  std::atomic<bool> stop{false};
  std::atomic<uint64_t> flood_connects{0};
  std::vector<std::thread> flood;
  std::vector<std::string> sources;
  for (int a = 0; a < 16; ++a) sources.push_back("127.0." + std::to_string(40 + a) + ".2");
  for (int a = 0; a < 16; ++a)
    for (int k = 0; k < 4; ++k)
      flood.emplace_back([&, a, k] {
        std::this_thread::sleep_for(std::chrono::milliseconds(37 * (4 * a + k) % 600));  // spread, as a real churn is
        const auto end = std::chrono::steady_clock::now() + 8s;  // bounded even if the test fails early
        while (!stop && std::chrono::steady_clock::now() < end) {
          try {
            RawSocket s(srv.port, 1s, sources[size_t(a)].c_str());
            s.send(looptest::hello_frame(1));
            ++flood_connects;
            std::this_thread::sleep_for(600ms);
          } catch (const std::exception&) {  // a refused connect: try again shortly
            std::this_thread::sleep_for(10ms);
          }
        }
      });
  std::this_thread::sleep_for(1200ms);  // the flood at full strength
  int served = 0;
  const int probes = 20;
  for (int i = 0; i < probes; ++i) {
    served += handshake_and_list(srv.port, "127.0.0.1");
    std::this_thread::sleep_for(20ms);
  }
  stop = true;
  for (auto& t : flood) t.join();
  const auto st = srv.server->stats();
  srv.stop();
  EXPECT_EQ(served, probes) << "flood connects " << flood_connects.load() << ", evicted " << st.connections_evicted
                            << ", rejected " << st.connections_rejected;
  EXPECT_GT(st.connections_evicted, 0u);
  EXPECT_GT(flood_connects.load(), 100u);  // the flood did churn
}

// Three networks fill max_connections with useful-looking idle connections (ListMaps,
// then nothing). A newcomer from a fourth network gets in at the expense of the longest
// idle connection of a network holding the most; a newcomer from one of the three (as
// heavy as any other) is still refused: the three keep an even share, not the server.
TEST(ServerFairness, UsefulIdleConnectionsOfAFewNetworksGiveWayToAnotherNetwork) {
  const auto pack = looptest::build_pack("fair_useful", 8, 6, looptest::first_encoding(), 4, 4096);
  server::ServerOptions so;
  so.max_connections = 12;
  looptest::TestServer srv = looptest::start_server({pack.path}, so);
  const char* nets[] = {"127.0.61.2", "127.0.62.2", "127.0.63.2"};
  std::vector<std::unique_ptr<RawSocket>> held;
  for (int n = 0; n < 3; ++n)
    for (int k = 0; k < 4; ++k) {
      std::unique_ptr<RawSocket> s;
      ASSERT_TRUE(handshake_and_list(srv.port, nets[n], &s)) << nets[n] << " #" << k;
      held.push_back(std::move(s));
      std::this_thread::sleep_for(5ms);  // distinct idle times: the first is the idlest
    }
  ASSERT_TRUE(looptest::wait_until([&] { return srv.server->stats().connections_open == 12; }, 5s));
  std::unique_ptr<RawSocket> newcomer;
  EXPECT_TRUE(handshake_and_list(srv.port, "127.0.64.2", &newcomer));
  EXPECT_EQ(srv.server->stats().connections_evicted, 1u);
  EXPECT_TRUE(held[0]->wait_closed()) << "the longest-idle connection of a heaviest network goes";
  // Now 127.0.61.2 holds 3, the others 4 and 4, the newcomer's network 1: a newcomer from
  // one of the heavy networks gains nothing over them and is refused.
  proto::ErrorCode refused = proto::ErrorCode::ok;
  EXPECT_FALSE(handshake_and_list(srv.port, "127.0.62.2", nullptr, &refused));
  EXPECT_EQ(refused, proto::ErrorCode::overloaded);
  srv.stop();
}

}  // namespace
}  // namespace st::client

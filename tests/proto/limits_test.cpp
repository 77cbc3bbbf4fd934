// Limits, the in-flight tracker and the handshake (limits.hpp, handshake.hpp).
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "proto/proto.hpp"

namespace st::proto {
namespace {

TEST(InFlight, RefusesBeyondCapacityDuplicatesAndIdZero) {
  InFlight f(3);
  EXPECT_EQ(f.begin(0).code, ErrorCode::invalid_field);
  EXPECT_TRUE(f.begin(10));
  EXPECT_EQ(f.begin(10).code, ErrorCode::duplicate_request_id);
  EXPECT_TRUE(f.begin(7));
  EXPECT_TRUE(f.begin(12));
  EXPECT_TRUE(f.full());
  EXPECT_EQ(f.begin(13).code, ErrorCode::too_many_in_flight);
  EXPECT_FALSE(f.end(99));
  EXPECT_TRUE(f.end(7));
  EXPECT_FALSE(f.end(7));
  EXPECT_TRUE(f.begin(13));
  EXPECT_TRUE(f.contains(13));
  EXPECT_FALSE(f.contains(7));
  EXPECT_EQ(f.size(), 3u);
}

TEST(InFlight, MatchesAReferenceSetUnderRandomTraffic) {
  std::mt19937_64 rng(11);
  InFlight f(16);
  std::set<std::uint32_t> ref;
  for (int i = 0; i < 20000; ++i) {
    const std::uint32_t id = static_cast<std::uint32_t>(rng() % 40);
    if (rng() & 1) {
      const bool expect_ok = id != 0 && !ref.count(id) && ref.size() < 16;
      ASSERT_EQ(f.begin(id).ok(), expect_ok) << i;
      if (expect_ok) ref.insert(id);
    } else {
      ASSERT_EQ(f.end(id), ref.erase(id) == 1) << i;
    }
    ASSERT_EQ(f.size(), ref.size());
  }
}

TEST(InFlight, LoweredCapacityKeepsExistingIds) {
  InFlight f(4);
  for (std::uint32_t id = 1; id <= 4; ++id) ASSERT_TRUE(f.begin(id));
  f.set_capacity(2);
  EXPECT_EQ(f.begin(5).code, ErrorCode::too_many_in_flight);
  EXPECT_TRUE(f.end(1));
  EXPECT_TRUE(f.end(2));
  EXPECT_EQ(f.begin(5).code, ErrorCode::too_many_in_flight);
  EXPECT_TRUE(f.end(3));
  EXPECT_TRUE(f.begin(5));
}

TEST(Limits, DefaultsAreValidAndBoundsAreEnforced) {
  EXPECT_TRUE(validate(Limits{}));
  Limits l;
  l.max_frame_bytes = kMinFrameBytes - 1;
  EXPECT_EQ(validate(l).code, ErrorCode::invalid_field);
  l = {};
  l.min_version = 2;
  l.max_version = 1;
  EXPECT_EQ(validate(l).code, ErrorCode::invalid_field);
  EXPECT_EQ(choose_version(1, 3, 2, 5), 3);
  EXPECT_EQ(choose_version(1, 1, 2, 5), 0);
  EXPECT_EQ(choose_version(4, 9, 1, 5), 5);
}

TEST(Handshake, LimitsBeforeTheAckAreVersionOneMinimumFramesAndTheRestOfOurOwn) {
  Limits local;
  local.max_frame_bytes = 8 << 20;
  local.max_in_flight = 12;
  local.max_tiles_per_batch = 99;
  local.min_version = 1;
  local.max_version = 3;
  const Limits h = handshake_limits(local);
  EXPECT_EQ(h.max_frame_bytes, kMinFrameBytes);
  EXPECT_EQ(h.min_version, kHandshakeVersion);
  EXPECT_EQ(h.max_version, kHandshakeVersion);
  EXPECT_EQ(h.max_in_flight, 12);
  EXPECT_EQ(h.max_tiles_per_batch, 99);
  EXPECT_TRUE(validate(h));
}

TEST(Handshake, NegotiatesTheSmallerLimitsAndTheHighestCommonVersion) {
  Limits client;
  client.max_frame_bytes = 1 << 20;
  client.max_in_flight = 8;
  client.max_tiles_per_batch = 512;
  Limits server;
  server.max_frame_bytes = 8 << 20;
  server.max_in_flight = 32;
  server.max_tiles_per_batch = 128;
  const Hello hello = make_hello(client, "viewer 1.0", 1, 3);
  std::array<std::uint8_t, kNonceBytes> nonce{};
  nonce.fill(0x5a);
  HelloAck ack;
  Limits on_server;
  ASSERT_TRUE(accept_hello(hello, server, nonce, "shadowtile-server", ack, on_server, 1, 2));
  EXPECT_EQ(ack.version, 2);
  EXPECT_EQ(ack.nonce, nonce);
  EXPECT_EQ(on_server.max_frame_bytes, 1u << 20);
  EXPECT_EQ(on_server.max_in_flight, 8);
  EXPECT_EQ(on_server.max_tiles_per_batch, 128);
  EXPECT_EQ(on_server.min_version, 2);
  EXPECT_EQ(on_server.max_version, 2);
  Limits on_client;
  ASSERT_TRUE(check_hello_ack(hello, ack, on_client));
  EXPECT_EQ(on_client.max_frame_bytes, on_server.max_frame_bytes);
  EXPECT_EQ(on_client.max_in_flight, on_server.max_in_flight);
  EXPECT_EQ(on_client.max_tiles_per_batch, on_server.max_tiles_per_batch);
  EXPECT_EQ(on_client.min_version, 2);

  // Through the wire: frames round trip with version-1 headers.
  std::vector<std::uint8_t> bytes;
  ASSERT_TRUE(encode_message(hello, 1, 0, Limits{}, bytes, kHandshakeVersion));
  FrameParser server_parser(Limits{}, Receiver::server);
  ASSERT_EQ(server_parser.feed(bytes).state, FrameParser::State::frame);
  Message m;
  ASSERT_TRUE(decode_message(server_parser.take_frame(), Limits{}, m));
  EXPECT_EQ(std::get<Hello>(m), hello);
}

TEST(Handshake, DisjointVersionsAndRaisedLimitsAreRefused) {
  const Hello hello = make_hello(Limits{}, "c", 3, 4);
  HelloAck ack;
  Limits n;
  const Status s = accept_hello(hello, Limits{}, {}, "s", ack, n, 1, 2);
  EXPECT_EQ(s.code, ErrorCode::unsupported_version);
  EXPECT_NE(s.detail.find("[3, 4]"), std::string::npos) << s.detail;

  const Hello h1 = make_hello(Limits{}, "c");
  HelloAck bad;
  bad.max_in_flight = h1.max_in_flight + 1;
  EXPECT_EQ(check_hello_ack(h1, bad, n).code, ErrorCode::invalid_field);
  bad = HelloAck{};
  bad.version = 2;
  EXPECT_EQ(check_hello_ack(h1, bad, n).code, ErrorCode::unsupported_version);
  bad = HelloAck{};
  bad.features = 1;
  EXPECT_EQ(check_hello_ack(h1, bad, n).code, ErrorCode::invalid_field);
}

}  // namespace
}  // namespace st::proto

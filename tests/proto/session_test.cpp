// A whole conversation in memory, the way the server and client are meant to use proto
// (PROTOCOL.md §5, §7, §10): handshake, pipelined GetTiles answered out of order with
// gathered TileData writes, a Cancel, in-flight accounting on both sides.
#include <gtest/gtest.h>

#include <map>

#include "proto/proto.hpp"

namespace st::proto {
namespace {

using Bytes = std::vector<std::uint8_t>;

// Feeds `wire` to `parser` and returns the decoded messages with their headers.
std::vector<std::pair<FrameHeader, Message>> receive(FrameParser& parser, const Bytes& wire) {
  std::vector<std::pair<FrameHeader, Message>> got;
  std::span<const std::uint8_t> rest(wire);
  while (!rest.empty()) {
    const auto r = parser.feed(rest);
    rest = rest.subspan(r.consumed);
    EXPECT_NE(r.state, FrameParser::State::error) << to_string(parser.status());
    if (r.state != FrameParser::State::frame) break;
    Frame f = parser.take_frame();
    Message m;
    const Status s = decode_message(f, parser.limits(), m);
    EXPECT_TRUE(s) << to_string(s);
    got.emplace_back(f.header, std::move(m));
  }
  return got;
}

Bytes tile_bytes(std::uint64_t id) {
  Bytes b(100 + id % 50);
  for (std::size_t i = 0; i < b.size(); ++i) b[i] = static_cast<std::uint8_t>(id * 31 + i);
  return b;
}

TEST(Session, HandshakePipelinedTilesOutOfOrderAndCancel) {
  Limits client_local;
  client_local.max_in_flight = 2;
  Limits server_local;
  server_local.max_frame_bytes = 1 << 20;
  FrameParser client_rx(Limits{}, Receiver::client);
  FrameParser server_rx(Limits{}, Receiver::server);
  InFlight client_flight(client_local.max_in_flight);

  // Handshake (header version 1).
  const Hello hello = make_hello(client_local, "session-test");
  Bytes c2s, s2c;
  ASSERT_TRUE(client_flight.begin(1));
  ASSERT_TRUE(encode_message(hello, 1, 0, Limits{}, c2s));
  auto at_server = receive(server_rx, c2s);
  ASSERT_EQ(at_server.size(), 1u);
  HelloAck ack;
  Limits server_negotiated;
  ASSERT_TRUE(accept_hello(std::get<Hello>(at_server[0].second), server_local, {}, "srv", ack,
                           server_negotiated));
  ASSERT_TRUE(encode_message(ack, at_server[0].first.request_id, kFlagFinal, Limits{}, s2c));
  auto at_client = receive(client_rx, s2c);
  ASSERT_EQ(at_client.size(), 1u);
  ASSERT_TRUE(at_client[0].first.final());
  EXPECT_TRUE(client_flight.end(at_client[0].first.request_id));
  Limits client_negotiated;
  ASSERT_TRUE(check_hello_ack(hello, std::get<HelloAck>(at_client[0].second), client_negotiated));
  client_rx.set_limits(client_negotiated);
  server_rx.set_limits(server_negotiated);
  EXPECT_EQ(client_negotiated.max_in_flight, 2);
  EXPECT_EQ(server_negotiated.max_frame_bytes, 1u << 20);  // the smaller: the server's

  // Two pipelined GetTiles; a third is refused by the client's own tracker.
  c2s.clear();
  GetTiles a{7, {{10, 5}, {11, 1}, {12, 9}}};
  GetTiles b{7, {{20, 3}}};
  ASSERT_TRUE(client_flight.begin(2));
  ASSERT_TRUE(encode_message(a, 2, 0, client_negotiated, c2s));
  ASSERT_TRUE(client_flight.begin(3));
  ASSERT_TRUE(encode_message(b, 3, 0, client_negotiated, c2s));
  EXPECT_EQ(client_flight.begin(4).code, ErrorCode::too_many_in_flight);
  Cancel cancel{{}, 7, {11}};
  ASSERT_TRUE(encode_message(cancel, kNoRequest, 0, client_negotiated, c2s));

  // Server: track requests, honour the cancel, answer the urgent request first and the
  // tiles of request 2 by priority, FINAL on each request's last answer.
  at_server = receive(server_rx, c2s);
  ASSERT_EQ(at_server.size(), 3u);
  InFlight server_flight(server_negotiated.max_in_flight);
  for (int i = 0; i < 2; ++i) ASSERT_TRUE(server_flight.begin(at_server[i].first.request_id));
  const auto& cancelled = std::get<Cancel>(at_server[2].second).tile_ids;
  s2c.clear();
  auto send_tile = [&](std::uint32_t req, std::uint64_t id, bool final) {
    if (std::find(cancelled.begin(), cancelled.end(), id) != cancelled.end()) {
      ASSERT_TRUE(encode_message(TileError{id, 7, ErrorCode::cancelled, "cancelled"}, req,
                                 final ? kFlagFinal : 0, server_negotiated, s2c));
    } else {
      const Bytes t = tile_bytes(id);
      TileMeta meta{id, 7, kTileFlagZlib, 4096, crc32(t)};
      std::array<std::uint8_t, kTileDataPrefixBytes> prefix;
      ASSERT_TRUE(encode_tile_data_prefix(meta, t, req, final ? kFlagFinal : 0,
                                          server_negotiated, prefix));
      s2c.insert(s2c.end(), prefix.begin(), prefix.end());  // gathered write: prefix,
      s2c.insert(s2c.end(), t.begin(), t.end());            // then the pack's bytes
    }
    if (final) {
      EXPECT_TRUE(server_flight.end(req));
    }
  };
  send_tile(3, 20, true);
  send_tile(2, 12, false);
  send_tile(2, 11, false);
  send_tile(2, 10, true);
  EXPECT_EQ(server_flight.size(), 0u);

  // Client: answers arrive out of request order; verify each tile end to end.
  at_client = receive(client_rx, s2c);
  ASSERT_EQ(at_client.size(), 4u);
  std::map<std::uint64_t, bool> delivered;
  for (const auto& [header, msg] : at_client) {
    if (const auto* td = std::get_if<TileData>(&msg)) {
      EXPECT_TRUE(tile_crc_matches(td->meta, td->payload));
      EXPECT_EQ(td->payload, tile_bytes(td->meta.tile_id));
      delivered[td->meta.tile_id] = true;
    } else {
      const auto& te = std::get<TileError>(msg);
      EXPECT_EQ(te.code, ErrorCode::cancelled);
      delivered[te.tile_id] = false;
    }
    if (header.final()) {
      EXPECT_TRUE(client_flight.end(header.request_id));
    }
  }
  EXPECT_EQ(at_client[0].first.request_id, 3u);
  EXPECT_EQ(client_flight.size(), 0u);
  EXPECT_EQ(delivered, (std::map<std::uint64_t, bool>{{10, true}, {11, false}, {12, true},
                                                       {20, true}}));
}

TEST(Session, ServerParserRefusesAnOversizedFrameFromTheNegotiatedLimits) {
  // The server accepted 1 MiB frames locally but the client offered 64 KiB: the client's
  // parser must refuse a 100 KiB TileData, and the server's encoder never produces one.
  Limits negotiated;
  negotiated.max_frame_bytes = kMinFrameBytes;
  const Bytes t(100 * 1024, 1);
  TileMeta meta{1, 7, kTileFlagZlib, 1, crc32(t)};
  std::array<std::uint8_t, kTileDataPrefixBytes> prefix;
  EXPECT_EQ(encode_tile_data_prefix(meta, t, 1, kFlagFinal, negotiated, prefix).code,
            ErrorCode::tile_too_large);
  Limits big;
  big.max_frame_bytes = 1 << 20;
  ASSERT_TRUE(encode_tile_data_prefix(meta, t, 1, kFlagFinal, big, prefix));
  FrameParser client_rx(negotiated, Receiver::client);
  const auto r = client_rx.feed(prefix);
  EXPECT_EQ(r.state, FrameParser::State::error);
  EXPECT_EQ(client_rx.status().code, ErrorCode::oversized_frame);
}

}  // namespace
}  // namespace st::proto

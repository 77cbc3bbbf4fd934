// Access control over loopback (PROTOCOL.md §11, proto/auth.hpp): a server with a catalog
// key serves a client holding the key bit-exactly, and refuses everyone else clearly,
// without revealing which maps exist; a recorded proof is useless on another connection;
// a client holding a key refuses a server that cannot prove it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <thread>

#include "client/map_access.hpp"
#include "proto/proto.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace auth_loopback_test {

using namespace std::chrono_literals;
using looptest::build_pack;
using looptest::error_code_of;
using looptest::RawFrame;
using looptest::RawSocket;
using looptest::read_frame;
using looptest::start_server;
using looptest::wait_until;

const std::vector<uint8_t> kKey = proto::parse_key("5a3f0c9e81d2b7a4e6f1c3d5a7b9e0f2", "test key");

ClientOptions options_with(std::vector<uint8_t> key) {
  ClientOptions o = looptest::quick_options();
  o.key = std::move(key);
  return o;
}

server::ServerOptions keyed() {
  server::ServerOptions o;
  o.key = kKey;
  return o;
}

// Calls `f`, expects st::Error containing `what`, and that it came fast (a clear
// refusal, not a request timeout).
template <class F>
void expect_refused(F&& f, const std::string& what) {
  const auto t0 = std::chrono::steady_clock::now();
  try {
    f();
    ADD_FAILURE() << "no error; expected one containing '" << what << "'";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 10s);
}

std::vector<uint8_t> hello_frame(uint32_t features) {
  proto::Limits l;
  l.max_frame_bytes = proto::kMinFrameBytes;
  proto::Hello h = proto::make_hello(proto::Limits{}, "raw");
  h.features = features;
  std::vector<uint8_t> out;
  ST_CHECK(proto::encode_message(h, 1, proto::kFlagFinal, l, out));
  return out;
}

std::vector<uint8_t> frame_of(const proto::Message& m, uint32_t id) {
  std::vector<uint8_t> out;
  ST_CHECK(proto::encode_message(m, id, proto::kFlagFinal, proto::Limits{}, out));
  return out;
}

bool contains(const std::vector<uint8_t>& hay, const std::string& needle) {
  return std::search(hay.begin(), hay.end(), needle.begin(), needle.end()) != hay.end();
}

TEST(AuthLoopback, TheKeyHolderIsServedBitExactly) {
  auto p = build_pack("secretmap", 6, 11, looptest::available_encodings()[0], 3, 1024);
  auto srv = start_server({p.path}, keyed());
  Client c({"127.0.0.1", srv.port}, options_with(kKey));
  auto maps = c.list_maps();
  ASSERT_EQ(maps.size(), 1u);
  EXPECT_EQ(maps[0].name, "secretmap");
  Map m = c.open("secretmap");
  m.request_region(6, 0, 0, 64, 64, 1);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(6, 0, 0, 64, 64); }));
  PackEvaluator local(p.reader);
  for (uint32_t level = 0; level <= 6; ++level)
    for (uint64_t y = 0; y < (1u << level); ++y)
      for (uint64_t x = 0; x < (1u << level); ++x) {
        const float a = m.depth(level, x, y), b = local.depth(level, x, y);
        ASSERT_EQ(std::memcmp(&a, &b, sizeof a), 0) << level << " " << x << " " << y;
      }
  EXPECT_FALSE(c.stats().refused);
}

TEST(AuthLoopback, NoKeyOrAWrongKeyIsRefusedClearly) {
  auto p = build_pack("secretmap", 5, 12, looptest::available_encodings()[0], 2, 1024);
  auto srv = start_server({p.path}, keyed());
  {
    Client none({"127.0.0.1", srv.port}, options_with({}));
    expect_refused([&] { none.open("secretmap"); }, "auth_required");
    expect_refused([&] { none.list_maps(); }, "auth_required");
    EXPECT_TRUE(none.stats().refused);
  }
  {
    auto wrong = kKey;
    wrong[3] ^= 1;
    Client bad({"127.0.0.1", srv.port}, options_with(wrong));
    expect_refused([&] { bad.open("secretmap"); }, "auth_failed: wrong key");
    expect_refused([&] { bad.server_stats(); }, "refused the key");
  }
  EXPECT_GE(srv.server->stats().auth_failures, 2u);
  // The refused clients stopped reconnecting: only the two refused attempts were made.
  std::this_thread::sleep_for(300ms);
  EXPECT_LE(srv.server->stats().connections_total, 2u);
}

TEST(AuthLoopback, NothingIsRevealedBeforeTheProof) {
  auto p = build_pack("secretmap", 5, 13, looptest::available_encodings()[0], 2, 1024);
  auto srv = start_server({p.path}, keyed());
  {  // A Hello without the auth feature: auth_required, closed.
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello_frame(0)));
    RawFrame f = read_frame(s);
    ASSERT_TRUE(f.ok);
    EXPECT_EQ(f.header.type, proto::MessageType::error);
    EXPECT_EQ(error_code_of(f), proto::ErrorCode::auth_required);
    EXPECT_TRUE(s.wait_closed());
  }
  for (const proto::Message& early :
       {proto::Message(proto::ListMaps{}), proto::Message(proto::OpenMap{"secretmap"}),
        proto::Message(proto::GetStats{}), proto::Message(proto::Ping{1})}) {
    RawSocket s(srv.port);
    ASSERT_TRUE(s.send(hello_frame(proto::kFeatureAuth)));
    RawFrame ack = read_frame(s);
    ASSERT_TRUE(ack.ok);
    ASSERT_EQ(ack.header.type, proto::MessageType::hello_ack);
    proto::HelloAck a;
    proto::Limits big;
    big.max_frame_bytes = proto::kMaxFrameBytesCeiling;
    ASSERT_TRUE(proto::decode_payload(ack.payload, big, a));
    EXPECT_EQ(a.features & proto::kFeatureAuth, proto::kFeatureAuth);
    EXPECT_NE(a.nonce, proto::Nonce{});  // a real challenge
    ASSERT_TRUE(s.send(frame_of(early, 2)));
    RawFrame f = read_frame(s);
    ASSERT_TRUE(f.ok);
    EXPECT_EQ(error_code_of(f), proto::ErrorCode::auth_required);
    EXPECT_FALSE(contains(f.payload, "secretmap"));
    EXPECT_TRUE(s.wait_closed());
  }
}

TEST(AuthLoopback, ARecordedProofFailsOnAnotherConnection) {
  auto p = build_pack("secretmap", 5, 14, looptest::available_encodings()[0], 2, 1024);
  auto srv = start_server({p.path}, keyed());
  proto::Limits big;
  big.max_frame_bytes = proto::kMaxFrameBytesCeiling;
  auto challenge = [&](RawSocket& s) {
    EXPECT_TRUE(s.send(hello_frame(proto::kFeatureAuth)));
    RawFrame ack = read_frame(s);
    proto::HelloAck a;
    EXPECT_TRUE(ack.ok && proto::decode_payload(ack.payload, big, a));
    return a.nonce;
  };
  proto::Auth recorded;
  {  // An honest exchange, recorded by an eavesdropper.
    RawSocket s(srv.port);
    const proto::Nonce ns = challenge(s);
    recorded.client_nonce = proto::random_nonce();
    recorded.proof = proto::client_proof(kKey, ns, recorded.client_nonce);
    ASSERT_TRUE(s.send(frame_of(recorded, 2)));
    RawFrame f = read_frame(s);
    ASSERT_TRUE(f.ok);
    ASSERT_EQ(f.header.type, proto::MessageType::auth_ok);
    proto::AuthOk ok;
    ASSERT_TRUE(proto::decode_payload(f.payload, big, ok));
    EXPECT_TRUE(proto::proofs_equal(ok.proof, proto::server_proof(kKey, ns, recorded.client_nonce)));
    ASSERT_TRUE(s.send(frame_of(proto::ListMaps{}, 3)));
    RawFrame list = read_frame(s);
    ASSERT_TRUE(list.ok);
    EXPECT_EQ(list.header.type, proto::MessageType::map_list);
    EXPECT_TRUE(contains(list.payload, "secretmap"));
  }
  {  // The replay: a fresh server nonce makes the old proof wrong.
    RawSocket s(srv.port);
    (void)challenge(s);
    ASSERT_TRUE(s.send(frame_of(recorded, 2)));
    RawFrame f = read_frame(s);
    ASSERT_TRUE(f.ok);
    EXPECT_EQ(error_code_of(f), proto::ErrorCode::auth_failed);
    EXPECT_TRUE(s.wait_closed());
  }
}

TEST(AuthLoopback, AKeyHolderRefusesAServerThatCannotProveTheKey) {
  auto p = build_pack("openmap", 5, 15, looptest::available_encodings()[0], 2, 1024);
  {  // No key on the server: it does not ask, so it cannot be the one the key is for.
    auto srv = start_server({p.path});
    Client c({"127.0.0.1", srv.port}, options_with(kKey));
    expect_refused([&] { c.open("openmap"); }, "does not ask for the key");
  }
  {  // Another key on the server: the client's proof fails there first.
    server::ServerOptions o;
    o.key = std::vector<uint8_t>(32, 7);
    auto srv = start_server({p.path}, o);
    Client c({"127.0.0.1", srv.port}, options_with(kKey));
    expect_refused([&] { c.open("openmap"); }, "wrong key");
  }
}

}  // namespace auth_loopback_test
}  // namespace st::client

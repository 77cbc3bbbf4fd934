// Access control primitives (proto/auth.hpp, PROTOCOL.md §11): HMAC-SHA256 against the
// RFC 4231 vectors, proofs bound to both nonces and to their direction, key parsing, and
// the Auth / AuthOk layouts.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "proto/proto.hpp"
#include "common/error.hpp"

namespace st::proto {
namespace {

std::string hex(std::span<const std::uint8_t> b) {
  static const char* d = "0123456789abcdef";
  std::string s;
  for (auto x : b) {
    s += d[x >> 4];
    s += d[x & 15];
  }
  return s;
}

std::vector<std::uint8_t> bytes(std::string_view s) { return {s.begin(), s.end()}; }

TEST(Auth, HmacSha256MatchesRfc4231) {
  // Test case 1: key 0x0b x 20, "Hi There".
  EXPECT_EQ(hex(hmac_sha256(std::vector<std::uint8_t>(20, 0x0b), bytes("Hi There"))),
            "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7");
  // Test case 2: key "Jefe".
  EXPECT_EQ(hex(hmac_sha256(bytes("Jefe"), bytes("what do ya want for nothing?"))),
            "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843");
  // Test case 6: a key longer than the block size.
  EXPECT_EQ(hex(hmac_sha256(std::vector<std::uint8_t>(131, 0xaa),
                            bytes("Test Using Larger Than Block-Size Key - Hash Key First"))),
            "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54");
}

TEST(Auth, ProofsDependOnKeyBothNoncesAndDirection) {
  std::mt19937_64 rng(7);
  auto random = [&] {
    Nonce n;
    for (auto& b : n) b = std::uint8_t(rng());
    return n;
  };
  const std::vector<std::uint8_t> key(32, 0x42), other(32, 0x43);
  for (int i = 0; i < 50; ++i) {
    const Nonce ns = random(), nc = random();
    const Proof p = client_proof(key, ns, nc);
    EXPECT_TRUE(proofs_equal(p, client_proof(key, ns, nc)));
    EXPECT_FALSE(proofs_equal(p, client_proof(other, ns, nc)));
    EXPECT_FALSE(proofs_equal(p, client_proof(key, random(), nc)));  // another connection
    EXPECT_FALSE(proofs_equal(p, client_proof(key, ns, random())));
    EXPECT_FALSE(proofs_equal(p, client_proof(key, nc, ns)));        // nonces swapped
    EXPECT_FALSE(proofs_equal(p, server_proof(key, ns, nc)));        // the other direction
    Proof q = p;
    q[std::size_t(rng() % q.size())] ^= std::uint8_t(1u << (rng() % 8));
    EXPECT_FALSE(proofs_equal(p, q));
  }
  EXPECT_FALSE(proofs_equal(random_nonce(), random_nonce()));  // 256 random bits each time
}

TEST(Auth, KeysParseAsHexOrRawAndBadKeysNameTheProblem) {
  EXPECT_EQ(parse_key("00112233445566778899aabbccddeeff\n", "k"),
            (std::vector<std::uint8_t>{0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88, 0x99,
                                       0xaa, 0xbb, 0xcc, 0xdd, 0xee, 0xff}));
  EXPECT_EQ(parse_key("a long passphrase, not hex\n", "k"), bytes("a long passphrase, not hex"));
  try {
    parse_key("abcdef", "key file 'x'");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("key file 'x': key of 3 bytes; at least 16"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(parse_key(std::string(5000, 'z'), "k"), Error);
  EXPECT_THROW(load_key_file("/nonexistent/shadowtile.key"), Error);
  const auto path = std::filesystem::path(SHADOWTILE_TEST_TMP) / "auth.key";
  std::ofstream(path) << "  0123456789abcdef 0123456789abcdef\n";
  EXPECT_EQ(load_key_file(path.string()).size(), 16u);
}

// The key-file rules PROTOCOL.md §11 states, edge by edge.
TEST(Auth, KeyFileIsHexWhenEveryNonSpaceCharacterIsAHexDigitElseRaw) {
  // Hex: whitespace anywhere is ignored, either case, an even number of digits.
  EXPECT_EQ(parse_key("00112233 44556677\n8899AABB\tccddeeff\r\n", "k"),
            parse_key("00112233445566778899aabbccddeeff", "k"));
  EXPECT_EQ(parse_key("00112233445566778899aabbccddeeff", "k").size(), 16u);
  // An odd number of hex digits is not hex: the 33 characters are the key.
  EXPECT_EQ(parse_key("0123456789abcdef0123456789abcdef0\n", "k"),
            bytes("0123456789abcdef0123456789abcdef0"));
  // Raw: the bytes as they are, only trailing CR/LF dropped (leading and inner spaces,
  // trailing spaces, stay).
  EXPECT_EQ(parse_key("  pass phrase, 16+ bytes \r\n\n", "k"), bytes("  pass phrase, 16+ bytes "));
  // The bounds apply to the decoded key: 16..1024 bytes.
  EXPECT_THROW(parse_key("00112233445566778899aabbccddee", "k"), Error);  // 15 bytes of hex
  EXPECT_EQ(parse_key(std::string(2048, 'a'), "k").size(), 1024u);         // 1024 bytes of hex
  EXPECT_THROW(parse_key(std::string(1025, 'z'), "k"), Error);
}

TEST(Auth, AuthAndAuthOkLayoutsArePinned) {
  Auth a;
  for (std::size_t i = 0; i < kNonceBytes; ++i) a.client_nonce[i] = std::uint8_t(i);
  for (std::size_t i = 0; i < kProofBytes; ++i) a.proof[i] = std::uint8_t(0x80 + i);
  std::vector<std::uint8_t> out;
  ASSERT_TRUE(encode_payload(a, Limits{}, out));
  ASSERT_EQ(out.size(), 64u);
  EXPECT_EQ(out[0], 0);
  EXPECT_EQ(out[31], 31);
  EXPECT_EQ(out[32], 0x80);
  EXPECT_EQ(out[63], 0x80 + 31);
  Auth back;
  ASSERT_TRUE(decode_payload(out, Limits{}, back));
  EXPECT_EQ(back, a);
  out.pop_back();
  EXPECT_EQ(decode_payload(out, Limits{}, back).code, ErrorCode::truncated);
  AuthOk ok;
  ok.proof[5] = 9;
  out.clear();
  ASSERT_TRUE(encode_payload(ok, Limits{}, out));
  ASSERT_EQ(out.size(), 32u);
  out.push_back(0);
  EXPECT_EQ(decode_payload(out, Limits{}, ok).code, ErrorCode::trailing_bytes);
  EXPECT_EQ(sender_of(MessageType::auth), Sender::client);
  EXPECT_EQ(sender_of(MessageType::auth_ok), Sender::server);
}

TEST(Auth, ServerRequiresTheFeatureBitAndAdvertisesIt) {
  Hello h = make_hello(Limits{}, "c");
  HelloAck ack;
  EXPECT_EQ(require_auth(h, ack).code, ErrorCode::auth_required);
  h.features |= kFeatureAuth;
  ASSERT_TRUE(require_auth(h, ack));
  EXPECT_EQ(ack.features & kFeatureAuth, kFeatureAuth);
  Limits negotiated;
  EXPECT_TRUE(check_hello_ack(h, ack, negotiated));
  h.features = 0;  // a client that offered nothing refuses an ack with the bit
  EXPECT_FALSE(check_hello_ack(h, ack, negotiated));
}

}  // namespace
}  // namespace st::proto

// HMAC-SHA256 challenge-response (auth.hpp, PROTOCOL.md §11) on OpenSSL's libcrypto.
#include "proto/auth.hpp"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/rand.h>

#include <cctype>
#include <fstream>
#include <iterator>
#include <string_view>

#include "common/error.hpp"

namespace st::proto {

namespace {

constexpr std::string_view kClientLabel = "shadowtile auth v1 client";
constexpr std::string_view kServerLabel = "shadowtile auth v1 server";

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

Proof proof_of(std::span<const std::uint8_t> key, std::string_view label, const Nonce& ns,
               const Nonce& nc) {
  std::vector<std::uint8_t> msg;
  msg.reserve(label.size() + 2 * kNonceBytes);
  msg.insert(msg.end(), label.begin(), label.end());
  msg.insert(msg.end(), ns.begin(), ns.end());
  msg.insert(msg.end(), nc.begin(), nc.end());
  return hmac_sha256(key, msg);
}

}  // namespace

std::vector<std::uint8_t> parse_key(std::string_view text, const std::string& what) {
  std::string digits;
  bool all_hex = true;
  for (char c : text) {
    if (std::isspace(static_cast<unsigned char>(c))) continue;
    if (hex_value(c) < 0) all_hex = false;
    digits += c;
  }
  std::vector<std::uint8_t> key;
  if (all_hex && !digits.empty() && digits.size() % 2 == 0) {
    for (size_t i = 0; i < digits.size(); i += 2)
      key.push_back(std::uint8_t(hex_value(digits[i]) * 16 + hex_value(digits[i + 1])));
  } else {
    std::string_view raw = text;
    while (!raw.empty() && (raw.back() == '\n' || raw.back() == '\r')) raw.remove_suffix(1);
    key.assign(raw.begin(), raw.end());
  }
  if (key.size() < kMinKeyBytes)
    throw Error(what + ": key of " + std::to_string(key.size()) + " bytes; at least " +
                std::to_string(kMinKeyBytes) + " needed (e.g. `openssl rand -hex 32`)");
  if (key.size() > kMaxKeyBytes)
    throw Error(what + ": key of " + std::to_string(key.size()) + " bytes; at most " +
                std::to_string(kMaxKeyBytes));
  return key;
}

std::vector<std::uint8_t> load_key_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw Error("key file '" + path + "': cannot open");
  std::string text;
  char buf[4096];
  while (f.read(buf, sizeof buf) || f.gcount() > 0) {
    text.append(buf, size_t(f.gcount()));
    if (text.size() > 4 * kMaxKeyBytes) throw Error("key file '" + path + "': too large for a key");
  }
  if (f.bad()) throw Error("key file '" + path + "': read error");
  return parse_key(text, "key file '" + path + "'");
}

Nonce random_nonce() {
  Nonce n{};
  if (RAND_bytes(n.data(), int(n.size())) != 1) throw Error("auth: the CSPRNG (RAND_bytes) failed");
  return n;
}

Proof hmac_sha256(std::span<const std::uint8_t> key, std::span<const std::uint8_t> message) {
  Proof out{};
  unsigned len = 0;
  static const std::uint8_t kEmpty = 0;
  if (!HMAC(EVP_sha256(), key.empty() ? &kEmpty : key.data(), int(key.size()),
            message.empty() ? &kEmpty : message.data(), message.size(), out.data(), &len) ||
      len != out.size())
    throw Error("auth: HMAC-SHA256 failed");
  return out;
}

Proof client_proof(std::span<const std::uint8_t> key, const Nonce& server_nonce,
                   const Nonce& client_nonce) {
  return proof_of(key, kClientLabel, server_nonce, client_nonce);
}

Proof server_proof(std::span<const std::uint8_t> key, const Nonce& server_nonce,
                   const Nonce& client_nonce) {
  return proof_of(key, kServerLabel, server_nonce, client_nonce);
}

bool proofs_equal(const Proof& a, const Proof& b) {
  return CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

Status require_auth(const Hello& hello, HelloAck& ack) {
  if (!(hello.features & kFeatureAuth))
    return Status::fail(ErrorCode::auth_required,
                        "this server requires a key; the client offered none");
  ack.features |= kFeatureAuth;
  return {};
}

}  // namespace st::proto

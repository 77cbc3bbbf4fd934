// Access control (PROTOCOL.md §11): a server may require a key per catalog; a client
// proves it knows the key with an HMAC-SHA256 challenge-response over the HelloAck's
// fresh server nonce and its own fresh nonce, and the server proves the same back:
//
//   C: Hello   features |= kFeatureAuth                  (the client holds a key)
//   S: HelloAck features = kFeatureAuth, nonce = Ns      (fresh, CSPRNG)
//   C: Auth    {Nc, HMAC(key, "shadowtile auth v1 client" || Ns || Nc)}
//   S: AuthOk  {HMAC(key, "shadowtile auth v1 server" || Ns || Nc)}   or Error auth_failed
//
// Before AuthOk the server answers every other request with Error auth_required and
// closes, so a client without the key learns nothing about which maps exist. The key
// never crosses the wire; fresh nonces on both sides make a recorded proof useless on
// another connection; proofs are compared in constant time (CRYPTO_memcmp). The label
// separates the two directions so a server proof can never be replayed as a client one.
// Keys are raw bytes, at least kMinKeyBytes (128 bits).
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "proto/messages.hpp"

namespace st::proto {

inline constexpr std::size_t kMinKeyBytes = 16;
inline constexpr std::size_t kMaxKeyBytes = 1024;

using Nonce = std::array<std::uint8_t, kNonceBytes>;
using Proof = std::array<std::uint8_t, kProofBytes>;

// A key file holds the key as hex (64+ hex digits typical, whitespace ignored) or, when it
// is not all hex, as raw bytes (a trailing newline is dropped). Throws st::Error naming
// the file: missing, unreadable, shorter than kMinKeyBytes, longer than kMaxKeyBytes.
std::vector<std::uint8_t> load_key_file(const std::string& path);
// Same rules for a key given as text (hex, or raw bytes). Throws st::Error.
std::vector<std::uint8_t> parse_key(std::string_view text, const std::string& what);

// Fresh random bytes from OpenSSL's CSPRNG (RAND_bytes); throws st::Error if it fails.
Nonce random_nonce();

Proof client_proof(std::span<const std::uint8_t> key, const Nonce& server_nonce,
                   const Nonce& client_nonce);
Proof server_proof(std::span<const std::uint8_t> key, const Nonce& server_nonce,
                   const Nonce& client_nonce);
// Constant-time equality (CRYPTO_memcmp): the time taken says nothing about where the
// first wrong byte is.
bool proofs_equal(const Proof& a, const Proof& b);

// The raw HMAC-SHA256 (exposed for the RFC 4231 test vectors).
Proof hmac_sha256(std::span<const std::uint8_t> key, std::span<const std::uint8_t> message);

// Server side of the handshake: with a key configured, the Hello must offer kFeatureAuth
// (auth_required otherwise, to be sent as an Error before closing); the ack then says so.
Status require_auth(const Hello& hello, HelloAck& ack);

}  // namespace st::proto

// The handshake (PROTOCOL.md §5), as pure functions both peers call:
//
//   client                                   server
//   make_hello(local) ── Hello (v1 header) ──► accept_hello(hello, local) -> ack
//   check_hello_ack ◄── HelloAck (v1 header) ─ (or Error(unsupported_version / invalid_field)
//                                               with request id 0, then close)
//   both: parser.set_limits(negotiated); every later frame uses negotiated.version
//
// The negotiated limits are the smaller of each pair; the version the highest in both
// ranges. A client must verify the server did not raise any limit or leave its range.
#pragma once
#include <array>
#include <string>

#include "proto/limits.hpp"
#include "proto/messages.hpp"

namespace st::proto {

// A Hello proposing `local` limits and the versions [min_version, max_version].
Hello make_hello(const Limits& local, std::string client_name,
                 std::uint8_t min_version = kMinSupportedVersion,
                 std::uint8_t max_version = kMaxSupportedVersion);

// Server side. ok: `ack` is the HelloAck to send (FINAL, the Hello's request id) and
// `negotiated` the limits for the rest of the connection. Failure: unsupported_version
// when the ranges do not meet (the detail says both ranges); send it as an Error and close.
// features: the subset of the Hello's bits this server knows (none in version 1).
Status accept_hello(const Hello& hello, const Limits& local,
                    const std::array<std::uint8_t, kNonceBytes>& nonce,
                    std::string server_name, HelloAck& ack, Limits& negotiated,
                    std::uint8_t min_version = kMinSupportedVersion,
                    std::uint8_t max_version = kMaxSupportedVersion);

// Client side: ok if the ack's version lies in the Hello's range and no limit exceeds
// what the Hello proposed (invalid_field otherwise); then `negotiated` holds the limits.
Status check_hello_ack(const Hello& sent, const HelloAck& ack, Limits& negotiated);

}  // namespace st::proto

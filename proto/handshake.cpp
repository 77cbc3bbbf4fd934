// Handshake negotiation (PROTOCOL.md §5).
#include "proto/handshake.hpp"

#include <string>
#include <utility>

namespace st::proto {

Hello make_hello(const Limits& local, std::string client_name, std::uint8_t min_version,
                 std::uint8_t max_version) {
  Hello h;
  h.min_version = min_version;
  h.max_version = max_version;
  h.max_in_flight = local.max_in_flight;
  h.max_frame_bytes = local.max_frame_bytes;
  h.max_tiles_per_batch = local.max_tiles_per_batch;
  h.client_name = std::move(client_name);
  return h;
}

Status accept_hello(const Hello& hello, const Limits& local,
                    const std::array<std::uint8_t, kNonceBytes>& nonce,
                    std::string server_name, HelloAck& ack, Limits& negotiated,
                    std::uint8_t min_version, std::uint8_t max_version) {
  const std::uint8_t v =
      choose_version(hello.min_version, hello.max_version, min_version, max_version);
  if (v == 0)
    return Status::fail(ErrorCode::unsupported_version,
                        "client speaks versions [" + std::to_string(hello.min_version) + ", " +
                            std::to_string(hello.max_version) + "], server [" +
                            std::to_string(min_version) + ", " + std::to_string(max_version) +
                            "]");
  Limits theirs;
  theirs.max_frame_bytes = hello.max_frame_bytes;
  theirs.max_in_flight = hello.max_in_flight;
  theirs.max_tiles_per_batch = hello.max_tiles_per_batch;
  negotiated = negotiate(local, theirs, v);
  ack = HelloAck{};
  ack.version = v;
  ack.max_in_flight = negotiated.max_in_flight;
  ack.max_frame_bytes = negotiated.max_frame_bytes;
  ack.max_tiles_per_batch = negotiated.max_tiles_per_batch;
  ack.features = 0;  // version 1 defines no feature bits
  ack.nonce = nonce;
  ack.server_name = std::move(server_name);
  return {};
}

Status check_hello_ack(const Hello& sent, const HelloAck& ack, Limits& negotiated) {
  if (ack.version < sent.min_version || ack.version > sent.max_version)
    return Status::fail(ErrorCode::unsupported_version,
                        "hello_ack: version " + std::to_string(ack.version) +
                            " outside the offered [" + std::to_string(sent.min_version) + ", " +
                            std::to_string(sent.max_version) + "]");
  auto raised = [](const char* field, std::uint64_t got, std::uint64_t offered) {
    return Status::fail(ErrorCode::invalid_field, std::string("hello_ack: ") + field + " " +
                                                      std::to_string(got) +
                                                      " exceeds the offered " +
                                                      std::to_string(offered));
  };
  if (ack.max_frame_bytes > sent.max_frame_bytes)
    return raised("max_frame_bytes", ack.max_frame_bytes, sent.max_frame_bytes);
  if (ack.max_in_flight > sent.max_in_flight)
    return raised("max_in_flight", ack.max_in_flight, sent.max_in_flight);
  if (ack.max_tiles_per_batch > sent.max_tiles_per_batch)
    return raised("max_tiles_per_batch", ack.max_tiles_per_batch, sent.max_tiles_per_batch);
  if ((ack.features & ~sent.features) != 0)
    return Status::fail(ErrorCode::invalid_field,
                        "hello_ack: features has bits the client did not offer");
  negotiated = Limits{};
  negotiated.max_frame_bytes = ack.max_frame_bytes;
  negotiated.max_in_flight = ack.max_in_flight;
  negotiated.max_tiles_per_batch = ack.max_tiles_per_batch;
  negotiated.min_version = ack.version;
  negotiated.max_version = ack.version;
  return validate(negotiated);
}

}  // namespace st::proto

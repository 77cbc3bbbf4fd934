// libFuzzer harness for the handshake (proto/handshake.hpp, PROTOCOL.md §5): Hello and
// HelloAck decoding and both sides' negotiation. Input: byte 0 picks the server's local
// limits and version range, byte 1 where the rest splits into a Hello payload (first
// part) and a HelloAck payload (second part).
// Checks, beyond no crash / no sanitizer report:
// - a payload that decodes re-encodes to the same bytes (one canonical form);
// - server: accept_hello on any decoded Hello either fails with unsupported_version or
//   gives valid negotiated limits no larger than either side's, and an ack that encodes,
//   decodes to itself and that check_hello_ack accepts with the same limits;
// - client: check_hello_ack on any decoded HelloAck accepts only valid limits within
//   what the Hello offered and a version inside its range.
#include <span>
#include <stdexcept>

#include "proto/byte_io.hpp"
#include "proto/proto.hpp"
#include "tests/fuzz/seed_support.hpp"

namespace {

using namespace st::proto;

bool same_limits(const Limits& a, const Limits& b) {
  return a.max_frame_bytes == b.max_frame_bytes && a.max_in_flight == b.max_in_flight &&
         a.max_tiles_per_batch == b.max_tiles_per_batch && a.min_version == b.min_version &&
         a.max_version == b.max_version;
}

template <class T>
bool decode_canonical(std::span<const std::uint8_t> payload, T& out) {
  if (!decode_payload(payload, Limits{}, out)) return false;
  std::vector<std::uint8_t> again;
  FUZZ_CHECK(encode_payload(out, Limits{}, again).ok());
  FUZZ_CHECK(std::equal(again.begin(), again.end(), payload.begin(), payload.end()));
  T back;
  FUZZ_CHECK(decode_payload(again, Limits{}, back).ok() && back == out);
  return true;
}

Limits server_limits(std::uint8_t control) {
  Limits l;
  l.max_frame_bytes = (control & 1) ? kMinFrameBytes : kMaxFrameBytesCeiling;
  l.max_in_flight = (control & 2) ? 1 : kMaxInFlightCeiling;
  l.max_tiles_per_batch = (control & 4) ? 1 : 256;
  return l;
}

void check_server_side(const Hello& hello, std::uint8_t control) {
  const Limits local = server_limits(control);
  const std::uint8_t min_v = 1 + ((control >> 3) & 1), max_v = min_v + ((control >> 4) & 1);
  std::array<std::uint8_t, kNonceBytes> nonce{};
  nonce[0] = control;
  HelloAck ack;
  Limits negotiated;
  const Status s = accept_hello(hello, local, nonce, "fuzz-server", ack, negotiated, min_v, max_v);
  if (!s) {
    FUZZ_CHECK(s.code == ErrorCode::unsupported_version);
    return;
  }
  FUZZ_CHECK(validate(negotiated).ok());
  FUZZ_CHECK(negotiated.max_frame_bytes <= hello.max_frame_bytes &&
             negotiated.max_frame_bytes <= local.max_frame_bytes);
  FUZZ_CHECK(negotiated.max_in_flight <= hello.max_in_flight &&
             negotiated.max_in_flight <= local.max_in_flight);
  FUZZ_CHECK(negotiated.max_tiles_per_batch <= hello.max_tiles_per_batch &&
             negotiated.max_tiles_per_batch <= local.max_tiles_per_batch);
  FUZZ_CHECK(ack.version >= hello.min_version && ack.version <= hello.max_version);
  FUZZ_CHECK(ack.version >= min_v && ack.version <= max_v);
  std::vector<std::uint8_t> wire;
  FUZZ_CHECK(encode_payload(ack, Limits{}, wire).ok());
  HelloAck back;
  FUZZ_CHECK(decode_payload(wire, Limits{}, back).ok() && back == ack);
  Limits client_view;
  FUZZ_CHECK(check_hello_ack(hello, back, client_view).ok());
  FUZZ_CHECK(same_limits(client_view, negotiated));
  // The whole frame the server would send fits the pre-handshake limits.
  std::vector<std::uint8_t> frame;
  FUZZ_CHECK(encode_message(Message{ack}, 1, kFlagFinal, Limits{}, frame).ok());
}

void check_client_side(const Hello& sent, const HelloAck& ack) {
  Limits negotiated;
  if (!check_hello_ack(sent, ack, negotiated)) return;
  FUZZ_CHECK(validate(negotiated).ok());
  FUZZ_CHECK(ack.version >= sent.min_version && ack.version <= sent.max_version);
  FUZZ_CHECK(negotiated.max_frame_bytes <= sent.max_frame_bytes);
  FUZZ_CHECK(negotiated.max_in_flight <= sent.max_in_flight);
  FUZZ_CHECK(negotiated.max_tiles_per_batch <= sent.max_tiles_per_batch);
  FUZZ_CHECK(negotiated.min_version == ack.version && negotiated.max_version == ack.version);
  // A parser configured with them accepts nothing of another version.
  FrameParser p(negotiated, Receiver::client);
  FUZZ_CHECK(!p.failed());
}

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  Limits small;
  small.max_frame_bytes = kMinFrameBytes;
  small.max_in_flight = 8;
  small.max_tiles_per_batch = 16;
  int n = 0;
  for (const Limits& client : {Limits{}, small}) {
    for (std::uint8_t max_v : {std::uint8_t(1), std::uint8_t(2)}) {
      const Hello hello = make_hello(client, n % 2 ? "client" : "", 1, max_v);
      HelloAck ack;
      Limits negotiated;
      std::array<std::uint8_t, kNonceBytes> nonce{};
      nonce[5] = std::uint8_t(n);
      if (!accept_hello(hello, server_limits(std::uint8_t(n)), nonce, "srv", ack, negotiated))
        ack = HelloAck{};
      std::vector<std::uint8_t> h, a;
      if (!encode_payload(hello, Limits{}, h) || !encode_payload(ack, Limits{}, a))
        throw std::runtime_error("handshake seed does not encode");
      Bytes seed = {std::uint8_t(n * 37), std::uint8_t(h.size())};
      seed.insert(seed.end(), h.begin(), h.end());
      seed.insert(seed.end(), a.begin(), a.end());
      out.push_back(std::move(seed));
      ++n;
    }
  }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  const std::uint8_t control = data[0];
  const std::vector<std::uint8_t> rest(data + 2, data + size);
  const std::size_t split = std::min<std::size_t>(data[1], rest.size());
  const std::span<const std::uint8_t> hello_bytes(rest.data(), split);
  const std::span<const std::uint8_t> ack_bytes(rest.data() + split, rest.size() - split);

  Hello hello;
  const bool have_hello = decode_canonical(hello_bytes, hello);
  if (have_hello) check_server_side(hello, control);
  HelloAck ack;
  const bool have_ack = decode_canonical(ack_bytes, ack);
  if (have_hello && have_ack) st::fuzz::note_accepted();
  if (have_ack) {
    Limits mine;
    mine.max_frame_bytes = (control & 0x20) ? kMinFrameBytes : Limits{}.max_frame_bytes;
    check_client_side(have_hello ? hello : make_hello(mine, "fuzz-client", 1, 1 + (control >> 7)),
                      ack);
  }
  return 0;
}

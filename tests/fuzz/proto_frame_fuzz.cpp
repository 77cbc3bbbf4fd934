// libFuzzer harness for the proto frame parser and message decoders. Not part of the
// default build (tests/CMakeLists.txt globs only tests/<module>/*_test.cpp). Build and run:
//
//   clang++ -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -I. \
//     tests/fuzz/proto_frame_fuzz.cpp proto/*.cpp -ldeflate -o /tmp/proto_fuzz
//   /tmp/proto_fuzz -max_total_time=60 -max_len=4096
//
// Input: byte 0 picks the chunk size the stream is fed in (bits 0-4), the receiver
// (bits 5-6) and whether to repair the checksums of every frame first (bit 7: without it
// the fuzzer rarely gets past the CRCs into the message decoders); the rest is the stream. Checks, beyond "no crash, no sanitizer report":
// - a chunked feed yields exactly the frames of a whole feed (or the same error);
// - every frame that decodes re-encodes to the same payload bytes (one canonical form);
// - a failed parser stays failed and consumes nothing.
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "proto/byte_io.hpp"
#include "proto/proto.hpp"

namespace {

using namespace st::proto;

struct Outcome {
  std::vector<Frame> frames;
  ErrorCode error = ErrorCode::ok;
};

Outcome run(std::span<const std::uint8_t> stream, std::size_t chunk, Receiver receiver,
            const Limits& limits) {
  Outcome out;
  FrameParser p(limits, receiver);
  while (!stream.empty()) {
    auto piece = stream.first(std::min(chunk, stream.size()));
    const auto r = p.feed(piece);
    if (r.consumed > piece.size()) std::abort();
    stream = stream.subspan(r.consumed);
    if (r.state == FrameParser::State::frame) {
      out.frames.push_back(p.take_frame());
    } else if (r.state == FrameParser::State::error) {
      out.error = p.status().code;
      if (p.feed(stream).consumed != 0) std::abort();
      break;
    } else if (r.consumed != piece.size()) {
      std::abort();
    }
  }
  return out;
}

// Rewrites payload_crc32 and header_crc32 of each frame the stream's length fields
// delimit, so mutated payloads reach the decoders.
void repair_checksums(std::vector<std::uint8_t>& b) {
  std::size_t pos = 0;
  while (pos + kHeaderSize <= b.size()) {
    const std::size_t len = load_le<std::uint32_t>(b.data() + pos + kOffPayloadLength);
    const std::size_t have = std::min(len, b.size() - pos - kHeaderSize);
    store_le<std::uint32_t>(b.data() + pos + kOffPayloadCrc,
                            crc32({b.data() + pos + kHeaderSize, have}));
    store_le<std::uint32_t>(b.data() + pos + kOffHeaderCrc, crc32({b.data() + pos, kOffHeaderCrc}));
    pos += kHeaderSize + have;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::uint8_t control = data[0];
  std::vector<std::uint8_t> bytes(data + 1, data + size);
  if (control & 0x80) repair_checksums(bytes);
  const std::span<const std::uint8_t> stream(bytes);
  const Receiver receiver = static_cast<Receiver>(((control >> 5) & 3) % 3);
  const std::size_t chunk = 1 + (control & 0x1f);
  Limits limits;
  limits.max_frame_bytes = kMinFrameBytes;
  limits.max_tiles_per_batch = 16;
  limits.max_in_flight = 8;

  const Outcome whole = run(stream, stream.size() + 1, receiver, limits);
  const Outcome chunked = run(stream, chunk, receiver, limits);
  if (whole.error != chunked.error || whole.frames.size() != chunked.frames.size()) std::abort();
  for (std::size_t i = 0; i < whole.frames.size(); ++i) {
    if (whole.frames[i].payload != chunked.frames[i].payload) std::abort();
    Message m;
    if (!decode_message(whole.frames[i], limits, m)) continue;
    std::vector<std::uint8_t> again;
    const Status s =
        std::visit([&](const auto& v) { return encode_payload(v, limits, again); }, m);
    if (!s || again != whole.frames[i].payload) std::abort();
  }
  return 0;
}

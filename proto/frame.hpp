// Frames: the 24-byte header of wire_format.hpp + a payload; encoding, and the
// incremental FrameParser a connection feeds with whatever bytes the socket delivered.
//
// The parser follows the Asio http request_parser idea: feed bytes, it answers
// need_more / frame / error. It never trusts a length: payload_length is checked against
// Limits::max_frame_bytes from the header alone (after the header checksum), before a
// payload byte is buffered; the buffer then grows only with the bytes received.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "proto/limits.hpp"
#include "proto/status.hpp"
#include "proto/wire_format.hpp"

namespace st::proto {

struct FrameHeader {
  std::uint8_t version = kVersion1;
  std::uint8_t flags = 0;
  MessageType type = MessageType::ping;
  std::uint32_t request_id = kNoRequest;
  std::uint32_t payload_length = 0;
  std::uint32_t payload_crc32 = 0;
  bool final() const { return (flags & kFlagFinal) != 0; }
};

struct Frame {
  FrameHeader header;
  std::vector<std::uint8_t> payload;  // exactly header.payload_length bytes, CRC verified
};

// CRC-32 (ISO-HDLC, the zlib/PNG polynomial) via libdeflate; chain with `crc` = previous.
std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc = 0);

// Writes the header for `h` (its payload_length and payload_crc32 as given) into `out`,
// computing header_crc32. No validation: the caller made h from a payload it owns.
void write_header(const FrameHeader& h, std::span<std::uint8_t, kHeaderSize> out);

// Header for a frame whose payload is the concatenation of `parts` (gathered writes: the
// server sends the header, the TileData fixed fields and the tile bytes straight from the
// mmapped pack without copying them). Fails with oversized_frame if the parts exceed
// limits.max_payload_bytes(), bad_flags on unknown flags.
Status make_header(MessageType type, std::uint8_t flags, std::uint32_t request_id,
                   std::span<const std::span<const std::uint8_t>> parts,
                   const Limits& limits, std::array<std::uint8_t, kHeaderSize>& out,
                   std::uint8_t version = kVersion1);

// Appends header + payload to `out`. Same failures as make_header; `out` is unchanged on
// failure.
Status append_frame(MessageType type, std::uint8_t flags, std::uint32_t request_id,
                    std::span<const std::uint8_t> payload, const Limits& limits,
                    std::vector<std::uint8_t>& out, std::uint8_t version = kVersion1);

// Parses a complete header (no payload needed): the same checks as FrameParser, in the
// same order. For tests and for peeking at a frame already in memory.
Status parse_header(std::span<const std::uint8_t, kHeaderSize> bytes, const Limits& limits,
                    FrameHeader& out);

// Which message types the parser accepts: a server's parser rejects server-only types
// with unexpected_type and vice versa.
enum class Receiver : std::uint8_t { server, client, any };

class FrameParser {
 public:
  enum class State : std::uint8_t { need_more, frame, error };
  struct Result {
    State state;
    std::size_t consumed;  // bytes of the fed span used; feed the rest again
  };

  // limits must satisfy validate(); asserted.
  explicit FrameParser(const Limits& limits, Receiver receiver = Receiver::any);

  // Consumes bytes until one frame completes, an error is found, or `bytes` runs out.
  // - need_more: all of `bytes` consumed (consumed == bytes.size()).
  // - frame: take_frame() returns it; bytes after `consumed` belong to later frames.
  // - error: status() says why (a typed code + a detail naming the field and the stream
  //   offset). Errors are sticky: the byte stream has lost its framing, every later feed
  //   returns the same error with consumed 0. The connection should send Error and close.
  Result feed(std::span<const std::uint8_t> bytes);

  // Moves out the frame completed by the last feed (precondition: it returned frame).
  // The parser then waits for the next header. Feeding again without taking the frame
  // drops it.
  Frame take_frame();

  const Status& status() const { return status_; }
  bool failed() const { return !status_.ok(); }

  // Applies newly negotiated limits (after HelloAck). Takes effect from the next header:
  // a frame already being buffered was checked against the old limits.
  void set_limits(const Limits& limits);
  const Limits& limits() const { return limits_; }

  // Total bytes consumed so far (for error details and statistics).
  std::uint64_t stream_offset() const { return stream_offset_; }

 private:
  enum class Phase : std::uint8_t { header, payload, ready, failed };
  Result fail(ErrorCode code, std::string detail, std::size_t consumed);

  Limits limits_;
  Receiver receiver_;
  Phase phase_ = Phase::header;
  std::array<std::uint8_t, kHeaderSize> header_bytes_{};
  std::size_t header_have_ = 0;
  Frame frame_;
  std::size_t payload_have_ = 0;
  std::uint64_t stream_offset_ = 0;
  std::uint64_t frame_start_ = 0;
  Status status_;
};

}  // namespace st::proto

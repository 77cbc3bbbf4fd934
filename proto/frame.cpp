// Frame encoding and the incremental FrameParser (PROTOCOL.md §2-3).
#include "proto/frame.hpp"

#include <libdeflate.h>

#include <algorithm>
#include <cassert>
#include <string>

#include "proto/byte_io.hpp"

namespace st::proto {
namespace {

std::string hex8(std::uint8_t v) {
  static const char* digits = "0123456789abcdef";
  return std::string("0x") + digits[v >> 4] + digits[v & 15];
}

bool accepts(Receiver r, MessageType type) {
  const Sender s = sender_of(type);
  switch (r) {
    case Receiver::server: return s != Sender::server;
    case Receiver::client: return s != Sender::client;
    case Receiver::any: return true;
  }
  return true;
}

// The checks that need the whole header, in spec order (PROTOCOL.md §3): header CRC
// first (nothing after it is trusted before), then flags, type, direction, length.
// `base` is the stream offset of the header, for the detail text.
Status check_full_header(std::span<const std::uint8_t, kHeaderSize> b, const Limits& limits,
                         Receiver receiver, std::uint64_t base, FrameHeader& h) {
  auto at = [&](std::size_t off) { return " at stream byte " + std::to_string(base + off); };
  const std::uint32_t stored = load_le<std::uint32_t>(b.data() + kOffHeaderCrc);
  const std::uint32_t actual = crc32(b.first(kOffHeaderCrc));
  if (stored != actual)
    return Status::fail(ErrorCode::header_checksum,
                        "header_crc32 " + std::to_string(stored) + " != computed " +
                            std::to_string(actual) + at(kOffHeaderCrc));
  h.version = b[kOffVersion];
  h.flags = b[kOffFlags];
  const std::uint16_t type = load_le<std::uint16_t>(b.data() + kOffType);
  h.request_id = load_le<std::uint32_t>(b.data() + kOffRequestId);
  h.payload_length = load_le<std::uint32_t>(b.data() + kOffPayloadLength);
  h.payload_crc32 = load_le<std::uint32_t>(b.data() + kOffPayloadCrc);
  if ((h.flags & ~kKnownFlags) != 0)
    return Status::fail(ErrorCode::bad_flags,
                        "flags " + hex8(h.flags) + " has reserved bits set" + at(kOffFlags));
  if (!is_known_type(type))
    return Status::fail(ErrorCode::unknown_type,
                        "type " + std::to_string(type) + " is not a message type of version " +
                            std::to_string(h.version) + at(kOffType));
  h.type = static_cast<MessageType>(type);
  if (!accepts(receiver, h.type))
    return Status::fail(ErrorCode::unexpected_type,
                        std::string("type ") + std::string(to_string(h.type)) +
                            " is never sent to this side" + at(kOffType));
  if (h.payload_length > limits.max_payload_bytes())
    return Status::fail(ErrorCode::oversized_frame,
                        "payload_length " + std::to_string(h.payload_length) +
                            " exceeds the limit " + std::to_string(limits.max_payload_bytes()) +
                            " (max_frame_bytes " + std::to_string(limits.max_frame_bytes) +
                            ")" + at(kOffPayloadLength));
  return {};
}

Status check_magic_byte(std::size_t i, std::uint8_t byte, std::uint64_t base) {
  if (byte != kMagic[i])
    return Status::fail(ErrorCode::bad_magic, "magic byte " + std::to_string(i) + " is " +
                                                  hex8(byte) + ", expected " + hex8(kMagic[i]) +
                                                  " at stream byte " + std::to_string(base + i));
  return {};
}

Status check_version(std::uint8_t v, const Limits& limits, std::uint64_t base) {
  if (v < limits.min_version || v > limits.max_version)
    return Status::fail(ErrorCode::unsupported_version,
                        "version " + std::to_string(v) + " outside the accepted [" +
                            std::to_string(limits.min_version) + ", " +
                            std::to_string(limits.max_version) + "] at stream byte " +
                            std::to_string(base + kOffVersion));
  return {};
}

}  // namespace

std::uint32_t crc32(std::span<const std::uint8_t> bytes, std::uint32_t crc) {
  return libdeflate_crc32(crc, bytes.data(), bytes.size());
}

void write_header(const FrameHeader& h, std::span<std::uint8_t, kHeaderSize> out) {
  std::copy(kMagic.begin(), kMagic.end(), out.begin() + kOffMagic);
  out[kOffVersion] = h.version;
  out[kOffFlags] = h.flags;
  store_le<std::uint16_t>(out.data() + kOffType, static_cast<std::uint16_t>(h.type));
  store_le<std::uint32_t>(out.data() + kOffRequestId, h.request_id);
  store_le<std::uint32_t>(out.data() + kOffPayloadLength, h.payload_length);
  store_le<std::uint32_t>(out.data() + kOffPayloadCrc, h.payload_crc32);
  store_le<std::uint32_t>(out.data() + kOffHeaderCrc,
                          crc32(std::span<const std::uint8_t>(out.data(), kOffHeaderCrc)));
}

Status make_header(MessageType type, std::uint8_t flags, std::uint32_t request_id,
                   std::span<const std::span<const std::uint8_t>> parts, const Limits& limits,
                   std::array<std::uint8_t, kHeaderSize>& out, std::uint8_t version) {
  if ((flags & ~kKnownFlags) != 0)
    return Status::fail(ErrorCode::bad_flags, "flags " + hex8(flags) + " has reserved bits set");
  if (!is_known_type(static_cast<std::uint16_t>(type)))
    return Status::fail(ErrorCode::unknown_type, "cannot encode an unknown message type");
  std::uint64_t length = 0;
  std::uint32_t crc = 0;
  for (auto part : parts) {
    length += part.size();
    crc = crc32(part, crc);
  }
  if (length > limits.max_payload_bytes())
    return Status::fail(ErrorCode::oversized_frame,
                        std::string(to_string(type)) + " payload of " + std::to_string(length) +
                            " bytes exceeds the limit " +
                            std::to_string(limits.max_payload_bytes()));
  FrameHeader h;
  h.version = version;
  h.flags = flags;
  h.type = type;
  h.request_id = request_id;
  h.payload_length = static_cast<std::uint32_t>(length);
  h.payload_crc32 = crc;
  write_header(h, out);
  return {};
}

Status append_frame(MessageType type, std::uint8_t flags, std::uint32_t request_id,
                    std::span<const std::uint8_t> payload, const Limits& limits,
                    std::vector<std::uint8_t>& out, std::uint8_t version) {
  std::array<std::uint8_t, kHeaderSize> header;
  const std::span<const std::uint8_t> parts[1] = {payload};
  Status s = make_header(type, flags, request_id, parts, limits, header, version);
  if (!s) return s;
  out.insert(out.end(), header.begin(), header.end());
  out.insert(out.end(), payload.begin(), payload.end());
  return s;
}

Status parse_header(std::span<const std::uint8_t, kHeaderSize> bytes, const Limits& limits,
                    FrameHeader& out) {
  for (std::size_t i = 0; i < kMagic.size(); ++i)
    if (Status s = check_magic_byte(i, bytes[i], 0); !s) return s;
  if (Status s = check_version(bytes[kOffVersion], limits, 0); !s) return s;
  return check_full_header(bytes, limits, Receiver::any, 0, out);
}

namespace {
// The first allocation for a payload; beyond it the buffer doubles as bytes arrive.
constexpr std::size_t kPayloadGrowStep = 16 * 1024;
}  // namespace

FrameParser::FrameParser(const Limits& limits, Receiver receiver)
    : limits_(limits), receiver_(receiver) {
  assert(validate(limits).ok());
}

void FrameParser::set_limits(const Limits& limits) {
  assert(validate(limits).ok());
  limits_ = limits;
}

FrameParser::Result FrameParser::fail(ErrorCode code, std::string detail, std::size_t consumed) {
  status_ = Status::fail(code, std::move(detail));
  phase_ = Phase::failed;
  frame_.payload = {};  // release the buffer: nothing more will be parsed
  return {State::error, consumed};
}

FrameParser::Result FrameParser::feed(std::span<const std::uint8_t> bytes) {
  if (phase_ == Phase::failed) return {State::error, 0};
  // A completed frame nobody took is dropped: the caller asked for the next one.
  if (phase_ == Phase::ready) {
    phase_ = Phase::header;
    header_have_ = 0;
  }
  std::size_t pos = 0;
  while (phase_ == Phase::header && pos < bytes.size()) {
    if (header_have_ == 0) frame_start_ = stream_offset_;
    const std::uint8_t byte = bytes[pos++];
    ++stream_offset_;
    header_bytes_[header_have_] = byte;
    // Magic and version are checked the moment they arrive: a peer speaking something
    // else is told so without waiting for a whole header (which may never come).
    if (header_have_ < kMagic.size()) {
      if (Status s = check_magic_byte(header_have_, byte, frame_start_); !s)
        return fail(s.code, std::move(s.detail), pos);
    } else if (header_have_ == kOffVersion) {
      if (Status s = check_version(byte, limits_, frame_start_); !s)
        return fail(s.code, std::move(s.detail), pos);
    }
    if (++header_have_ < kHeaderSize) continue;
    FrameHeader h;
    if (Status s = check_full_header(header_bytes_, limits_, receiver_, frame_start_, h); !s)
      return fail(s.code, std::move(s.detail), pos);
    // Only now, with the length checked against the limit, is the payload allocated, and
    // only as its bytes arrive: a header claiming megabytes that never come costs the
    // receiver what was sent, not what was claimed.
    frame_.header = h;
    frame_.payload.clear();
    frame_.payload.reserve(std::min<std::size_t>(h.payload_length, kPayloadGrowStep));
    payload_have_ = 0;
    phase_ = Phase::payload;
  }
  if (phase_ == Phase::payload) {
    const std::size_t want = frame_.header.payload_length;
    const std::size_t take = std::min<std::size_t>(bytes.size() - pos, want - payload_have_);
    if (frame_.payload.capacity() < payload_have_ + take)  // doubling, capped at the claim
      frame_.payload.reserve(std::min(want, std::max(payload_have_ + take, 2 * frame_.payload.capacity())));
    frame_.payload.insert(frame_.payload.end(), bytes.data() + pos, bytes.data() + pos + take);
    pos += take;
    payload_have_ += take;
    stream_offset_ += take;
    if (payload_have_ == want) {
      const std::uint32_t actual = crc32(frame_.payload);
      if (actual != frame_.header.payload_crc32)
        return fail(ErrorCode::payload_checksum,
                    std::string(to_string(frame_.header.type)) + " payload_crc32 " +
                        std::to_string(frame_.header.payload_crc32) + " != computed " +
                        std::to_string(actual) + " for the frame at stream byte " +
                        std::to_string(frame_start_),
                    pos);
      phase_ = Phase::ready;
      return {State::frame, pos};
    }
  }
  return {State::need_more, pos};
}

Frame FrameParser::take_frame() {
  assert(phase_ == Phase::ready);
  Frame f = std::move(frame_);
  frame_ = Frame{};
  phase_ = Phase::header;
  header_have_ = 0;
  return f;
}

}  // namespace st::proto

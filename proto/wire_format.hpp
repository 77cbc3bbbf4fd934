// Format constants of the shadowtile wire protocol (PROTOCOL.md is the spec; every value
// here is a FORMAT CONSTANT: changing one breaks every deployed peer).
//
// Frame header, 24 bytes, all integers little-endian:
//
//   offset size field            notes
//   ------ ---- ---------------- ------------------------------------------------------
//        0    4 magic            bytes 'S' 'T' 'W' 'P'
//        4    1 version          protocol version of this frame (1 = this spec)
//        5    1 flags            bit 0 FINAL (last frame answering request_id), 1..7 zero
//        6    2 type             MessageType
//        8    4 request_id       chosen by the requester, echoed by every answer frame
//       12    4 payload_length   bytes following the header (<= limit - 24)
//       16    4 payload_crc32    CRC-32 (ISO-HDLC, libdeflate_crc32) of the payload
//       20    4 header_crc32     CRC-32 of header bytes [0, 20)
//       24      payload
//
// Bytes [0, 5) (magic and version) are frozen across all versions, so a peer speaking a
// newer version always gets a clear "unsupported version" instead of a checksum error.
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace st::proto {

inline constexpr std::array<std::uint8_t, 4> kMagic = {'S', 'T', 'W', 'P'};

inline constexpr std::size_t kOffMagic = 0;
inline constexpr std::size_t kOffVersion = 4;
inline constexpr std::size_t kOffFlags = 5;
inline constexpr std::size_t kOffType = 6;
inline constexpr std::size_t kOffRequestId = 8;
inline constexpr std::size_t kOffPayloadLength = 12;
inline constexpr std::size_t kOffPayloadCrc = 16;
inline constexpr std::size_t kOffHeaderCrc = 20;
inline constexpr std::size_t kHeaderSize = 24;

static_assert(kOffVersion == kOffMagic + kMagic.size());
static_assert(kOffFlags == kOffVersion + 1);
static_assert(kOffType == kOffFlags + 1);
static_assert(kOffRequestId == kOffType + 2);
static_assert(kOffPayloadLength == kOffRequestId + 4);
static_assert(kOffPayloadCrc == kOffPayloadLength + 4);
static_assert(kOffHeaderCrc == kOffPayloadCrc + 4);
static_assert(kHeaderSize == kOffHeaderCrc + 4);
static_assert(kHeaderSize % 8 == 0, "payloads start 8-aligned in a frame buffer");

// Protocol versions this implementation speaks. Version 1 is also the handshake version:
// Hello, HelloAck and handshake Error frames always carry version 1 (PROTOCOL.md §5).
inline constexpr std::uint8_t kVersion1 = 1;
inline constexpr std::uint8_t kHandshakeVersion = kVersion1;
inline constexpr std::uint8_t kMinSupportedVersion = 1;
inline constexpr std::uint8_t kMaxSupportedVersion = 1;

// Header flags.
inline constexpr std::uint8_t kFlagFinal = 0x01;
inline constexpr std::uint8_t kKnownFlags = kFlagFinal;

// Request id 0 is reserved for frames not tied to a request (a connection-level Error,
// a server-initiated Ping and its Pong, Cancel).
inline constexpr std::uint32_t kNoRequest = 0;

enum class MessageType : std::uint16_t {
  hello = 0x0001,      // C->S  handshake offer
  hello_ack = 0x0002,  // S->C  handshake answer (chosen version, limits, nonce)
  error = 0x0003,      // both  typed error + one-line message
  list_maps = 0x0010,  // C->S
  map_list = 0x0011,   // S->C
  open_map = 0x0012,   // C->S
  map_info = 0x0013,   // S->C
  get_tiles = 0x0020,  // C->S  batch of tile ids with priorities
  tile_data = 0x0021,  // S->C  one per tile answered
  tile_error = 0x0022, // S->C  one per tile that could not be answered
  cancel = 0x0023,     // C->S  no answer
  ping = 0x0030,       // both
  pong = 0x0031,       // both
  get_stats = 0x0040,  // C->S
  stats = 0x0041,      // S->C
  auth = 0x0050,       // C->S  proof of the catalog key (feature kFeatureAuth, §11)
  auth_ok = 0x0051,    // S->C  the server's proof of the same key
};

// Which side may send a message type (the receiving parser rejects the other direction).
enum class Sender : std::uint8_t { client = 1, server = 2, both = 3 };

// nullopt-free lookup: false for a value that is no MessageType of this version.
bool is_known_type(std::uint16_t type);
Sender sender_of(MessageType type);
std::string_view to_string(MessageType type);  // "hello", "tile_data", ...; "unknown"

// Error codes, shared by the parser, Error and TileError messages (u16 on the wire).
// A receiver keeps codes it does not know (forward compatibility) and treats them as
// `internal`. FORMAT CONSTANTS.
enum class ErrorCode : std::uint16_t {
  ok = 0,
  // framing (the connection is lost: the receiver answers Error with request id 0, closes)
  bad_magic = 1,
  unsupported_version = 2,
  header_checksum = 3,
  payload_checksum = 4,
  oversized_frame = 5,
  unknown_type = 6,
  unexpected_type = 7,  // known type, wrong direction or wrong connection state
  bad_flags = 8,
  // payload
  truncated = 9,
  trailing_bytes = 10,
  invalid_field = 11,
  limit_exceeded = 12,  // a count above a negotiated limit
  bad_map_name = 13,
  // requests
  too_many_in_flight = 14,
  duplicate_request_id = 15,
  unknown_map = 16,
  unknown_map_id = 17,
  unknown_tile = 18,
  tile_too_large = 19,  // the tile's frame would exceed the negotiated max frame size
  cancelled = 20,
  // server state
  internal = 21,
  shutting_down = 22,
  overloaded = 23,
  timeout = 24,
  handshake_required = 25,
  auth_required = 26,  // the server needs a key: no Auth yet, or the client offered none
  auth_failed = 27,    // the Auth proof does not match the server's key
};

std::string_view to_string(ErrorCode code);  // "bad_magic", ...; "unknown"

}  // namespace st::proto

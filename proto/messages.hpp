// The messages of protocol version 1 (PROTOCOL.md §4 draws every payload with offsets).
//
// Every message has
//   Status encode_payload(const T&, const Limits&, std::vector<uint8_t>& out)  (appends)
//   Status decode_payload(std::span<const uint8_t> payload, const Limits&, T& out)
// Encoders check the same rules as decoders, so whatever encodes under some Limits
// decodes under the same Limits to an equal value. Decoders are safe for untrusted input:
// they reject truncation (truncated), bytes after the last field (trailing_bytes), bad
// field values (invalid_field, bad_map_name) and counts above the negotiated limits
// (limit_exceeded); they never allocate more than the payload's own size. On failure
// `out` is left in an unspecified but valid state. All functions are reentrant; no
// shared state.
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "proto/frame.hpp"
#include "proto/limits.hpp"
#include "proto/status.hpp"
#include "proto/wire_format.hpp"

namespace st::proto {

inline constexpr std::size_t kNonceBytes = 32;          // FORMAT CONSTANT
inline constexpr std::size_t kProofBytes = 32;          // FORMAT CONSTANT: HMAC-SHA256

// Feature bits (Hello.features / HelloAck.features). FORMAT CONSTANTS.
// kFeatureAuth: in a Hello, the client holds a key and can prove it (Auth); in a HelloAck,
// the server requires that proof before any request (PROTOCOL.md §11).
// kFeatureTileKind: in a Hello, the client wants to read a tile's kind from TileData; in a
// HelloAck, the server sets kTileFlagIndex on every index tile it sends (PROTOCOL.md §4.8).
inline constexpr std::uint32_t kFeatureAuth = 0x0000'0001;
inline constexpr std::uint32_t kFeatureTileKind = 0x0000'0002;
inline constexpr std::uint32_t kKnownFeatures = kFeatureAuth | kFeatureTileKind;
inline constexpr std::size_t kMaxMapsListed = 4096;
inline constexpr std::size_t kMaxCounters = 1024;
inline constexpr std::size_t kMaxHistograms = 64;
inline constexpr std::size_t kMaxHistogramBuckets = 64;
inline constexpr std::uint8_t kMaxResolutionLog2 = 30;   // packs allow L <= 20 today

// TileData.flags (FORMAT CONSTANTS, PROTOCOL.md §4.8):
//   bit 0 zlib: the payload is zlib format (packs store tiles already compressed). Clear:
//         the payload is the raw tile and uncompressed_size == its length.
//   bit 1 index: the tile is an index tile (pack index kind 2, a CutGrid); clear: an
//         encoded tile of the map's encoding (kind 1). Set by servers that grant
//         kFeatureTileKind; a server without that feature leaves it clear.
//   bits 2..15 reserved: 0 (invalid_field otherwise).
inline constexpr std::uint16_t kTileFlagZlib = 0x0001;
inline constexpr std::uint16_t kTileFlagIndex = 0x0002;
inline constexpr std::uint16_t kKnownTileFlags = kTileFlagZlib | kTileFlagIndex;

// C->S. First frame of a connection (header version 1). Proposes a version range and the
// limits this client accepts (see Limits). features: capability bits (kFeatureAuth);
// unknown bits are ignored by the server.
struct Hello {
  static constexpr MessageType kType = MessageType::hello;
  std::uint8_t min_version = kMinSupportedVersion;
  std::uint8_t max_version = kMaxSupportedVersion;
  std::uint16_t max_in_flight = Limits{}.max_in_flight;
  std::uint32_t max_frame_bytes = Limits{}.max_frame_bytes;
  std::uint16_t max_tiles_per_batch = Limits{}.max_tiles_per_batch;
  std::uint32_t features = 0;
  std::string client_name;  // free text, <= kMaxLabelBytes, informative only
  bool operator==(const Hello&) const = default;
};

// S->C. The chosen version (the highest both speak) and limits (each <= the Hello's), and
// a 32-byte server nonce: the challenge of the Auth proof when features has kFeatureAuth
// (then from a CSPRNG, fresh per connection); otherwise unused.
struct HelloAck {
  static constexpr MessageType kType = MessageType::hello_ack;
  std::uint8_t version = kVersion1;
  std::uint16_t max_in_flight = Limits{}.max_in_flight;
  std::uint32_t max_frame_bytes = Limits{}.max_frame_bytes;
  std::uint16_t max_tiles_per_batch = Limits{}.max_tiles_per_batch;
  std::uint32_t features = 0;
  std::array<std::uint8_t, kNonceBytes> nonce{};
  std::string server_name;
  bool operator==(const HelloAck&) const = default;
};

// Both directions. A request's failure (request_id echoed, FINAL set) or, with request
// id 0, a connection-level failure after which the sender closes.
struct ErrorMessage {
  static constexpr MessageType kType = MessageType::error;
  ErrorCode code = ErrorCode::internal;  // never ok; unknown values are kept
  std::string message;                   // free text, <= kMaxErrorMessageBytes
  bool operator==(const ErrorMessage&) const = default;
};

// An Error for `code` whose message is `text` made valid (sanitize_text): never fails to
// encode, whatever the text (an exception's what(), a parser Status detail).
ErrorMessage make_error(ErrorCode code, std::string_view text);
// The Error a receiver sends (with request id 0, then closes) after a framing or decode
// failure `s` (precondition: !s.ok()).
ErrorMessage make_error(const Status& s);

struct ListMaps {
  static constexpr MessageType kType = MessageType::list_maps;
  bool operator==(const ListMaps&) const = default;
};

struct MapEntry {
  std::string name;                  // a valid map name, unique within the list
  std::uint8_t encoding = 0;         // st::Encoding of the pack (opaque to proto)
  std::uint8_t resolution_log2 = 0;  // full map is 2^L texels a side, L <= 30
  std::uint8_t skip_level = 0;       // K <= L: the skip grid is 2^K a side
  std::uint32_t tile_count = 0;
  std::uint64_t pack_bytes = 0;
  bool operator==(const MapEntry&) const = default;
};

struct MapList {
  static constexpr MessageType kType = MessageType::map_list;
  std::vector<MapEntry> maps;  // <= kMaxMapsListed
  bool operator==(const MapList&) const = default;
};

struct OpenMap {
  static constexpr MessageType kType = MessageType::open_map;
  std::string name;  // a valid map name
  bool operator==(const OpenMap&) const = default;
};

// The pack header and skip grid bytes exactly as they lie in the pack (parsed by tiles/,
// never by proto), and the connection-local handle for GetTiles.
struct MapInfo {
  static constexpr MessageType kType = MessageType::map_info;
  std::uint32_t map_id = 1;  // != 0
  std::vector<std::uint8_t> pack_header;
  std::vector<std::uint8_t> skip_grid;
  bool operator==(const MapInfo&) const = default;
};

struct TileRequest {
  std::uint64_t tile_id = 0;
  std::uint16_t priority = 0;  // larger = more urgent
  bool operator==(const TileRequest&) const = default;
};

// C->S. 1..max_tiles_per_batch distinct tile ids of one opened map. Answered by exactly
// one TileData or TileError per tile, in any order; the last of them carries FINAL.
struct GetTiles {
  static constexpr MessageType kType = MessageType::get_tiles;
  std::uint32_t map_id = 1;
  std::vector<TileRequest> tiles;
  bool operator==(const GetTiles&) const = default;
};

// The fixed fields of TileData (all but the bytes), 28 bytes on the wire.
struct TileMeta {
  std::uint64_t tile_id = 0;
  std::uint32_t map_id = 1;
  std::uint16_t flags = kTileFlagZlib;
  std::uint32_t uncompressed_size = 0;
  std::uint32_t payload_crc32 = 0;  // CRC-32 of the stored bytes, from the pack index
  bool operator==(const TileMeta&) const = default;
};
inline constexpr std::size_t kTileMetaBytes = 28;  // FORMAT CONSTANT (incl. length field)

struct TileData {
  static constexpr MessageType kType = MessageType::tile_data;
  TileMeta meta;
  std::vector<std::uint8_t> payload;  // the stored tile bytes as they lie in the pack
  bool operator==(const TileData&) const = default;
};

// The end-to-end check the client runs before decompressing: the bytes it got are the
// bytes the pack builder wrote (the frame CRC only covers the hop).
bool tile_crc_matches(const TileMeta& meta, std::span<const std::uint8_t> payload);

struct TileError {
  static constexpr MessageType kType = MessageType::tile_error;
  std::uint64_t tile_id = 0;
  std::uint32_t map_id = 1;
  ErrorCode code = ErrorCode::unknown_tile;  // never ok
  std::string message;
  bool operator==(const TileError&) const = default;
};

// C->S, no answer (send it with request id 0). Requests and/or tiles of one map to drop:
// tiles not yet sent are answered with TileError(cancelled), so every tile still gets
// exactly one answer and every request still ends with FINAL.
struct Cancel {
  static constexpr MessageType kType = MessageType::cancel;
  std::vector<std::uint32_t> request_ids;  // each != 0, <= max_in_flight of them
  std::uint32_t map_id = 0;                // != 0 iff tile_ids is not empty
  std::vector<std::uint64_t> tile_ids;     // <= max_in_flight * max_tiles_per_batch
  bool operator==(const Cancel&) const = default;
};

// C->S, only when the HelloAck set kFeatureAuth, before any other request (PROTOCOL.md
// §11): proof = HMAC-SHA256(key, "shadowtile auth v1 client" || server nonce || client_nonce).
// Answered by AuthOk, or Error auth_failed and a close.
struct Auth {
  static constexpr MessageType kType = MessageType::auth;
  std::array<std::uint8_t, kNonceBytes> client_nonce{};  // fresh per connection (CSPRNG)
  std::array<std::uint8_t, kProofBytes> proof{};
  bool operator==(const Auth&) const = default;
};

// S->C. The server's proof that it holds the same key, so a client never feeds a fake
// server's tiles to its renderer: HMAC-SHA256(key, "shadowtile auth v1 server" ||
// server nonce || client_nonce).
struct AuthOk {
  static constexpr MessageType kType = MessageType::auth_ok;
  std::array<std::uint8_t, kProofBytes> proof{};
  bool operator==(const AuthOk&) const = default;
};

struct Ping {
  static constexpr MessageType kType = MessageType::ping;
  std::uint64_t timestamp = 0;  // sender's clock, opaque to the receiver
  bool operator==(const Ping&) const = default;
};

struct Pong {
  static constexpr MessageType kType = MessageType::pong;
  std::uint64_t echo_timestamp = 0;      // the Ping's timestamp
  std::uint64_t responder_timestamp = 0; // responder's clock (ns since its epoch) or 0
  bool operator==(const Pong&) const = default;
};

struct GetStats {
  static constexpr MessageType kType = MessageType::get_stats;
  bool operator==(const GetStats&) const = default;
};

struct Counter {
  std::string name;  // map-name rules, unique within the message
  std::uint64_t value = 0;
  bool operator==(const Counter&) const = default;
};

struct Bucket {
  std::uint64_t upper_bound = 0;  // inclusive; strictly increasing within a histogram
  std::uint64_t count = 0;
  bool operator==(const Bucket&) const = default;
};

struct Histogram {
  std::string name;             // map-name rules with the unit in it ("latency_us")
  std::vector<Bucket> buckets;  // 1..kMaxHistogramBuckets
  bool operator==(const Histogram&) const = default;
};

// S->C. Server counters (connections, requests, tiles, bytes, errors, ...) as a generic
// list, plus histograms (request latency, ...).
struct Stats {
  static constexpr MessageType kType = MessageType::stats;
  std::vector<Counter> counters;      // <= kMaxCounters
  std::vector<Histogram> histograms;  // <= kMaxHistograms
  bool operator==(const Stats&) const = default;
};

using Message = std::variant<Hello, HelloAck, ErrorMessage, ListMaps, MapList, OpenMap,
                             MapInfo, GetTiles, TileData, TileError, Cancel, Ping, Pong,
                             GetStats, Stats, Auth, AuthOk>;

MessageType type_of(const Message& m);

#define ST_PROTO_CODEC(T)                                                               \
  Status encode_payload(const T& m, const Limits& limits, std::vector<std::uint8_t>& out); \
  Status decode_payload(std::span<const std::uint8_t> payload, const Limits& limits, T& out);
ST_PROTO_CODEC(Hello)
ST_PROTO_CODEC(HelloAck)
ST_PROTO_CODEC(ErrorMessage)
ST_PROTO_CODEC(ListMaps)
ST_PROTO_CODEC(MapList)
ST_PROTO_CODEC(OpenMap)
ST_PROTO_CODEC(MapInfo)
ST_PROTO_CODEC(GetTiles)
ST_PROTO_CODEC(TileData)
ST_PROTO_CODEC(TileError)
ST_PROTO_CODEC(Cancel)
ST_PROTO_CODEC(Ping)
ST_PROTO_CODEC(Pong)
ST_PROTO_CODEC(GetStats)
ST_PROTO_CODEC(Stats)
ST_PROTO_CODEC(Auth)
ST_PROTO_CODEC(AuthOk)
#undef ST_PROTO_CODEC

// Appends one whole frame (header + payload) carrying `m`. Fails (out unchanged) if the
// message breaks a rule or the frame would exceed limits.max_frame_bytes.
Status encode_message(const Message& m, std::uint32_t request_id, std::uint8_t flags,
                      const Limits& limits, std::vector<std::uint8_t>& out,
                      std::uint8_t version = kVersion1);

// Decodes a frame the FrameParser produced into the alternative its header type names.
Status decode_message(const Frame& frame, const Limits& limits, Message& out);

// Zero-copy TileData for the server's gathered write: fills `out` with the frame header
// followed by the 28 fixed TileData bytes; the frame is `out` then `tile_bytes`
// (unchanged, e.g. straight from the mmapped pack). Fails with tile_too_large if the
// frame would exceed the limit.
inline constexpr std::size_t kTileDataPrefixBytes = kHeaderSize + kTileMetaBytes;
Status encode_tile_data_prefix(const TileMeta& meta, std::span<const std::uint8_t> tile_bytes,
                               std::uint32_t request_id, std::uint8_t flags,
                               const Limits& limits,
                               std::array<std::uint8_t, kTileDataPrefixBytes>& out);

// The largest frame (header + payload) a client may send under `limits`: a Cancel naming
// max_in_flight requests and as many tiles as its rule allows, or the handshake minimum if
// that is larger (kMinFrameBytes <= result <= limits.max_frame_bytes unless the limits
// themselves are below the minimum). A server may bound what it buffers from a client by
// this instead of max_frame_bytes, which exists for the server's tiles.
std::uint32_t max_client_frame_bytes(const Limits& limits);

// Zero-copy decode for the client: `bytes` views the frame's payload.
Status decode_tile_data_view(std::span<const std::uint8_t> payload, TileMeta& meta,
                             std::span<const std::uint8_t>& bytes);

}  // namespace st::proto

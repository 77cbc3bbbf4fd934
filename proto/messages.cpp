// Payload codecs of protocol version 1 (PROTOCOL.md §4): per message a writer and a reader
// built on the bounds-checked Reader (byte_io.hpp); both run the message's rule check
// (message_rules.hpp), so anything encodable decodes.
#include "proto/messages.hpp"

#include <algorithm>
#include <string>
#include <string_view>

#include "proto/byte_io.hpp"
#include "proto/message_rules.hpp"
#include "proto/names.hpp"
#include "proto/tile_prefix.hpp"

namespace st::proto {
namespace {

using detail::check;
using detail::check_tile;
using detail::max_cancel_tiles;

void put_str8(Writer& w, std::string_view s) {
  w.u8(static_cast<std::uint8_t>(s.size()));
  w.bytes(s);
}
void put_str16(Writer& w, std::string_view s) {
  w.u16(static_cast<std::uint16_t>(s.size()));
  w.bytes(s);
}
void put_blob32(Writer& w, std::span<const std::uint8_t> b) {
  w.u32(static_cast<std::uint32_t>(b.size()));
  w.bytes(b);
}
bool get_str8(Reader& r, std::string& s, const char* field) {
  std::uint8_t n = 0;
  return r.u8(n, field) && r.copy(n, s, field);
}
bool get_str16(Reader& r, std::string& s, const char* field) {
  std::uint16_t n = 0;
  return r.u16(n, field) && r.copy(n, s, field);
}
bool get_blob32(Reader& r, std::vector<std::uint8_t>& b, const char* field) {
  std::uint32_t n = 0;
  return r.u32(n, field) && r.copy(n, b, field);
}
bool get_zero16(Reader& r, const char* field) {
  const std::size_t at = r.offset();
  std::uint16_t v = 0;
  if (!r.u16(v, field)) return false;
  return v == 0 || r.fail_field(ErrorCode::invalid_field, field, "must be 0", at);
}
bool get_zero8(Reader& r, const char* field) {
  const std::size_t at = r.offset();
  std::uint8_t v = 0;
  if (!r.u8(v, field)) return false;
  return v == 0 || r.fail_field(ErrorCode::invalid_field, field, "must be 0", at);
}

// Decode epilogue: structural failure first, then trailing bytes, then the shared rules.
template <class T, class Check>
Status finish(Reader& r, const T& out, Check check) {
  Status s = r.finish();
  if (!s) return s;
  return check(out);
}

// ---- writers (called after check) -----------------------------------------------------

void write(Writer& w, const Hello& m) {
  w.u8(m.min_version);
  w.u8(m.max_version);
  w.u16(m.max_in_flight);
  w.u32(m.max_frame_bytes);
  w.u16(m.max_tiles_per_batch);
  w.u16(0);
  w.u32(m.features);
  put_str8(w, m.client_name);
}

void write(Writer& w, const HelloAck& m) {
  w.u8(m.version);
  w.u8(0);
  w.u16(m.max_in_flight);
  w.u32(m.max_frame_bytes);
  w.u16(m.max_tiles_per_batch);
  w.u16(0);
  w.u32(m.features);
  w.bytes(m.nonce);
  put_str8(w, m.server_name);
}

void write(Writer& w, const ErrorMessage& m) {
  w.u16(static_cast<std::uint16_t>(m.code));
  put_str16(w, m.message);
}

void write(Writer&, const ListMaps&) {}
void write(Writer&, const GetStats&) {}

void write(Writer& w, const MapList& m) {
  w.u16(static_cast<std::uint16_t>(m.maps.size()));
  w.u16(0);
  for (const MapEntry& e : m.maps) {
    put_str8(w, e.name);
    w.u8(e.encoding);
    w.u8(e.resolution_log2);
    w.u8(e.skip_level);
    w.u8(0);
    w.u32(e.tile_count);
    w.u64(e.pack_bytes);
  }
}

void write(Writer& w, const OpenMap& m) { put_str8(w, m.name); }

void write(Writer& w, const MapInfo& m) {
  w.u32(m.map_id);
  put_blob32(w, m.pack_header);
  put_blob32(w, m.skip_grid);
}

void write(Writer& w, const GetTiles& m) {
  w.u32(m.map_id);
  w.u16(static_cast<std::uint16_t>(m.tiles.size()));
  w.u16(0);
  for (const TileRequest& t : m.tiles) {
    w.u64(t.tile_id);
    w.u16(t.priority);
  }
}

void write_meta(Writer& w, const TileMeta& m, std::size_t payload_size) {
  w.u64(m.tile_id);
  w.u32(m.map_id);
  w.u16(m.flags);
  w.u16(0);
  w.u32(m.uncompressed_size);
  w.u32(m.payload_crc32);
  w.u32(static_cast<std::uint32_t>(payload_size));
}

void write(Writer& w, const TileData& m) {
  write_meta(w, m.meta, m.payload.size());
  w.bytes(m.payload);
}

void write(Writer& w, const TileError& m) {
  w.u64(m.tile_id);
  w.u32(m.map_id);
  w.u16(static_cast<std::uint16_t>(m.code));
  put_str16(w, m.message);
}

void write(Writer& w, const Cancel& m) {
  w.u16(static_cast<std::uint16_t>(m.request_ids.size()));
  w.u16(static_cast<std::uint16_t>(m.tile_ids.size()));
  w.u32(m.map_id);
  for (std::uint32_t id : m.request_ids) w.u32(id);
  for (std::uint64_t id : m.tile_ids) w.u64(id);
}

void write(Writer& w, const Ping& m) { w.u64(m.timestamp); }

void write(Writer& w, const Auth& m) {
  w.bytes(m.client_nonce);
  w.bytes(m.proof);
}

void write(Writer& w, const AuthOk& m) { w.bytes(m.proof); }

void write(Writer& w, const Pong& m) {
  w.u64(m.echo_timestamp);
  w.u64(m.responder_timestamp);
}

void write(Writer& w, const Stats& m) {
  w.u16(static_cast<std::uint16_t>(m.counters.size()));
  w.u16(static_cast<std::uint16_t>(m.histograms.size()));
  w.u32(0);
  for (const Counter& c : m.counters) {
    put_str8(w, c.name);
    w.u64(c.value);
  }
  for (const Histogram& h : m.histograms) {
    put_str8(w, h.name);
    w.u16(static_cast<std::uint16_t>(h.buckets.size()));
    for (const Bucket& b : h.buckets) {
      w.u64(b.upper_bound);
      w.u64(b.count);
    }
  }
}

template <class T>
Status encode_checked(const T& m, const Limits& limits, std::vector<std::uint8_t>& out) {
  if (Status s = check(m, limits); !s) return s;
  Writer w(out);
  write(w, m);
  return {};
}

template <class T>
Status decode_into(const Frame& f, const Limits& limits, Message& out) {
  return decode_payload(f.payload, limits, out.emplace<T>());
}

}  // namespace

// ---- public encoders ---------------------------------------------------------------------

#define ST_PROTO_ENCODE(T)                                                                  \
  Status encode_payload(const T& m, const Limits& limits, std::vector<std::uint8_t>& out) { \
    return encode_checked(m, limits, out);                                                  \
  }
ST_PROTO_ENCODE(Hello)
ST_PROTO_ENCODE(HelloAck)
ST_PROTO_ENCODE(ErrorMessage)
ST_PROTO_ENCODE(ListMaps)
ST_PROTO_ENCODE(MapList)
ST_PROTO_ENCODE(OpenMap)
ST_PROTO_ENCODE(MapInfo)
ST_PROTO_ENCODE(GetTiles)
ST_PROTO_ENCODE(TileData)
ST_PROTO_ENCODE(TileError)
ST_PROTO_ENCODE(Cancel)
ST_PROTO_ENCODE(Ping)
ST_PROTO_ENCODE(Pong)
ST_PROTO_ENCODE(GetStats)
ST_PROTO_ENCODE(Stats)
ST_PROTO_ENCODE(Auth)
ST_PROTO_ENCODE(AuthOk)
#undef ST_PROTO_ENCODE

// ---- public decoders ---------------------------------------------------------------------

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, Hello& m) {
  Reader r(p, "hello");
  r.u8(m.min_version, "min_version");
  r.u8(m.max_version, "max_version");
  r.u16(m.max_in_flight, "max_in_flight");
  r.u32(m.max_frame_bytes, "max_frame_bytes");
  r.u16(m.max_tiles_per_batch, "max_tiles_per_batch");
  get_zero16(r, "reserved");
  r.u32(m.features, "features");
  get_str8(r, m.client_name, "client_name");
  return finish(r, m, [&](const Hello& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, HelloAck& m) {
  Reader r(p, "hello_ack");
  r.u8(m.version, "version");
  get_zero8(r, "reserved");
  r.u16(m.max_in_flight, "max_in_flight");
  r.u32(m.max_frame_bytes, "max_frame_bytes");
  r.u16(m.max_tiles_per_batch, "max_tiles_per_batch");
  get_zero16(r, "reserved");
  r.u32(m.features, "features");
  std::span<const std::uint8_t> nonce;
  if (r.view(kNonceBytes, nonce, "nonce")) std::copy(nonce.begin(), nonce.end(), m.nonce.begin());
  get_str8(r, m.server_name, "server_name");
  return finish(r, m, [&](const HelloAck& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, ErrorMessage& m) {
  Reader r(p, "error");
  std::uint16_t code = 0;
  r.u16(code, "code");
  m.code = static_cast<ErrorCode>(code);
  get_str16(r, m.message, "message");
  return finish(r, m, [&](const ErrorMessage& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits&, ListMaps&) {
  Reader r(p, "list_maps");
  return r.finish();
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits&, GetStats&) {
  Reader r(p, "get_stats");
  return r.finish();
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, MapList& m) {
  Reader r(p, "map_list");
  std::uint16_t n = 0;
  r.u16(n, "count");
  get_zero16(r, "reserved");
  m.maps.clear();
  constexpr std::size_t kMinEntry = 1 + 1 + 16;  // 1-byte name + fixed fields
  if (r.count_fits(n, kMinEntry, "count")) m.maps.resize(n);
  for (std::size_t i = 0; i < m.maps.size() && r.ok(); ++i) {
    MapEntry& e = m.maps[i];
    get_str8(r, e.name, "name");
    r.u8(e.encoding, "encoding");
    r.u8(e.resolution_log2, "resolution_log2");
    r.u8(e.skip_level, "skip_level");
    get_zero8(r, "reserved");
    r.u32(e.tile_count, "tile_count");
    r.u64(e.pack_bytes, "pack_bytes");
  }
  return finish(r, m, [&](const MapList& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, OpenMap& m) {
  Reader r(p, "open_map");
  get_str8(r, m.name, "name");
  return finish(r, m, [&](const OpenMap& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, MapInfo& m) {
  Reader r(p, "map_info");
  r.u32(m.map_id, "map_id");
  get_blob32(r, m.pack_header, "pack_header");
  get_blob32(r, m.skip_grid, "skip_grid");
  return finish(r, m, [&](const MapInfo& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, GetTiles& m) {
  Reader r(p, "get_tiles");
  std::uint16_t n = 0;
  r.u32(m.map_id, "map_id");
  const std::size_t count_at = r.offset();
  r.u16(n, "count");
  get_zero16(r, "reserved");
  // The limit is checked before the count is trusted for anything.
  if (r.ok() && n > limits.max_tiles_per_batch)
    r.fail(ErrorCode::limit_exceeded,
           "count " + std::to_string(n) + " exceeds max_tiles_per_batch " +
               std::to_string(limits.max_tiles_per_batch),
           count_at);
  m.tiles.clear();
  if (r.count_fits(n, 10, "count")) m.tiles.resize(n);
  for (TileRequest& t : m.tiles) {
    r.u64(t.tile_id, "tile_id");
    r.u16(t.priority, "priority");
  }
  return finish(r, m, [&](const GetTiles& v) { return check(v, limits); });
}

namespace {
bool read_meta(Reader& r, TileMeta& m, std::uint32_t& length) {
  r.u64(m.tile_id, "tile_id");
  r.u32(m.map_id, "map_id");
  r.u16(m.flags, "flags");
  get_zero16(r, "reserved");
  r.u32(m.uncompressed_size, "uncompressed_size");
  r.u32(m.payload_crc32, "payload_crc32");
  return r.u32(length, "payload_length");
}
}  // namespace

std::uint32_t max_client_frame_bytes(const Limits& l) {
  // Every C->S payload (PROTOCOL.md §4): Hello 17 + name, OpenMap 1 + name, Auth 64,
  // Ping 8, Pong 16, Error 4 + message, and the two that grow with the limits.
  const std::uint64_t get_tiles = 8 + 10 * std::uint64_t(l.max_tiles_per_batch);
  const std::uint64_t cancel = 8 + 4 * std::uint64_t(l.max_in_flight) + 8 * std::uint64_t(max_cancel_tiles(l));
  const std::uint64_t payload = std::max({get_tiles, cancel, std::uint64_t(4 + kMaxErrorMessageBytes),
                                          std::uint64_t(17 + kMaxLabelBytes)});
  const std::uint64_t frame = std::max<std::uint64_t>(kHeaderSize + payload, kMinFrameBytes);
  return static_cast<std::uint32_t>(std::min<std::uint64_t>(frame, l.max_frame_bytes));
}

Status decode_tile_data_view(std::span<const std::uint8_t> p, TileMeta& meta,
                             std::span<const std::uint8_t>& bytes) {
  Reader r(p, "tile_data");
  std::uint32_t n = 0;
  read_meta(r, meta, n);
  r.view(n, bytes, "payload");
  Status s = r.finish();
  if (!s) return s;
  return check_tile(meta, bytes.size());
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits&, TileData& m) {
  std::span<const std::uint8_t> bytes;
  Status s = decode_tile_data_view(p, m.meta, bytes);
  if (s) m.payload.assign(bytes.begin(), bytes.end());
  return s;
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, TileError& m) {
  Reader r(p, "tile_error");
  std::uint16_t code = 0;
  r.u64(m.tile_id, "tile_id");
  r.u32(m.map_id, "map_id");
  r.u16(code, "code");
  m.code = static_cast<ErrorCode>(code);
  get_str16(r, m.message, "message");
  return finish(r, m, [&](const TileError& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, Cancel& m) {
  Reader r(p, "cancel");
  std::uint16_t n_req = 0, n_tiles = 0;
  r.u16(n_req, "request_count");
  r.u16(n_tiles, "tile_count");
  r.u32(m.map_id, "map_id");
  if (r.ok() && n_req > limits.max_in_flight)
    r.fail(ErrorCode::limit_exceeded,
           "request_count " + std::to_string(n_req) + " exceeds max_in_flight " +
               std::to_string(limits.max_in_flight),
           0);
  if (r.ok() && n_tiles > max_cancel_tiles(limits))
    r.fail(ErrorCode::limit_exceeded,
           "tile_count " + std::to_string(n_tiles) + " exceeds " +
               std::to_string(max_cancel_tiles(limits)),
           2);
  m.request_ids.clear();
  m.tile_ids.clear();
  if (r.count_fits(n_req, 4, "request_count")) m.request_ids.resize(n_req);
  for (std::uint32_t& id : m.request_ids) r.u32(id, "request_id");
  if (r.count_fits(n_tiles, 8, "tile_count")) m.tile_ids.resize(n_tiles);
  for (std::uint64_t& id : m.tile_ids) r.u64(id, "tile_id");
  return finish(r, m, [&](const Cancel& v) { return check(v, limits); });
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits&, Ping& m) {
  Reader r(p, "ping");
  r.u64(m.timestamp, "timestamp");
  return r.finish();
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits&, Auth& m) {
  Reader r(p, "auth");
  std::span<const std::uint8_t> v;
  if (r.view(kNonceBytes, v, "client_nonce")) std::copy(v.begin(), v.end(), m.client_nonce.begin());
  if (r.view(kProofBytes, v, "proof")) std::copy(v.begin(), v.end(), m.proof.begin());
  return r.finish();
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits&, AuthOk& m) {
  Reader r(p, "auth_ok");
  std::span<const std::uint8_t> v;
  if (r.view(kProofBytes, v, "proof")) std::copy(v.begin(), v.end(), m.proof.begin());
  return r.finish();
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits&, Pong& m) {
  Reader r(p, "pong");
  r.u64(m.echo_timestamp, "echo_timestamp");
  r.u64(m.responder_timestamp, "responder_timestamp");
  return r.finish();
}

Status decode_payload(std::span<const std::uint8_t> p, const Limits& limits, Stats& m) {
  Reader r(p, "stats");
  std::uint16_t n_counters = 0, n_hist = 0;
  r.u16(n_counters, "counter_count");
  r.u16(n_hist, "histogram_count");
  std::uint32_t reserved = 0;
  if (r.u32(reserved, "reserved") && reserved != 0)
    r.fail(ErrorCode::invalid_field, "reserved must be 0", 4);
  if (r.ok() && n_counters > kMaxCounters)
    r.fail(ErrorCode::limit_exceeded, "counter_count " + std::to_string(n_counters), 0);
  if (r.ok() && n_hist > kMaxHistograms)
    r.fail(ErrorCode::limit_exceeded, "histogram_count " + std::to_string(n_hist), 2);
  m.counters.clear();
  m.histograms.clear();
  if (r.count_fits(n_counters, 1 + 1 + 8, "counter_count")) m.counters.resize(n_counters);
  for (std::size_t i = 0; i < m.counters.size() && r.ok(); ++i) {
    get_str8(r, m.counters[i].name, "counter.name");
    r.u64(m.counters[i].value, "counter.value");
  }
  if (r.count_fits(n_hist, 1 + 1 + 2, "histogram_count")) m.histograms.resize(n_hist);
  for (std::size_t i = 0; i < m.histograms.size() && r.ok(); ++i) {
    Histogram& h = m.histograms[i];
    get_str8(r, h.name, "histogram.name");
    std::uint16_t nb = 0;
    const std::size_t at = r.offset();
    r.u16(nb, "bucket_count");
    if (r.ok() && nb > kMaxHistogramBuckets)
      r.fail(ErrorCode::limit_exceeded, "bucket_count " + std::to_string(nb), at);
    if (r.count_fits(nb, 16, "bucket_count")) h.buckets.resize(nb);
    for (Bucket& b : h.buckets) {
      r.u64(b.upper_bound, "upper_bound");
      r.u64(b.count, "count");
    }
  }
  return finish(r, m, [&](const Stats& v) { return check(v, limits); });
}

// ---- frames --------------------------------------------------------------------------------

ErrorMessage make_error(ErrorCode code, std::string_view text) {
  return ErrorMessage{code == ErrorCode::ok ? ErrorCode::internal : code,
                      sanitize_text(text, kMaxErrorMessageBytes)};
}

ErrorMessage make_error(const Status& s) { return make_error(s.code, s.detail); }

bool tile_crc_matches(const TileMeta& meta, std::span<const std::uint8_t> payload) {
  return crc32(payload) == meta.payload_crc32;
}

MessageType type_of(const Message& m) {
  return std::visit([](const auto& v) { return std::decay_t<decltype(v)>::kType; }, m);
}

Status encode_message(const Message& m, std::uint32_t request_id, std::uint8_t flags,
                      const Limits& limits, std::vector<std::uint8_t>& out,
                      std::uint8_t version) {
  std::vector<std::uint8_t> payload;
  Status s = std::visit([&](const auto& v) { return encode_payload(v, limits, payload); }, m);
  if (!s) return s;
  return append_frame(type_of(m), flags, request_id, payload, limits, out, version);
}

Status decode_message(const Frame& f, const Limits& limits, Message& out) {
  switch (f.header.type) {
    case MessageType::hello: return decode_into<Hello>(f, limits, out);
    case MessageType::hello_ack: return decode_into<HelloAck>(f, limits, out);
    case MessageType::error: return decode_into<ErrorMessage>(f, limits, out);
    case MessageType::list_maps: return decode_into<ListMaps>(f, limits, out);
    case MessageType::map_list: return decode_into<MapList>(f, limits, out);
    case MessageType::open_map: return decode_into<OpenMap>(f, limits, out);
    case MessageType::map_info: return decode_into<MapInfo>(f, limits, out);
    case MessageType::get_tiles: return decode_into<GetTiles>(f, limits, out);
    case MessageType::tile_data: return decode_into<TileData>(f, limits, out);
    case MessageType::tile_error: return decode_into<TileError>(f, limits, out);
    case MessageType::cancel: return decode_into<Cancel>(f, limits, out);
    case MessageType::ping: return decode_into<Ping>(f, limits, out);
    case MessageType::pong: return decode_into<Pong>(f, limits, out);
    case MessageType::get_stats: return decode_into<GetStats>(f, limits, out);
    case MessageType::stats: return decode_into<Stats>(f, limits, out);
    case MessageType::auth: return decode_into<Auth>(f, limits, out);
    case MessageType::auth_ok: return decode_into<AuthOk>(f, limits, out);
  }
  return Status::fail(ErrorCode::unknown_type,
                      "type " + std::to_string(static_cast<unsigned>(f.header.type)));
}

Status encode_tile_data_prefix(const TileMeta& meta, std::span<const std::uint8_t> tile_bytes,
                               std::uint32_t request_id, std::uint8_t flags,
                               const Limits& limits,
                               std::array<std::uint8_t, kTileDataPrefixBytes>& out) {
  if (Status s = check_tile(meta, tile_bytes.size()); !s) return s;
  if (std::uint64_t(tile_bytes.size()) + kTileMetaBytes > limits.max_payload_bytes())
    return Status::fail(ErrorCode::tile_too_large,
                        "tile " + std::to_string(meta.tile_id) + " of " +
                            std::to_string(tile_bytes.size()) + " bytes does not fit max_frame_bytes " +
                            std::to_string(limits.max_frame_bytes));
  std::vector<std::uint8_t> fixed;
  fixed.reserve(kTileMetaBytes);
  Writer w(fixed);
  write_meta(w, meta, tile_bytes.size());
  const std::span<const std::uint8_t> parts[2] = {fixed, tile_bytes};
  std::array<std::uint8_t, kHeaderSize> header;
  if (Status s = make_header(MessageType::tile_data, flags, request_id, parts, limits, header);
      !s)
    return s;
  std::copy(header.begin(), header.end(), out.begin());
  std::copy(fixed.begin(), fixed.end(), out.begin() + kHeaderSize);
  return {};
}

}  // namespace st::proto

namespace st::proto {
namespace {

// GF(2) polynomial arithmetic modulo the reflected CRC-32 polynomial (zlib 1.2.12's
// crc32.c: multmodp, x2nmodp): a * b modulo p, bit 31 being x^0.
std::uint32_t mult_mod_p(std::uint32_t a, std::uint32_t b) {
  std::uint32_t m = 1u << 31, p = 0;
  for (;;) {
    if (a & m) {
      p ^= b;
      if ((a & (m - 1)) == 0) break;
    }
    m >>= 1;
    b = b & 1 ? (b >> 1) ^ 0xedb88320u : b >> 1;
  }
  return p;
}

// x^(2^k) modulo p for k = 0..31.
const std::array<std::uint32_t, 32>& x2n_table() {
  static const std::array<std::uint32_t, 32> t = [] {
    std::array<std::uint32_t, 32> r{};
    std::uint32_t p = 1u << 30;  // x^1
    for (auto& e : r) {
      e = p;
      p = mult_mod_p(p, p);
    }
    return r;
  }();
  return t;
}

}  // namespace

std::uint32_t crc32_combine(std::uint32_t crc_a, std::uint32_t crc_b, std::uint64_t len_b) {
  // crc(A||B) = crc(A) * x^(8 len_b) + crc(B) (the pre- and post-conditioning cancel).
  std::uint32_t p = 1u << 31;  // x^0
  unsigned k = 3;              // x^(8n) = x^(2^3 n)
  for (std::uint64_t n = len_b; n; n >>= 1, ++k)
    if (n & 1) p = mult_mod_p(x2n_table()[k & 31], p);
  return mult_mod_p(p, crc_a) ^ crc_b;
}

Status encode_tile_data_prefix(const TileMeta& meta, std::uint32_t tile_size, std::uint32_t tile_crc32,
                               std::uint32_t request_id, std::uint8_t flags, const Limits& limits,
                               std::array<std::uint8_t, kTileDataPrefixBytes>& out) {
  if (Status s = check_tile(meta, tile_size); !s) return s;
  if (std::uint64_t(tile_size) + kTileMetaBytes > limits.max_payload_bytes())
    return Status::fail(ErrorCode::tile_too_large,
                        "tile " + std::to_string(meta.tile_id) + " of " + std::to_string(tile_size) +
                            " bytes does not fit max_frame_bytes " + std::to_string(limits.max_frame_bytes));
  if ((flags & ~kKnownFlags) != 0)
    return Status::fail(ErrorCode::bad_flags, "flags have reserved bits set");
  std::array<std::uint8_t, kTileMetaBytes> fixed{};
  {
    std::vector<std::uint8_t> buf;
    buf.reserve(kTileMetaBytes);
    Writer w(buf);
    write_meta(w, meta, tile_size);
    std::copy(buf.begin(), buf.end(), fixed.begin());
  }
  FrameHeader h;
  h.flags = flags;
  h.type = MessageType::tile_data;
  h.request_id = request_id;
  h.payload_length = std::uint32_t(kTileMetaBytes + tile_size);
  h.payload_crc32 = crc32_combine(crc32(fixed), tile_crc32, tile_size);
  std::array<std::uint8_t, kHeaderSize> header{};
  write_header(h, header);
  std::copy(header.begin(), header.end(), out.begin());
  std::copy(fixed.begin(), fixed.end(), out.begin() + kHeaderSize);
  return {};
}

}  // namespace st::proto

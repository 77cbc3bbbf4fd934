// The rules each message's fields obey (PROTOCOL.md §4), checked by the encoder before
// writing and by the decoder after reading: one definition, so encode and decode can
// never disagree about what is valid.
#include "proto/message_rules.hpp"

#include <algorithm>
#include <string>
#include <string_view>
#include <unordered_set>

#include "proto/names.hpp"

namespace st::proto::detail {
namespace {

Status bad(const char* msg, ErrorCode code, const std::string& what) {
  return Status::fail(code, std::string(msg) + ": " + what);
}

// Prefixes a rule failure from names.hpp with the message and field.
Status in(const char* msg, const std::string& field, Status s) {
  if (!s) s.detail = std::string(msg) + ": " + field + ": " + s.detail;
  return s;
}

std::string idx(const char* field, std::size_t i) {
  return std::string(field) + "[" + std::to_string(i) + "]";
}

Status check_limits_fields(const char* msg, std::uint8_t min_v, std::uint8_t max_v,
                           std::uint16_t in_flight, std::uint32_t frame_bytes,
                           std::uint16_t batch) {
  Limits l;
  l.min_version = min_v;
  l.max_version = max_v;
  l.max_in_flight = in_flight;
  l.max_frame_bytes = frame_bytes;
  l.max_tiles_per_batch = batch;
  Status s = validate(l);
  if (!s) s.detail = std::string(msg) + ": " + s.detail;
  return s;
}

template <class Items, class NameOf>
Status check_unique_names(const char* msg, const char* field, const Items& items,
                          NameOf name_of) {
  std::unordered_set<std::string_view> seen;
  seen.reserve(items.size());
  for (std::size_t i = 0; i < items.size(); ++i) {
    const std::string_view name = name_of(items[i]);
    if (Status s = validate_map_name(name); !s) return in(msg, idx(field, i) + ".name", s);
    if (!seen.insert(name).second)
      return bad(msg, ErrorCode::invalid_field,
                 idx(field, i) + ".name '" + std::string(name) + "' appears twice");
  }
  return {};
}

}  // namespace

Status check(const Hello& m, const Limits&) {
  Status s = check_limits_fields("hello", m.min_version, m.max_version, m.max_in_flight,
                                 m.max_frame_bytes, m.max_tiles_per_batch);
  if (!s) return s;
  return in("hello", "client_name", validate_text(m.client_name, kMaxLabelBytes, "text"));
}

Status check(const HelloAck& m, const Limits&) {
  Status s = check_limits_fields("hello_ack", m.version, m.version, m.max_in_flight,
                                 m.max_frame_bytes, m.max_tiles_per_batch);
  if (!s) return s;
  return in("hello_ack", "server_name", validate_text(m.server_name, kMaxLabelBytes, "text"));
}

Status check(const ErrorMessage& m, const Limits&) {
  if (m.code == ErrorCode::ok) return bad("error", ErrorCode::invalid_field, "code is 0 (ok)");
  return in("error", "message", validate_text(m.message, kMaxErrorMessageBytes, "text"));
}

Status check(const ListMaps&, const Limits&) { return {}; }
Status check(const GetStats&, const Limits&) { return {}; }
Status check(const Ping&, const Limits&) { return {}; }
Status check(const Pong&, const Limits&) { return {}; }
Status check(const Auth&, const Limits&) { return {}; }
Status check(const AuthOk&, const Limits&) { return {}; }

Status check(const MapList& m, const Limits&) {
  if (m.maps.size() > kMaxMapsListed)
    return bad("map_list", ErrorCode::limit_exceeded,
               std::to_string(m.maps.size()) + " maps exceed " + std::to_string(kMaxMapsListed));
  if (Status s = check_unique_names("map_list", "maps", m.maps,
                                    [](const MapEntry& e) -> std::string_view { return e.name; });
      !s)
    return s;
  for (std::size_t i = 0; i < m.maps.size(); ++i) {
    const MapEntry& e = m.maps[i];
    if (e.resolution_log2 > kMaxResolutionLog2)
      return bad("map_list", ErrorCode::invalid_field,
                 idx("maps", i) + ".resolution_log2 " + std::to_string(e.resolution_log2) +
                     " > " + std::to_string(kMaxResolutionLog2));
    if (e.skip_level > e.resolution_log2)
      return bad("map_list", ErrorCode::invalid_field,
                 idx("maps", i) + ".skip_level " + std::to_string(e.skip_level) +
                     " > resolution_log2 " + std::to_string(e.resolution_log2));
  }
  return {};
}

Status check(const OpenMap& m, const Limits&) {
  return in("open_map", "name", validate_map_name(m.name));
}

Status check(const MapInfo& m, const Limits&) {
  if (m.map_id == 0) return bad("map_info", ErrorCode::invalid_field, "map_id is 0");
  return {};
}

Status check(const GetTiles& m, const Limits& limits) {
  if (m.map_id == 0) return bad("get_tiles", ErrorCode::invalid_field, "map_id is 0");
  if (m.tiles.empty()) return bad("get_tiles", ErrorCode::invalid_field, "no tiles");
  if (m.tiles.size() > limits.max_tiles_per_batch)
    return bad("get_tiles", ErrorCode::limit_exceeded,
               std::to_string(m.tiles.size()) + " tiles exceed max_tiles_per_batch " +
                   std::to_string(limits.max_tiles_per_batch));
  std::unordered_set<std::uint64_t> seen;
  seen.reserve(m.tiles.size());
  for (std::size_t i = 0; i < m.tiles.size(); ++i)
    if (!seen.insert(m.tiles[i].tile_id).second)
      return bad("get_tiles", ErrorCode::invalid_field,
                 idx("tiles", i) + ".tile_id " + std::to_string(m.tiles[i].tile_id) +
                     " appears twice");
  return {};
}

Status check_tile(const TileMeta& meta, std::size_t payload_size) {
  if (meta.map_id == 0) return bad("tile_data", ErrorCode::invalid_field, "map_id is 0");
  if ((meta.flags & ~kKnownTileFlags) != 0)
    return bad("tile_data", ErrorCode::invalid_field,
               "flags " + std::to_string(meta.flags) + " has reserved bits (2..15) set");
  if ((meta.flags & kTileFlagZlib) == 0 && meta.uncompressed_size != payload_size)
    return bad("tile_data", ErrorCode::invalid_field,
               "raw tile (flags bit 0 clear) of " + std::to_string(payload_size) +
                   " bytes has uncompressed_size " + std::to_string(meta.uncompressed_size));
  return {};
}

Status check(const TileData& m, const Limits&) { return check_tile(m.meta, m.payload.size()); }

Status check(const TileError& m, const Limits&) {
  if (m.map_id == 0) return bad("tile_error", ErrorCode::invalid_field, "map_id is 0");
  if (m.code == ErrorCode::ok)
    return bad("tile_error", ErrorCode::invalid_field, "code is 0 (ok)");
  return in("tile_error", "message", validate_text(m.message, kMaxErrorMessageBytes, "text"));
}

std::size_t max_cancel_tiles(const Limits& l) {
  return std::min<std::size_t>(0xffff, std::size_t(l.max_in_flight) * l.max_tiles_per_batch);
}

Status check(const Cancel& m, const Limits& limits) {
  if (m.request_ids.empty() && m.tile_ids.empty())
    return bad("cancel", ErrorCode::invalid_field, "cancels nothing");
  if (m.request_ids.size() > limits.max_in_flight)
    return bad("cancel", ErrorCode::limit_exceeded,
               std::to_string(m.request_ids.size()) + " request ids exceed max_in_flight " +
                   std::to_string(limits.max_in_flight));
  if (m.tile_ids.size() > max_cancel_tiles(limits))
    return bad("cancel", ErrorCode::limit_exceeded,
               std::to_string(m.tile_ids.size()) + " tile ids exceed " +
                   std::to_string(max_cancel_tiles(limits)));
  for (std::size_t i = 0; i < m.request_ids.size(); ++i)
    if (m.request_ids[i] == kNoRequest)
      return bad("cancel", ErrorCode::invalid_field, idx("request_ids", i) + " is 0");
  if (m.tile_ids.empty() != (m.map_id == 0))
    return bad("cancel", ErrorCode::invalid_field,
               "map_id " + std::to_string(m.map_id) + " with " +
                   std::to_string(m.tile_ids.size()) + " tile ids (map_id is 0 iff none)");
  return {};
}

Status check(const Stats& m, const Limits&) {
  if (m.counters.size() > kMaxCounters)
    return bad("stats", ErrorCode::limit_exceeded,
               std::to_string(m.counters.size()) + " counters exceed " +
                   std::to_string(kMaxCounters));
  if (m.histograms.size() > kMaxHistograms)
    return bad("stats", ErrorCode::limit_exceeded,
               std::to_string(m.histograms.size()) + " histograms exceed " +
                   std::to_string(kMaxHistograms));
  if (Status s = check_unique_names("stats", "counters", m.counters,
                                    [](const Counter& c) -> std::string_view { return c.name; });
      !s)
    return s;
  if (Status s = check_unique_names(
          "stats", "histograms", m.histograms,
          [](const Histogram& h) -> std::string_view { return h.name; });
      !s)
    return s;
  for (std::size_t i = 0; i < m.histograms.size(); ++i) {
    const auto& b = m.histograms[i].buckets;
    if (b.empty() || b.size() > kMaxHistogramBuckets)
      return bad("stats", ErrorCode::invalid_field,
                 idx("histograms", i) + " has " + std::to_string(b.size()) +
                     " buckets, expected 1.." + std::to_string(kMaxHistogramBuckets));
    for (std::size_t j = 1; j < b.size(); ++j)
      if (b[j].upper_bound <= b[j - 1].upper_bound)
        return bad("stats", ErrorCode::invalid_field,
                   idx("histograms", i) + "." + idx("buckets", j) +
                       ".upper_bound does not increase");
  }
  return {};
}

}  // namespace st::proto::detail

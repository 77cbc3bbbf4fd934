// Names and directions of the format constants in wire_format.hpp.
#include "proto/wire_format.hpp"

namespace st::proto {

bool is_known_type(std::uint16_t type) {
  switch (static_cast<MessageType>(type)) {
    case MessageType::hello:
    case MessageType::hello_ack:
    case MessageType::error:
    case MessageType::list_maps:
    case MessageType::map_list:
    case MessageType::open_map:
    case MessageType::map_info:
    case MessageType::get_tiles:
    case MessageType::tile_data:
    case MessageType::tile_error:
    case MessageType::cancel:
    case MessageType::ping:
    case MessageType::pong:
    case MessageType::get_stats:
    case MessageType::stats:
    case MessageType::auth:
    case MessageType::auth_ok:
      return true;
  }
  return false;
}

Sender sender_of(MessageType type) {
  switch (type) {
    case MessageType::hello:
    case MessageType::list_maps:
    case MessageType::open_map:
    case MessageType::get_tiles:
    case MessageType::cancel:
    case MessageType::get_stats:
    case MessageType::auth:
      return Sender::client;
    case MessageType::hello_ack:
    case MessageType::map_list:
    case MessageType::map_info:
    case MessageType::tile_data:
    case MessageType::tile_error:
    case MessageType::stats:
    case MessageType::auth_ok:
      return Sender::server;
    case MessageType::error:
    case MessageType::ping:
    case MessageType::pong:
      return Sender::both;
  }
  return Sender::both;
}

std::string_view to_string(MessageType type) {
  switch (type) {
    case MessageType::hello: return "hello";
    case MessageType::hello_ack: return "hello_ack";
    case MessageType::error: return "error";
    case MessageType::list_maps: return "list_maps";
    case MessageType::map_list: return "map_list";
    case MessageType::open_map: return "open_map";
    case MessageType::map_info: return "map_info";
    case MessageType::get_tiles: return "get_tiles";
    case MessageType::tile_data: return "tile_data";
    case MessageType::tile_error: return "tile_error";
    case MessageType::cancel: return "cancel";
    case MessageType::ping: return "ping";
    case MessageType::pong: return "pong";
    case MessageType::get_stats: return "get_stats";
    case MessageType::stats: return "stats";
    case MessageType::auth: return "auth";
    case MessageType::auth_ok: return "auth_ok";
  }
  return "unknown";
}

std::string_view to_string(ErrorCode code) {
  switch (code) {
    case ErrorCode::ok: return "ok";
    case ErrorCode::bad_magic: return "bad_magic";
    case ErrorCode::unsupported_version: return "unsupported_version";
    case ErrorCode::header_checksum: return "header_checksum";
    case ErrorCode::payload_checksum: return "payload_checksum";
    case ErrorCode::oversized_frame: return "oversized_frame";
    case ErrorCode::unknown_type: return "unknown_type";
    case ErrorCode::unexpected_type: return "unexpected_type";
    case ErrorCode::bad_flags: return "bad_flags";
    case ErrorCode::truncated: return "truncated";
    case ErrorCode::trailing_bytes: return "trailing_bytes";
    case ErrorCode::invalid_field: return "invalid_field";
    case ErrorCode::limit_exceeded: return "limit_exceeded";
    case ErrorCode::bad_map_name: return "bad_map_name";
    case ErrorCode::too_many_in_flight: return "too_many_in_flight";
    case ErrorCode::duplicate_request_id: return "duplicate_request_id";
    case ErrorCode::unknown_map: return "unknown_map";
    case ErrorCode::unknown_map_id: return "unknown_map_id";
    case ErrorCode::unknown_tile: return "unknown_tile";
    case ErrorCode::tile_too_large: return "tile_too_large";
    case ErrorCode::cancelled: return "cancelled";
    case ErrorCode::internal: return "internal";
    case ErrorCode::shutting_down: return "shutting_down";
    case ErrorCode::overloaded: return "overloaded";
    case ErrorCode::timeout: return "timeout";
    case ErrorCode::handshake_required: return "handshake_required";
    case ErrorCode::auth_required: return "auth_required";
    case ErrorCode::auth_failed: return "auth_failed";
  }
  return "unknown";
}

}  // namespace st::proto

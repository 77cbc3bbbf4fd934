// Internal to proto (not installed: the one public header is the client's): the
// per-message rule checks shared by encoders and decoders (message_rules.cpp).
#pragma once
#include <cstddef>

#include "proto/limits.hpp"
#include "proto/messages.hpp"
#include "proto/status.hpp"

namespace st::proto::detail {

// ok, or the first broken rule as a typed Status naming message, field and index.
Status check(const Hello& m, const Limits& limits);
Status check(const HelloAck& m, const Limits& limits);
Status check(const Auth& m, const Limits& limits);
Status check(const AuthOk& m, const Limits& limits);
Status check(const ErrorMessage& m, const Limits& limits);
Status check(const ListMaps& m, const Limits& limits);
Status check(const MapList& m, const Limits& limits);
Status check(const OpenMap& m, const Limits& limits);
Status check(const MapInfo& m, const Limits& limits);
Status check(const GetTiles& m, const Limits& limits);
Status check(const TileData& m, const Limits& limits);
Status check(const TileError& m, const Limits& limits);
Status check(const Cancel& m, const Limits& limits);
Status check(const Ping& m, const Limits& limits);
Status check(const Pong& m, const Limits& limits);
Status check(const GetStats& m, const Limits& limits);
Status check(const Stats& m, const Limits& limits);

// TileData's rules on the fixed fields alone (for the zero-copy paths).
Status check_tile(const TileMeta& meta, std::size_t payload_size);

// Most tile ids one Cancel may name: every tile that can be outstanding, capped by u16.
std::size_t max_cancel_tiles(const Limits& limits);

}  // namespace st::proto::detail

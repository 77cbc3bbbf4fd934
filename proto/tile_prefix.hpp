// The TileData prefix (frame header + TileMeta) for a sender that already knows the CRC-32
// of the tile bytes, as a tile server does from its pack index: the frame's payload CRC
// (PROTOCOL.md §3, over TileMeta then the tile bytes) is combined from the TileMeta's CRC
// and the tile's, so the tile bytes are not read again for every frame that carries them.
#pragma once
#include <array>
#include <cstdint>

#include "proto/messages.hpp"

namespace st::proto {

// CRC-32 (IEEE, as crc32() in frame.hpp) of A followed by B, from crc(A), crc(B) and B's
// length alone (zlib's crc32_combine: multiply by x^(8 len_b) modulo the polynomial).
std::uint32_t crc32_combine(std::uint32_t crc_a, std::uint32_t crc_b, std::uint64_t len_b);

// Same bytes and failures as encode_tile_data_prefix(meta, tile_bytes, ...) when
// tile_size == tile_bytes.size() and tile_crc32 == crc32(tile_bytes). The caller vouches
// for the CRC: a wrong one makes the receiver reject the frame (ErrorCode::payload_checksum).
Status encode_tile_data_prefix(const TileMeta& meta, std::uint32_t tile_size, std::uint32_t tile_crc32,
                               std::uint32_t request_id, std::uint8_t flags, const Limits& limits,
                               std::array<std::uint8_t, kTileDataPrefixBytes>& out);

}  // namespace st::proto

// Deep tiles in a pack (tiles/PACK.md "Deep tiles"; DSM 2000 §5.4): the deep map of a
// scene's partial occluders rides in the same pack as its opaque map. The pack's tile
// index holds one deep directory (kind deep_directory, id kDeepDirectoryId) and the deep
// tiles (kind deep, id kDeepTileIdBit | tile id of the tile's root node at level D - b),
// stored zlib-compressed behind tile records like every other tile.
//
// Deep directory (raw bytes, little-endian; pinned by deep_pack_test):
//   0  u32 magic            "DSMD" (0x444D5344)
//   4  u32 version          1
//   8  u32 header_bytes     32
//  12  u32 level D          the deep map is 2^D texels a side, D <= 20
//  16  u32 side_bits b      deep tiles are 2^b texels a side: b <= min(D, 8), D - b <= 10
//  20  u32 tile_count n     deep tiles stored, 1 <= n = popcount(bitmap)
//  24  f32 epsilon          the compression bound of mip 0 (finite, >= 0)
//  28  u32 samples          jittered samples per texel side (1..64; provenance)
//  32  bitmap               ceil(4^(D-b) / 8) bytes: bit i (byte i >> 3, bit i & 7) is
//                           tile (tx, ty) with i = ty * 2^(D-b) + tx; bits past 4^(D-b) zero
// A tile whose bit is clear is not stored and answers transmittance 1.
//
// The deep map covers the same light-space image plane as the opaque map (the same
// LightSpace, header bytes 40..183), at its own level D; lookups take map coordinates
// (u, v) in [0, 1) and a light-space depth (deep_map.hpp).
#pragma once
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/pack_format.hpp"

namespace st {

namespace deep {
inline constexpr uint32_t kDirectoryMagic = 0x444D5344;  // "DSMD"; format constant
inline constexpr uint32_t kDirectoryVersion = 1;         // format constant
inline constexpr uint32_t kDirectoryHeaderBytes = 32;    // format constant
inline constexpr uint32_t kMaxTilesPerSideBits = 10;     // D - b <= 10; format constant
}  // namespace deep

struct DeepDirectory {
  uint32_t level = 0, side_bits = 0;
  float epsilon = 0;
  uint32_t samples_per_side = 1;
  std::vector<uint8_t> bitmap;  // ceil(4^(level - side_bits) / 8) bytes

  uint32_t tiles_per_side_bits() const { return level - side_bits; }
  uint32_t tiles_per_side() const { return 1u << (level - side_bits); }
  static size_t bitmap_bytes(uint32_t per_side_bits) { return ((size_t(1) << (2 * per_side_bits)) + 7) / 8; }
  bool has(uint32_t tx, uint32_t ty) const {
    const size_t i = size_t(ty) * tiles_per_side() + tx;
    return (bitmap[i >> 3] >> (i & 7)) & 1;
  }
  void set(uint32_t tx, uint32_t ty) {
    const size_t i = size_t(ty) * tiles_per_side() + tx;
    bitmap[i >> 3] = uint8_t(bitmap[i >> 3] | (1u << (i & 7)));
  }
  uint64_t tile_count() const;  // popcount of the bitmap
  // The pack id of tile (tx, ty).
  uint64_t tile_id(uint32_t tx, uint32_t ty) const;

  // An empty directory (no tile) of this shape; st::Error for a shape the format refuses.
  static DeepDirectory make(uint32_t level, uint32_t side_bits, float epsilon, uint32_t samples_per_side);
  std::vector<uint8_t> serialize() const;
  // Validates every field (st::FormatError naming `what` and the field at fault).
  static DeepDirectory parse(std::span<const uint8_t> bytes, const std::string& what);
};

}  // namespace st

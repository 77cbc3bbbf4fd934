// Deep shadow tile format, version 1 (deep shadow maps, Lokovic and Veach 2000, DSM 2000
// §3.3-§3.4, §5.2-§5.4): one tile's compressed visibility functions, a square block of
// 2^side_bits texels a side, with every mip level of the block (§5.3: a texel of mip m+1
// is the average of its 2x2 children, recompressed). tiles/core/DEEP.md draws the layout
// and states the error contract; tests/tiles/deep_tile_test.cpp pins every offset below.
//
// Every constant marked "format constant" is part of the on-disk layout: changing one
// changes kVersion.
#pragma once
#include <cstddef>
#include <cstdint>

namespace st::deep {

inline constexpr uint32_t kMagic = 0x544D5344;  // "DSMT" little-endian; format constant
inline constexpr uint32_t kVersion = 1;         // format constant
inline constexpr uint32_t kHeaderBytes = 48;    // format constant
inline constexpr uint32_t kMaxSideBits = 8;     // at most 256 x 256 texels at mip 0; format constant
inline constexpr uint32_t kMaxVertices = 65535; // per texel (uint16 count); format constant
// Transmittance is stored as unorm16: value = stored / 65535 (format constant). Rounding
// to nearest adds at most kQuantisation to a function's error and keeps it nonincreasing.
inline constexpr double kUnormScale = 65535.0;
inline constexpr double kQuantisation = 0.5 / kUnormScale;
// Lookups read a stored q as float(q) * kUnormInverse (the float nearest 1 / 65535, bits
// 0x37800080; 65535 * it is exactly 1): within one float ulp of q / 65535.
inline constexpr float kUnormInverse = 1.0f / 65535.0f;

// Lookups read depths (stored and asked) of magnitude below 2^-103 as 0 (deep_tile.cpp
// flush_depth; the shader's st_deep_flush), so CPU and GPU lookups agree bit for bit.
inline constexpr float kDepthFlushBelow = 0x1p-103f;

// A receiver's deep lookup point: the surface point moved toward the light along the
// light ray by this many texels of the deep level (render/render.hpp
// deep_lookup_point says why; gpu/ writes it into the GPU's deep block). Not a format
// constant.
inline constexpr double kLookupBiasTexels = 1.5;

// Directory entry flags (format constants).
inline constexpr uint8_t kFlagMonochrome = 1;  // one channel stored (DSM 2000 §5.2)

// Header: 48 bytes, little-endian, at byte 0.
struct Header {
  uint32_t magic;             //  0 kMagic
  uint32_t version;           //  4 kVersion
  uint32_t header_bytes;      //  8 = 48
  uint32_t side_bits;         // 12 b <= kMaxSideBits: mip 0 is 2^b x 2^b texels
  uint32_t mip_count;         // 16 = b + 1 (mip b is one texel)
  uint32_t texel_count;       // 20 = sum over m of 4^(b - m)
  uint32_t directory_offset;  // 24 = 48
  uint32_t data_offset;       // 28 = 48 + 8 * texel_count
  uint32_t data_bytes;        // 32 = the sum of every texel's padded block
  uint32_t total_bytes;       // 36 = data_offset + data_bytes = the buffer's length
  float epsilon;              // 40 compression bound of mip 0, finite, >= 0 (informational)
  uint32_t reserved;          // 44 = 0
};
static_assert(sizeof(Header) == kHeaderBytes);
static_assert(offsetof(Header, side_bits) == 12);
static_assert(offsetof(Header, epsilon) == 40);

// Directory: one 8-byte entry per texel, mip 0 first, each mip row-major.
struct DirEntry {
  uint32_t offset;        // 0 bytes from data_offset to the texel's block, a multiple of 4
  uint16_t vertex_count;  // 4 n <= kMaxVertices; 0: fully lit (transmittance 1)
  uint8_t flags;          // 6 kFlagMonochrome or 0
  uint8_t reserved;       // 7 = 0
};
static_assert(sizeof(DirEntry) == 8);
static_assert(offsetof(DirEntry, vertex_count) == 4);

// A texel's block: float32 depth[n], then uint16 value[n * c] (c = 1 monochrome, else
// 3, interleaved r g b per vertex), zero-padded to a multiple of 4 bytes. Blocks follow
// each other in directory order without gaps (one canonical layout).
inline constexpr uint32_t block_bytes(uint32_t n, bool mono) {
  const uint32_t raw = 4 * n + 2 * n * (mono ? 1 : 3);
  return (raw + 3) & ~3u;
}

inline constexpr uint32_t mip_side(uint32_t side_bits, uint32_t mip) { return 1u << (side_bits - mip); }
// Index of mip m's first texel in the directory.
inline constexpr uint32_t mip_base(uint32_t side_bits, uint32_t mip) {
  uint32_t base = 0;
  for (uint32_t k = 0; k < mip; ++k) base += mip_side(side_bits, k) * mip_side(side_bits, k);
  return base;
}
inline constexpr uint32_t texel_count(uint32_t side_bits) { return mip_base(side_bits, side_bits + 1); }
static_assert(texel_count(0) == 1 && texel_count(1) == 5 && texel_count(8) == 87381);

}  // namespace st::deep

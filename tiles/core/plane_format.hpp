// Plane tiles (tiles/core/PLANES.md): a tile whose finest texels are, block by block, the
// depths of one plane each, stores those blocks as planes and the rest of its subtree in
// an inner DAG-MH, MMH or MH buffer. Layout (every constant here is a format constant:
// changing one changes the bytes on disk, so bump kVersion):
//
//   offset     size  field
//   0          4     magic        "STPN", bytes in that order
//   4          2     version      kVersion
//   6          1     levels       the tile's finest level + 1 (1..kMaxLevels); the inner
//                                 buffer has the same finest level
//   7          1     flags        zero (no flag is defined)
//   8          4     plane_count  P (1..kMaxPlanes)
//   12         4     byte_size    whole buffer, header, planes and inner buffer included
//   16         32*P  planes       sorted by `start`, disjoint (below)
//   16+32P     rest  inner        the inner buffer (its own magic: DAG-MH, MMH or MH)
//
// Plane record (32 bytes, all little-endian):
//   0  u32 start   finest-level morton code of the block's first texel; a multiple of
//                  4^shift (the block is an aligned square of the tile)
//   4  u32 shift   log2 of the block's side, kMinShift..kMaxShift, <= the tile's finest level
//   8  i64 a       depth in units of 2^-kFracBits at the block's first texel
//   16 i64 b       step per texel along x, |b| <= kMaxSlope
//   24 i64 c       step per texel along y, |c| <= kMaxSlope
//
// Depth of a finest texel (x, y) of the block, (x, y) relative to the block's corner
// (0 <= x, y < 2^shift): v = a + b x + c y in 64-bit integers (no overflow: |a| <= kMaxBase
// and the bounds above keep |v| < 2^62), then plane_fixed_to_float(v): v <= 0 gives 0, v >=
// 2^kFracBits gives 1, otherwise v 2^-kFracBits rounded to the nearest binary32, ties to
// even, computed with integer operations only. Nothing in the evaluation is a floating-point
// operation, so the CPU and every GPU (shadowtile.glsl's st_plane_depth, 32-bit words) answer
// the same bits; the encoder verifies each texel it gives to a plane with these functions.
// A texel of a coarser level l inside a block (the block is finer than l: finest - l <
// shift) answers the plane at its central finest texel ((x << s) + h, (y << s) + h),
// s = finest - l, h = s ? 2^(s-1) : 0; any other lookup answers the inner buffer.
#pragma once
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace st::planes {

inline constexpr uint32_t kMagic = 0x4E505453u;  // bytes "STPN"
inline constexpr uint16_t kVersion = 1;
inline constexpr uint32_t kMaxLevels = 17;  // finest level <= 16: starts fit 32 bits
inline constexpr size_t kOffMagic = 0, kOffVersion = 4, kOffLevels = 6, kOffFlags = 7;
inline constexpr size_t kOffPlaneCount = 8, kOffByteSize = 12, kHeaderSize = 16;
inline constexpr size_t kRecordSize = 32;
inline constexpr size_t kOffStart = 0, kOffShift = 4, kOffA = 8, kOffB = 16, kOffC = 24;
inline constexpr uint32_t kMinShift = 2, kMaxShift = 8;
inline constexpr uint32_t kMaxPlanes = 1u << 20;
inline constexpr uint32_t kFracBits = 60;
inline constexpr int64_t kOne = int64_t(1) << kFracBits;
inline constexpr int64_t kMaxBase = int64_t(1) << 61;
inline constexpr int64_t kMaxSlope = int64_t(1) << 52;

// v 2^-60 as binary32 (see above). Integer operations only, mirrored by shadowtile.glsl.
inline float plane_fixed_to_float(int64_t v) {
  if (v <= 0) return 0.0f;
  if (v >= kOne) return 1.0f;
  const uint64_t u = uint64_t(v);
  const int p = 63 - std::countl_zero(u);  // 0..59
  uint64_t m;
  if (p <= 23) {
    m = u << (23 - p);
  } else {
    const int k = p - 23;
    m = u >> k;
    const uint64_t rem = u & ((uint64_t(1) << k) - 1), half = uint64_t(1) << (k - 1);
    if (rem > half || (rem == half && (m & 1))) ++m;  // ties to even; m may reach 2^24
  }
  // m in [2^23, 2^24]: 2^24 carries into the exponent, as the float's next binade.
  const uint32_t bits = (uint32_t(p - int(kFracBits) + 127) << 23) + uint32_t(m - (uint64_t(1) << 23));
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

struct Plane {
  uint32_t start = 0, shift = 0;
  int64_t a = 0, b = 0, c = 0;
  // Texel (x, y) relative to the block's corner; wraps modulo 2^64 like the GPU's
  // 32-bit word pairs (never in a validated buffer).
  int64_t fixed(uint32_t x, uint32_t y) const {
    return int64_t(uint64_t(a) + uint64_t(b) * uint64_t(x) + uint64_t(c) * uint64_t(y));
  }
  float depth(uint32_t x, uint32_t y) const { return plane_fixed_to_float(fixed(x, y)); }
};

}  // namespace st::planes

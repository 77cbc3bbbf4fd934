// Plane tiles (tiles/core/PLANES.md): a tile whose finest texels are, block by block, the
// depths of one plane each, stores those blocks as references into a table of the tile's
// planes and the rest of its subtree in an inner DAG-MH, MMH or MH buffer. Blocks on one
// surface share one table entry, so a block costs 8 bytes and a plane 24. An 8x8 block
// across an edge of a few planes (a labelled block) names up to 4 table planes and, per
// texel, which of them answers it (24 more bytes). Layout (every
// constant here is a format constant: changing one changes the bytes on disk, so bump
// kVersion):
//
//   offset        size  field
//   0             4     magic        "STPN", bytes in that order
//   4             2     version      kVersion (3: wide labelled blocks) or 2 (none); version
//                                    1 had a plane per block
//   6             1     levels       the tile's finest level + 1 (1..kMaxLevels); the inner
//                                    buffer has the same finest level
//   7             1     flags        zero (no flag is defined)
//   8             4     block_count  B (1..kMaxPlanes)
//   12            4     byte_size    whole buffer, header, table, blocks and inner buffer
//   16            4     table_count  T (1..kMaxTable)
//   20            4     label_count  L (0..kMaxTable): labels section slots (a labelled block
//                                    one, a wide one two)
//   24            24*T  table        planes (a, b, c) of the tile (below)
//   24+24T        8*B   blocks       sorted by `start`, disjoint (below)
//   24+24T+8B     24*L  labels       the labelled blocks' palettes and labels (below)
//   24+24T+8B+24L rest  inner        the inner buffer (its own magic: DAG-MH, MMH or MH)
//
// Table entry (24 bytes, all little-endian), in units of 2^-kFracBits:
//   0  i64 a       depth at the tile's texel (0, 0) (any value: the sum wraps, below)
//   8  i64 b       step per texel along x, |b| <= kMaxSlope
//   16 i64 c       step per texel along y, |c| <= kMaxSlope
// Block record (8 bytes):
//   0  u32 start   finest-level morton code of the block's first texel; a multiple of
//                  4^shift (the block is an aligned square of the tile)
//   4  u8  shift   log2 of the block's side, kMinShift..kMaxShift, <= the tile's finest level
//   5  u8  kind    kKindPlane: one plane answers the block; kKindLabels: a labelled block
//                  (shift kLabelShift), its texels answered by the planes their labels name;
//                  kKindWide (version 3): a wide labelled block (8 planes, 3-bit labels)
//   6  u16 index   kKindPlane: index into the table, < T; kKindLabels, kKindWide: the slot of
//                  the labels section (24 bytes a slot) where the block starts, < L
// Labelled block (24 bytes): 0 four u16 palette entries, each < T; 8 sixteen bytes of
//   2-bit labels, texel (x, y) of the block (i = 8 y + x) in bits 2 (i mod 4) .. +1 of byte
//   i / 4: its plane is palette[label] (unused palette entries repeat a used one).
// Wide labelled block (version 3, record kind kKindWide, shift kLabelShift; two consecutive
//   24-byte slots of the labels section, the record's index naming the first; 48 bytes):
//   0 eight u16 palette entries, each < T; 16 three 8-byte bit planes of 3-bit labels, bit k
//   of texel i's label in bit i mod 8 of byte 16 + 8 k + i / 8; 40 eight zero bytes. The
//   labels section's slots are taken in the order of the records (a labelled block one, a
//   wide one two), so L counts slots. Version 2 tiles (no wide block) read unchanged; the
//   writer writes version 2 when a tile has no wide block.
//
// Depth of a finest texel (x, y) of a block (tile coordinates) whose plane is (a, b, c):
// v = a + b x + c y modulo 2^64, read as a signed 64-bit integer. The validator requires
// the block's own corner value a' = a + b x0 + c y0 (modulo 2^64) to satisfy |a'| <=
// kMaxBase, so that inside the block v = a' + b (x - x0) + c (y - y0) without overflow
// (|v| < 2^62): the same integer whichever way it is summed. Then plane_fixed_to_float(v): v <= 0 gives 0, v >=
// 2^kFracBits gives 1, otherwise v 2^-kFracBits rounded to the nearest binary32, ties to
// even, computed with integer operations only. Nothing in the evaluation is a floating-point
// operation, so the CPU and every GPU (shadowtile.glsl's st_plane_lookup, 32-bit words) answer
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
inline constexpr uint16_t kVersion = 3;
inline constexpr uint16_t kVersionNarrow = 2;  // written when no block is wide; read as version 3
inline constexpr uint32_t kMaxLevels = 17;  // finest level <= 16: starts fit 32 bits
inline constexpr size_t kOffMagic = 0, kOffVersion = 4, kOffLevels = 6, kOffFlags = 7;
inline constexpr size_t kOffPlaneCount = 8, kOffByteSize = 12, kOffTableCount = 16, kOffLabelCount = 20;
inline constexpr size_t kHeaderSize = 24;
inline constexpr size_t kEntrySize = 24, kOffA = 0, kOffB = 8, kOffC = 16;  // table entry
inline constexpr size_t kRecordSize = 8, kOffStart = 0, kOffShift = 4, kOffKind = 5, kOffIndex = 6;  // block
inline constexpr uint8_t kKindPlane = 0, kKindLabels = 1, kKindWide = 2;
inline constexpr uint32_t kLabelShift = 3, kPalette = 4;
inline constexpr size_t kLabelSize = 24, kOffLabelBits = 8;  // labelled block: palette, then labels
// Wide labelled block: two slots, 8 palette entries, 3 bit planes of 8 bytes, 8 zero bytes.
inline constexpr uint32_t kWidePalette = 8, kWideSlots = 2, kWideLabelBits = 3;
inline constexpr size_t kOffWideBits = 16, kOffWidePad = 40, kWideSize = kWideSlots * kLabelSize;
// Texel i's (i = 8 y + x) label in a wide labelled block's bit planes `bits` (its byte 16 on).
inline uint32_t wide_label(const uint8_t* bits, uint32_t i) {
  const uint32_t byte = i / 8, bit = i % 8;
  return uint32_t((bits[byte] >> bit) & 1u) | uint32_t((bits[8 + byte] >> bit) & 1u) << 1 |
         uint32_t((bits[16 + byte] >> bit) & 1u) << 2;
}
inline constexpr uint32_t kMaxTable = 0xFFFFu;
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
  // u's leading one moved to bit 63: its top 24 bits are the significand, the 40 below
  // what rounding drops (all zero when p <= 23). Without a branch on the dropped bits (a
  // lookup's plane depths take either way about half the time).
  const uint64_t w = u << (63 - p);
  uint64_t m = w >> 40;
  const uint64_t rem = w & ((uint64_t(1) << 40) - 1), half = uint64_t(1) << 39;
  m += uint64_t(rem > half) | (uint64_t(rem == half) & m);  // ties to even; m may reach 2^24
  // m in [2^23, 2^24]: 2^24 carries into the exponent, as the float's next binade.
  const uint32_t bits = (uint32_t(p - int(kFracBits) + 127) << 23) + uint32_t(m - (uint64_t(1) << 23));
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

// plane_fixed_to_float's bits from the CPU's own conversion, for the CPU's hot lookups:
// for 0 < v < 2^60, float(v) is v rounded once to binary32, ties to even (the default
// rounding mode), and scaling by 2^-60 is exact (the result stays a normal float), so the
// product is v 2^-60 rounded once, the integer version's answer; at and above 2^60 the
// product is >= 1 and at or below 0 it is <= 0 (+0 for 0), clamped as that version does.
// Tests check both on every binade's rounding cases.
inline float plane_fixed_to_float_cpu(int64_t v) {
  const float f = float(v) * 0x1p-60f;
  return f < 0.0f ? 0.0f : (f > 1.0f ? 1.0f : f);
}

// One block with its plane resolved to the block's corner: a = the table's a + b x0 + c y0.
struct Plane {
  uint32_t start = 0, shift = 0;
  int64_t a = 0, b = 0, c = 0;
  // Texel (x, y) relative to the block's corner; wraps modulo 2^64 like the GPU's
  // 32-bit word pairs (never in a validated buffer).
  int64_t fixed(uint32_t x, uint32_t y) const {
    return int64_t(uint64_t(a) + uint64_t(b) * uint64_t(x) + uint64_t(c) * uint64_t(y));
  }
  float depth(uint32_t x, uint32_t y) const { return plane_fixed_to_float(fixed(x, y)); }
  // The table's a (at the tile's texel (0, 0)) of this block, whose corner is (x0, y0).
  int64_t origin_a(uint32_t x0, uint32_t y0) const {
    return int64_t(uint64_t(a) - uint64_t(b) * uint64_t(x0) - uint64_t(c) * uint64_t(y0));
  }
};

}  // namespace st::planes

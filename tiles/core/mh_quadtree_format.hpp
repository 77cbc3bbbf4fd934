// Byte layout of the MH quadtree (MH §3.2) and of its merged variant MMH, shared by the
// encoders (tiles/encode/mh_quadtree_layout.cpp, mmh_merge.cpp) and the reader (mh_quadtree_reader.cpp).
// The full drawing with examples is in tiles/core/MHQUAD.md; every constant here is a
// format constant: changing one changes the bytes on disk, so bump kVersion.
//
//   offset  size  field
//   0       4     magic        "STMH" (MH) or "STMM" (MMH), bytes in that order
//   4       2     version      kVersion
//   6       1     levels       finest level + 1 (1..21)
//   7       1     flags        bit0 root is a leaf (constant tile); bit1 relative values (MMH)
//   8       4     node_count   nodes stored (a node shared by MMH counts once)
//   12      4     byte_size    whole buffer, header included (== the span's size)
//   16      L     shift[l]     log2 of the child-offset scale of parents at level l (<= 15)
//   16+L    pad   zero bytes up to a multiple of 4
//   T       4*W   tree         W little-endian 32-bit words; the root at word 0
//
// Tree words (word index w is relative to the tree start T; byte = T + 4w):
//   leaf   1 word : float value
//   empty  1 word : node word
//   inner  2 words: node word, float value
//   node word bits  0-7 : child mask, 2 bits per child slot c at bits 2c..2c+1:
//                         00 none, 01 leaf, 10 empty, 11 inner (popcount = size in words)
//                   8-15: MH: zero. MMH: bits 8-11 "absolute" flag of child slot 0..3
//                         (its value is stored as is, not relative), bits 12-15 this
//                         node's offset shift (a merged block is reached from parents at
//                         different levels, so the shift travels with the node)
//                   16-31: child offset `off` (1..65535) in units of 2^shift words
//   children block of a node at word p: starts at ((p >> shift) + off) << shift, its
//   children contiguous in slot order; child slot c lies popcount(mask & ((1<<2c)-1))
//   words in. off >= 1 makes every offset point strictly forward (no cycles in MMH).
//   Words no node covers are alignment padding and must be zero; the last word belongs
//   to a node (no trailing bytes).
//
// Values: MH stores absolute floats (MH §3.2: "we do not encode the depth values using
// parent node differentials"). MMH stores each value relative to the decoded value of the
// nearest valued ancestor unless the parent's absolute flag says otherwise; the decoder
// computes mmh_add(ancestor, stored): one IEEE binary32 addition, round to nearest, no
// contraction possible. The root value is always absolute.
#pragma once
#include <bit>
#include <cfloat>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "common/bytes.hpp"

namespace st::mhq {

static_assert(std::endian::native == std::endian::little, "tree words are little-endian");
// mmh_add must be one binary32 rounding on the encoder (which verifies with it) and the
// reader alike: no excess precision, no value-changing optimizations.
static_assert(FLT_EVAL_METHOD == 0, "float arithmetic must evaluate in float (MMH relative values)");
#if defined(__FAST_MATH__)
#error "tiles/core must not be built with -ffast-math: MMH verifies values with exact float adds"
#endif

inline constexpr uint32_t kMagicMh = 0x484D5453u;   // bytes "STMH"
inline constexpr uint32_t kMagicMmh = 0x4D4D5453u;  // bytes "STMM"
inline constexpr uint16_t kVersion = 1;
inline constexpr uint32_t kMaxLevels = 21;  // finest level <= kMaxLevel (20)

inline constexpr size_t kOffMagic = 0, kOffVersion = 4, kOffLevels = 6, kOffFlags = 7;
inline constexpr size_t kOffNodeCount = 8, kOffByteSize = 12, kOffShifts = 16;
inline constexpr size_t kHeaderFixedSize = 16;

inline constexpr uint8_t kFlagRootLeaf = 1, kFlagRelative = 2, kFlagsKnown = 3;

inline constexpr uint32_t kCodeNone = 0, kCodeLeaf = 1, kCodeEmpty = 2, kCodeInner = 3;
inline constexpr uint32_t kMaxOffset = 0xFFFF;
inline constexpr uint32_t kMaxShift = 15;
// Largest tree the 32-bit byte_size can describe.
inline constexpr uint64_t kMaxBytes = 0xFFFFFFFCull;

// Byte offset of the tree (word 0) for a header of `levels` levels.
inline constexpr size_t tree_offset(uint32_t levels) {
  return kHeaderFixedSize + ((size_t(levels) + 3) & ~size_t(3));
}

inline constexpr uint32_t code_words(uint32_t code) { return code == kCodeInner ? 2 : code != 0; }

inline uint32_t node_word(uint32_t mask, uint32_t pad, uint32_t off) {
  return mask | (pad << 8) | (off << 16);
}
inline uint32_t word_mask(uint32_t w) { return w & 0xFFu; }
inline uint32_t word_pad(uint32_t w) { return (w >> 8) & 0xFFu; }
inline uint32_t word_abs_flags(uint32_t w) { return (w >> 8) & 0xFu; }
inline uint32_t word_shift(uint32_t w) { return (w >> 12) & 0xFu; }
inline uint32_t word_offset(uint32_t w) { return w >> 16; }

// Bit count of an 8-bit mask without a library call (the build has no -mpopcnt).
inline uint32_t popcount8(uint32_t m) {
  m = m - ((m >> 1) & 0x55u);
  m = (m & 0x33u) + ((m >> 2) & 0x33u);
  return (m + (m >> 4)) & 0x0Fu;
}

inline uint32_t child_code(uint32_t mask, uint32_t slot) { return (mask >> (2 * slot)) & 3u; }
// Words before child `slot` in its block: each code's popcount is its size in words.
inline uint32_t child_skip(uint32_t mask, uint32_t slot) {
  return popcount8(mask & ((1u << (2 * slot)) - 1u));
}
inline uint64_t block_start(uint64_t parent_word, uint32_t shift, uint32_t off) {
  return ((parent_word >> shift) + off) << shift;
}

// The MMH decoder's arithmetic, shared with the encoder's verification: one binary32
// add. Kept out of line of any multiply so no compiler may contract it.
inline float mmh_add(float ancestor, float stored) { return ancestor + stored; }

inline uint32_t float_bits(float f) { return std::bit_cast<uint32_t>(f); }
inline float bits_float(uint32_t b) { return std::bit_cast<float>(b); }


}  // namespace st::mhq

// Byte layout and level geometry of the MH octree: a shadow-map stack (MH 2016 §4) as
// one flat buffer. Shared by the builder (tiles/encode/mh_octree_build.*), the encoder
// (tiles/encode/mh_octree_encode.*) and the reader (mh_octree_reader.*). The drawing with
// an example is tiles/core/MHOCT.md; every constant here is a format constant: changing
// one changes the bytes, so bump kVersion.
//
//   offset  size  field
//   0       4     magic       "STOC", bytes in that order
//   4       2     version     kVersion
//   6       1     xy_level    n: slices are 2^n texels a side (0..20)
//   7       1     w_level     k: the stack is padded to 2^k slices (0..12)
//   8       2     slices      N real slices: 2^(k-1) < N <= 2^k (N = 1 when k = 0)
//   10      1     flags       bit0: root is a leaf (1 tree word); other bits zero
//   11      1     reserved    zero
//   12      4     node_count  nodes in the tree
//   16      4     byte_size   whole buffer, header included (== the span's size)
//   20      L     shift[l]    l = 0..L-1, L = max(n, k) + 1 levels: log2 of the child-offset
//                             scale of parents at level l (<= 15)
//   20+L    pad   zero bytes up to a multiple of 4
//   T       4*W   tree        T = 20 + round_up(L, 4); W little-endian words; root at word 0
//
// Tree words: leaf = [float]; empty = [node word]; inner = [node word][float].
//   node word bits 0-15 : child mask, 2 bits per child slot c (0..7) at bits 2c..2c+1:
//                         00 none, 01 leaf, 10 empty, 11 inner (popcount = size in words)
//             bits 16-31: child offset `off`, a signed 16-bit number (two's complement,
//                         -32768..32767, non-zero) in units of 2^shift[level] words. The
//                         block it names is either the node's own children block (after
//                         the node) or, since version 2, a block of equal children stored
//                         earlier in the depth-first order for another node of the same
//                         level (a shared block: identical subtrees stored once, DAG-MH
//                         style), before or after the node
//                         version 3: off in -32768..-32737 (kFarCodes codes) is FAR: for
//                         c = off + 32768 the block starts at the tree word whose index is
//                         the 32-bit far word at p + 1 + c (far words lie right after the
//                         block that holds the node; each is claimed by one node only), so
//                         a shared block any distance away is reached without a copy
//   The children block of a node at word p starts at ((p >> s) + off) << s (or at its
//   far word's value, child_block); child slot c
//   lies popcount(mask & ((1 << 2c) - 1)) words in. With 16-bit masks a node word has no
//   pad byte (MH §4: octree nodes are 4-byte aligned by default).
#pragma once
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "common/bit_count.hpp"

namespace st::moct {

static_assert(std::endian::native == std::endian::little, "tree words are little-endian");

inline constexpr uint32_t kMagic = 0x434F5453u;  // bytes "STOC"
inline constexpr uint16_t kVersion = 3;  // 1: forward offsets only; 2: no far words (neither read any more)
inline constexpr uint32_t kMaxXyLevel = 20;  // kMaxLevel (interval.hpp)
inline constexpr uint32_t kMaxWLevel = 12;   // 4096 slices (kMaxLightSamples)
inline constexpr uint32_t kMaxLevels = 21;   // max(n, k) + 1

inline constexpr size_t kOffMagic = 0, kOffVersion = 4, kOffXyLevel = 6, kOffWLevel = 7, kOffSlices = 8,
                        kOffFlags = 10, kOffReserved = 11, kOffNodeCount = 12, kOffByteSize = 16, kOffShifts = 20;
inline constexpr size_t kHeaderFixedSize = 20;
inline constexpr uint8_t kFlagRootLeaf = 1, kFlagsKnown = 1;

inline constexpr uint32_t kCodeNone = 0, kCodeLeaf = 1, kCodeEmpty = 2, kCodeInner = 3;
inline constexpr uint32_t kSlots = 8;  // child slot c = cx | cy << 1 | cw << 2
inline constexpr uint32_t kMaxOffset = 0x7FFF;      // the largest offset forward
// Far offsets (version 3): off in [kFarOffsetMin, kFarOffsetMin + kFarCodes) names a far
// word (a node's block holds at most 8 inner children, 16 words, and 8 far words follow
// it: 32 codes reach every far word of the block from every node of it).
inline constexpr uint32_t kFarCodes = 32;
inline constexpr int32_t kFarOffsetMin = -0x8000;
inline constexpr int32_t kFarLimit = kFarOffsetMin + int32_t(kFarCodes);  // off < kFarLimit: far
inline constexpr uint32_t kMaxBackOffset = 0x8000 - kFarCodes;  // the largest backward (off = -32736)
inline constexpr uint32_t kMaxShift = 15;
inline constexpr uint64_t kMaxBytes = 0xFFFFFFFCull;

inline constexpr size_t tree_offset(uint32_t levels) { return kHeaderFixedSize + ((size_t(levels) + 3) & ~size_t(3)); }
inline constexpr uint32_t code_words(uint32_t code) { return code == kCodeInner ? 2 : code != 0; }
inline uint32_t word_mask(uint32_t w) { return w & 0xFFFFu; }
inline int32_t word_offset(uint32_t w) { return int32_t(int16_t(uint16_t(w >> 16))); }
inline uint32_t node_word(uint32_t mask, int32_t off) { return mask | (uint32_t(uint16_t(int16_t(off))) << 16); }
inline uint32_t child_code(uint32_t mask, uint32_t slot) { return (mask >> (2 * slot)) & 3u; }
// Bit count of a 16-bit mask: st::bit_count's form, which a caller compiled for POPCNT
// turns into the instruction (StackMap's soft lookups; the build has no -mpopcnt).
inline uint32_t popcount16(uint32_t m) { return st::bit_count(uint64_t(m)); }
inline uint32_t child_skip(uint32_t mask, uint32_t slot) { return popcount16(mask & ((1u << (2 * slot)) - 1u)); }
// For a validated tree the result lies in the buffer (an offset never reaches before
// word 0: the validator checks it).
inline uint64_t block_start(uint64_t parent_word, uint32_t shift, int32_t off) {
  return ((parent_word >> shift) + uint64_t(int64_t(off))) << shift;
}
inline bool is_far(int32_t off) { return off < kFarLimit; }
// The far word of a node at word p with a far offset; far_offset is the inverse.
inline uint64_t far_word(uint64_t p, int32_t off) { return p + 1 + uint64_t(off - kFarOffsetMin); }
inline int32_t far_offset(uint64_t p, uint64_t far) { return kFarOffsetMin + int32_t(far - p - 1); }
// The children block of the node at word p whose node word is w (shift: its level's);
// `tree` is the tree's first byte. A validated tree keeps the result in the buffer.
inline uint64_t child_block(const uint8_t* tree, uint64_t p, uint32_t shift, uint32_t w) {
  const int32_t off = word_offset(w);
  if (is_far(off)) [[unlikely]] {
    uint32_t b;
    std::memcpy(&b, tree + 4 * far_word(p, off), 4);
    return b;
  }
  return block_start(p, shift, off);
}

// Level geometry of a stack of 2^k slices of 2^n x 2^n texels (MH §4 "non-cubic image
// stacks"). The paper pads the stack to a cube with placeholder slices of interval
// [0, 1]; a placeholder contains every depth, so it is covered wherever it meets real
// slices and never stored. The cube's coarse levels therefore only ever hold children
// in the real corner, and this geometry stores exactly that: the octree has
// L = max(n, k) levels below the root; the finest min(n, k) steps halve x, y and w
// together (8 child slots), the steps above them halve only the longer axis (x and y:
// slots with cw = 0; w: slots with cx = cy = 0), so level l is a grid of
// 2^xy_bits(l) x 2^xy_bits(l) x 2^w_bits(l) nodes. Slots an axis does not split at a
// level are never present (the validator refuses them).
struct Geometry {
  uint32_t n = 0, k = 0;
  constexpr uint32_t depth() const { return n > k ? n : k; }
  constexpr uint32_t levels() const { return depth() + 1; }
  constexpr uint32_t xy_bits(uint32_t l) const { return l + n >= depth() ? l + n - depth() : 0; }
  constexpr uint32_t w_bits(uint32_t l) const { return l + k >= depth() ? l + k - depth() : 0; }
  // Whether the step from level l to l + 1 halves x and y / w.
  constexpr bool splits_xy(uint32_t l) const { return l + n >= depth(); }
  constexpr bool splits_w(uint32_t l) const { return l + k >= depth(); }
  // Bits of a node's code the step from level l to l + 1 adds (x and y: 2, w: 1).
  constexpr uint32_t step_bits(uint32_t l) const { return (splits_xy(l) ? 2u : 0u) + (splits_w(l) ? 1u : 0u); }
  // The child slots a node of level l may use (bit c: slot c).
  constexpr uint32_t slot_set(uint32_t l) const {
    const uint32_t xy = splits_xy(l) ? 0x0Fu : 0x01u;
    return splits_w(l) ? (xy | xy << 4) : xy;
  }
  // The octree level whose x, y resolution is 2^q (q <= n).
  constexpr uint32_t level_of_xy(uint32_t q) const { return q + depth() - n; }
};

inline uint32_t float_bits(float f) { return std::bit_cast<uint32_t>(f); }
inline float bits_float(uint32_t b) { return std::bit_cast<float>(b); }

}  // namespace st::moct

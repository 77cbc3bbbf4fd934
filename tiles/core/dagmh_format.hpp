// DAG-MH buffer format (DAG-MH 2021; drawn with sizes and offsets in tiles/core/DAGMH.md).
// Every constant here is a FORMAT CONSTANT: changing one changes the bytes of every
// encoded buffer and needs a version bump.
//
// One self-contained little-endian byte buffer, 4-byte aligned sections, offsets only:
//   header | skip table | inner nodes | treelets | chunk infos | multipliers
// All multi-byte reads go through memcpy (the span handed to open_dagmh may be unaligned).
#pragma once
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "common/bit_count.hpp"
#include "common/bytes.hpp"

namespace st::dagmh {

static_assert(std::endian::native == std::endian::little, "DAG-MH buffers are little-endian");

inline constexpr uint32_t kMagic = 0x484D4744u;  // the bytes "DGMH"
inline constexpr uint32_t kVersion = 1;
// Version 2: a tile whose references may name nodes and treelets of a pack-wide
// dictionary (DictHeader below; DAGMH.md "Dictionary"); header field 68 then holds the
// dictionary's CRC-32. Version 1 tiles never reference one (field 68 is zero).
inline constexpr uint32_t kVersionDictionary = 2;

// Treelets: subtrees of height <= 3 (4 levels) stored as a full 4-level quadtree bitmap
// in depth-first order, 1 + 4 + 16 + 64 = 85 bits in 3 words (DAG-MH §3.2, Alg. 1).
inline constexpr uint32_t kTreeletLevels = 4;
inline constexpr uint32_t kTreeletNodes = 85;
inline constexpr uint32_t kTreeletWords = 3;
inline constexpr uint32_t kTreeletBytes = kTreeletWords * 4;
// Depth-first positions in a full 4-level quadtree: a node at treelet level n reached by
// child indices l0, l1, l2 sits at n + 21*l0 + 5*l1 + l2 (DAG-MH §3.5): 21 and 5 are the
// sizes of the subtrees below levels 1 and 2.
inline constexpr uint32_t kTreeletStride[3] = {21, 5, 1};

// Values: depth-first order, chunks of 32 (DAG-MH §3.4, Table 4).
inline constexpr uint32_t kChunkValues = 32;
inline constexpr uint32_t kMaxFactorBits = 24;  // multipliers i < 2^24 convert to float exactly
inline constexpr uint32_t kRawFactorBits = 32;  // "factor bits 32": the multiplier is the float
// The multiplier section ends with 8 zero bytes so a multiplier is always read with one
// unaligned 8-byte load; only the bytes before them carry multipliers.
inline constexpr uint32_t kMultiplierPadBytes = 8;

// Skip list (DAG-MH §3.7): a dense 2^S x 2^S table of traversal cursors at level S inside
// one tile (a format constant of the DAG-MH buffer; unrelated to the pack's skip grid K,
// whose bound is st::kMaxSkipLevel in tile_cut_grid.hpp).
inline constexpr uint32_t kMaxSkipListLevel = 6;

// Tagged references (root, skip entries): tag in the top 2 bits, index below.
inline constexpr uint32_t kRefTagMask = 3u << 30;
inline constexpr uint32_t kRefIndexMask = (1u << 30) - 1;
inline constexpr uint32_t kRefNone = 0u << 30;     // no node: the answer is `last`
inline constexpr uint32_t kRefInner = 1u << 30;    // index = word offset in the node section
inline constexpr uint32_t kRefTreelet = 2u << 30;  // index = treelet number

// Inner node: word 0 = flags, then per present child (child order) two words:
// child reference (word offset, or treelet number if its treelet bit is set) and the
// child's value offset (= own value + values of the earlier present children).
inline constexpr uint32_t kNodeChildMask = 0xFu;        // bit c: child c present
inline constexpr uint32_t kNodeTreeletShift = 4;        // bit 4+c: child c is a treelet
inline constexpr uint32_t kNodeValuedBit = 1u << 8;     // the node itself has a value
inline constexpr uint32_t kNodeFlagBits = 0x1FFu;       // the others must be zero
inline constexpr uint32_t node_words(uint32_t flags) {
  return 1 + 2 * uint32_t(std::popcount(flags & kNodeChildMask));
}

struct Header {
  uint32_t magic;              //  0
  uint32_t version;            //  4
  uint32_t header_bytes;       //  8 = sizeof(Header)
  uint32_t finest_level;       // 12 map is 2^finest_level a side, <= 20
  uint32_t skip_level;         // 16 S <= min(finest_level, kMaxSkipListLevel)
  uint32_t root_ref;           // 20 tagged: kRefInner | 0, or kRefTreelet | 0
  uint32_t node_words;         // 24 inner-node section length in 4-byte words
  uint32_t treelet_count;      // 28
  uint32_t value_count;        // 32 values in depth-first order
  uint32_t chunk_count;        // 36 = ceil(value_count / 32)
  uint32_t multiplier_bytes;   // 40 multiple of 4, >= kMultiplierPadBytes
  uint32_t total_bytes;        // 44 = the buffer's length
  uint32_t skip_offset;        // 48 byte offsets of the sections, in this order
  uint32_t node_offset;        // 52
  uint32_t treelet_offset;     // 56
  uint32_t chunk_offset;       // 60
  uint32_t multiplier_offset;  // 64
  uint32_t dictionary_crc;     // 68 version 1: 0; version 2: CRC-32 of the dictionary it references
};
static_assert(sizeof(Header) == 72);
static_assert(offsetof(Header, root_ref) == 20 && offsetof(Header, multiplier_offset) == 64);

// Pack-wide dictionary (DAG-MH §3.1 applied across tiles; DAGMH.md "Dictionary"): the
// inner nodes and treelets that occur in two or more tiles, stored once. Same node and
// treelet formats as a tile's; its references are its own (word offsets into its node
// section, its treelet numbers) and never leave it. A version-2 tile addresses
// [the dictionary's nodes | its own] as one space, so the dictionary's references mean
// the same in every tile: inner index i < D (the dictionary's node_words) is the
// dictionary's word i, else the tile's word i - D; treelet t < T (the dictionary's
// treelet_count) the dictionary's, else the tile's t - T.
// Layout: header (32 B) | nodes (node_words x 4 B) | treelets (treelet_count x 12 B).
inline constexpr uint32_t kDictMagic = 0x444D4744u;  // the bytes "DGMD"
inline constexpr uint32_t kDictVersion = 1;
struct DictHeader {
  uint32_t magic;           //  0
  uint32_t version;         //  4
  uint32_t header_bytes;    //  8 = 32
  uint32_t node_words;      // 12 < 2^30
  uint32_t treelet_count;   // 16 < 2^30
  uint32_t total_bytes;     // 20 the buffer's length
  uint32_t node_offset;     // 24 = 32
  uint32_t treelet_offset;  // 28 = node_offset + 4 * node_words
};
static_assert(sizeof(DictHeader) == 32);
static_assert(offsetof(DictHeader, treelet_count) == 16 && offsetof(DictHeader, treelet_offset) == 28);

// A traversal cursor; also the skip-table entry. `ref` is the node where traversal
// resumes (at `level`, its own value not yet applied), `base` the depth-first index of
// that node's first value, `last` the index of the deepest valued node above it.
struct Cursor {
  uint32_t ref;    //  0 tagged reference
  uint32_t level;  //  4
  uint32_t base;   //  8
  uint32_t last;   // 12
};
static_assert(sizeof(Cursor) == 16);
inline constexpr uint32_t kSkipEntryBytes = sizeof(Cursor);

// Per-chunk info (DAG-MH §3.4 Fig. 4). mask bit j set: value j of the chunk is stored as
// a multiplier (Alg. 2 "exists"); clear: it equals `base`.
struct ChunkInfo {
  float base;            //  0 representative value
  uint32_t mask;         //  4
  float c_l;             //  8 value = c_l + c_f * i (no fma, see dagmh_values.hpp)
  float c_f;             // 12
  uint32_t bit_offset;   // 16 first multiplier, in bits from the multiplier section start
  uint8_t factor_bits;   // 20 k in 0..24, or 32 = raw float bits
  uint8_t pad[3];        // 21 zero
};
static_assert(sizeof(ChunkInfo) == 24);
static_assert(offsetof(ChunkInfo, bit_offset) == 16 && offsetof(ChunkInfo, factor_bits) == 20);


inline constexpr size_t align4(size_t n) { return (n + 3) & ~size_t(3); }

}  // namespace st::dagmh

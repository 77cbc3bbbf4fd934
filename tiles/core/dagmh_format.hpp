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
// Version 3: a 32-byte header without the fields its counts imply (DAGMH.md "Header"), and
// 20-byte chunk infos. Versions 1 and 2 (a 72-byte header with every section offset,
// 24-byte chunk infos; 2 = referencing a pack dictionary) are refused, naming the version.
inline constexpr uint32_t kVersion = 3;
// Header flag bit 0: the tile's references may name nodes and treelets of a pack-wide
// dictionary (DictHeader below; DAGMH.md "Dictionary"), whose CRC-32 is `dictionary_crc`.
inline constexpr uint8_t kFlagDictionary = 1;

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

// The header (32 bytes). Every section's offset and length follows from the counts and the
// buffer's length (sections_of below): skip table at 32, then inner nodes, treelets,
// chunk infos, multipliers (the rest of the buffer).
struct Header {
  uint32_t magic;           //  0
  uint32_t version;         //  4 = kVersion
  uint8_t finest_level;     //  8 map is 2^finest_level a side, <= 20
  uint8_t skip_level;       //  9 S <= min(finest_level, kMaxSkipListLevel)
  uint8_t flags;            // 10 bit 0 kFlagDictionary; the others zero
  uint8_t reserved;         // 11 zero
  uint32_t root_ref;        // 12 tagged: kRefInner | word, or kRefTreelet | number
  uint32_t node_words;      // 16 inner-node section length in 4-byte words
  uint32_t treelet_count;   // 20
  uint32_t value_count;     // 24 values in depth-first order, >= 1
  uint32_t dictionary_crc;  // 28 flag clear: 0; set: CRC-32 of the dictionary it references
};
static_assert(sizeof(Header) == 32);
static_assert(offsetof(Header, finest_level) == 8 && offsetof(Header, flags) == 10 &&
              offsetof(Header, root_ref) == 12 && offsetof(Header, dictionary_crc) == 28);

// Pack-wide dictionary (DAG-MH §3.1 applied across tiles; DAGMH.md "Dictionary"): the
// inner nodes and treelets that occur in two or more tiles, stored once. Same node and
// treelet formats as a tile's; its references are its own (word offsets into its node
// section, its treelet numbers) and never leave it. A tile with kFlagDictionary addresses
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

// Per-chunk info (DAG-MH §3.4 Fig. 4), 20 bytes. mask bit j set: value j of the chunk is
// stored as a multiplier (Alg. 2 "exists"); clear: it equals `base`. Word 16 packs the
// first multiplier's bit offset (bits 0..26) and the factor code (bits 27..31): k for
// k = 0..24, kRawFactorCode for raw float32 bits (k = 32); codes 25..30 are invalid.
inline constexpr uint32_t kBitOffsetBits = 27;
inline constexpr uint32_t kBitOffsetMask = (1u << kBitOffsetBits) - 1;
inline constexpr uint32_t kRawFactorCode = 31;
struct ChunkInfo {
  float base;       //  0 representative value
  uint32_t mask;    //  4
  float c_l;        //  8 value = c_l + c_f * i (no fma, see dagmh_values.hpp)
  float c_f;        // 12
  uint32_t packed;  // 16 bit_offset | factor code << 27
  uint32_t bit_offset() const { return packed & kBitOffsetMask; }
  uint32_t factor_code() const { return packed >> kBitOffsetBits; }
  // k: 0..24, or 32 (raw); only meaningful for a valid code.
  uint32_t factor_bits() const { return factor_code() == kRawFactorCode ? kRawFactorBits : factor_code(); }
};
static_assert(sizeof(ChunkInfo) == 20);
static_assert(offsetof(ChunkInfo, c_f) == 12 && offsetof(ChunkInfo, packed) == 16);
inline uint32_t pack_factor(uint32_t bit_offset, uint32_t k) {
  return bit_offset | ((k == kRawFactorBits ? kRawFactorCode : k) << kBitOffsetBits);
}

// The skip table holds 4^S cursors for S >= 1 and none for S = 0 (its one entry would be
// the root cursor, which the header's root_ref already gives).
inline uint64_t skip_table_entries(uint32_t skip_level) {
  return skip_level == 0 ? 0 : uint64_t(1) << (2 * (skip_level & 15));
}

// Section offsets and lengths implied by a header and the buffer's length. The validator
// checks the counts first (so these do not overflow); the encoder and the dictionary
// rewrite lay buffers out with it.
struct Sections {
  uint64_t skip, nodes, treelets, chunks, multipliers, end;
  uint32_t chunk_count;
};
inline Sections sections_of(const Header& h, uint64_t total_bytes) {
  Sections s;
  s.chunk_count = uint32_t((uint64_t(h.value_count) + kChunkValues - 1) / kChunkValues);
  s.skip = sizeof(Header);
  s.nodes = s.skip + skip_table_entries(h.skip_level) * sizeof(Cursor);
  s.treelets = s.nodes + uint64_t(h.node_words) * 4;
  s.chunks = s.treelets + uint64_t(h.treelet_count) * kTreeletBytes;
  s.multipliers = s.chunks + uint64_t(s.chunk_count) * sizeof(ChunkInfo);
  s.end = total_bytes;
  return s;
}
// The header of a buffer (unchecked: validate() checks it).
inline Header load_header(const uint8_t* bytes) {
  Header h;
  std::memcpy(&h, bytes, sizeof h);
  return h;
}

inline constexpr size_t align4(size_t n) { return (n + 3) & ~size_t(3); }

}  // namespace st::dagmh

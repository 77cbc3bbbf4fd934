// Packed plane tiles (tiles/core/PLANES.md "Packed form"): how a plane tile ("STPN",
// plane_format.hpp) is stored in a pack. Its block records and labelled blocks become a
// quadtree of block kinds, one- or two-byte indices and one-bit labels where a labelled
// block uses two planes; the zero bytes this frees stay in place, so the buffer keeps its
// size (zlib stores them in a few bytes) and the pack's raw sizes, cache slots and wire
// sizes are those of the STPN tile. Readers unpack in place as they load (pack reader,
// client), so every lookup, the GPU and the shaders read STPN as before. Layout (format
// constants: a change is a new magic):
//
//   offset  size  field
//   0       4     magic   "STPQ", bytes in that order
//   4       20    the STPN header's bytes 4..23 unchanged (version 2 or 3, levels, flags,
//                 block_count B, byte_size, table_count T, label_count L)
//   24      24*T  the plane table, unchanged (a varint form without the rounded planes'
//                 trailing zero bits deflated no smaller: zlib stores those zero bytes)
//   then          kinds    the block quadtree, 2 bits a node (bits 2k..2k+1 of its byte for
//                          the k-th node of four), nodes in preorder from the whole tile
//                          (shift = finest level), children in Morton order:
//                          0 no block in it, 1 split into four (only above kMinShift),
//                          2 one plane block (shift kMinShift..kMaxShift), 3 a labelled
//                          block, wide or not (shift kLabelShift); the last byte's unused
//                          bits zero
//   then          indices  a plane block's table index, in block order: one byte when
//                          T <= 256, else two (little-endian)
//   then          palettes a labelled block's 2 bytes, in block order: byte 0 the class of
//                          each of its 4 palette entries (bits 2k..2k+1: the k-th entry is
//                          the class-th distinct plane, classes in first-seen order),
//                          byte 1 the palette entries its labels use (bit k: entry k);
//                          a wide labelled block (plane_format.hpp) 0 and 0x80 (kWideUse):
//                          its slots, two, are implied by it (L counts slots)
//   then          planes   each labelled block's distinct planes, class order, one or two
//                          bytes each as indices; a wide block's 8 palette entries as stored
//   then          labels   per labelled block: nothing when it uses one entry; 8 bytes
//                          when it uses two (bit i of byte i / 8 for texel i = 8 y + x:
//                          set = the higher entry); else its 16 STPN label bytes; a wide
//                          block's 24 label bytes (bit planes) as stored
//   then          zeros    up to where the STPN tile's inner buffer starts
//   24+24T+8B+24L the inner buffer, unchanged
//
// Predicted labels (magic "STPL", pack feature bit 14 predicted_plane_labels; otherwise
// the STPQ layout): a labelled block (not wide) using two or more entries has in its use byte bits
// 4..5 a prediction mode (0 none, 1 each texel takes the used entry whose plane is least
// there, a crease's near surface, 2 the greatest; ties to the lower entry; plane values
// a + b x + c y summed modulo 2^64 at the texel's tile coordinates) and bit 6 "all
// predicted" (then no label bytes); its labels are stored against the prediction: with two
// entries a bit a texel set where the label is the higher entry and the prediction is not
// or the other way round, with more the 2-bit XOR of label and prediction. The mode is the
// one that leaves the fewest texels unpredicted, ties to the lower mode (mode 0 counts the
// texels whose plain code is not zero).
// STPL also leaves out the inner buffer's header fields the tile implies: header byte 7
// (the STPN flags, 0) is the inner kind, 1 MH or 2 MMH when its version is kVersion, its
// levels the tile's and its byte_size the rest of the buffer (else 0: nothing left out),
// and then the inner header's bytes 0..6 (magic, version, levels) and 12..15 (byte_size)
// are zeros in place.
//
// The form is canonical: one STPN tile packs to one STPQ buffer and unpacking refuses any
// other (stray bits, a split with no block below it, a class map out of first-seen order,
// a plane named twice in a palette, a use mask that is not what the labels use, nonzero
// padding).
#pragma once
#include <cstdint>
#include <span>
#include <vector>

namespace st {

// Whether `bytes` start with a packed plane tile magic ("STPQ" or "STPL").
bool is_packed_plane_tile(std::span<const uint8_t> bytes);

// The pack features (pack_format.hpp) a pack holding packed tile `bytes` must declare:
// packed_plane_tiles, and predicted_plane_labels for "STPL"; 0 for anything else.
uint32_t packed_plane_tile_features(std::span<const uint8_t> bytes);

// The pack features beyond plane_tiles that a pack holding plane tile `bytes` ("STPN",
// "STPQ" or "STPL") must declare: packed_plane_tile_features, and wide_plane_blocks when
// its version field (bytes 4..5, the same in every form) is 3; 0 for anything else. Reads
// at most 6 bytes; the tile's own validation comes later.
uint32_t plane_tile_features(std::span<const uint8_t> bytes);

// The byte counts of a packed tile's parts after the table (for bench_pack_bytes).
struct PlanePackParts {
  size_t kinds = 0, indices = 0, palettes = 0, planes = 0, labels = 0;
};

// The packed form of the valid STPN tile `stpn` (the same size): "STPL" with labels
// predicted, else "STPQ"; empty when the tile is not a valid plane tile. Throws nothing on
// any input. `parts`, if given, gets the sizes.
std::vector<uint8_t> pack_plane_tile(std::span<const uint8_t> stpn, PlanePackParts* parts = nullptr, bool predict_labels = true);

// An STPQ or STPL buffer back to its STPN bytes, in place (safe for untrusted input: throws
// st::FormatError naming the field and leaves `bytes` unspecified; the STPN result is
// then validated by whoever opens it, like any tile).
void unpack_plane_tile(std::span<uint8_t> bytes);

}  // namespace st

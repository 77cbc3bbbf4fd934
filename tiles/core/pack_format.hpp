// The pack file format, version 2 (tiles/PACK.md draws it in full; pack_format_test pins
// every offset). All integers little-endian; every byte a reader uses is covered by a
// CRC-32 (zlib polynomial, libdeflate_crc32).
//
//   [0, 256)            header (PackHeader): magic, version, state, light, levels, offsets
//   [256, +params)      build parameters: "key=value\n" text (params_crc)
//   journal             appended in build order: tile records (32-byte header + stored
//                       payload) and cell records (32 bytes, one per finished level-K cell)
//   zero padding        to a multiple of 8
//   skip grid           CutGrid bytes (tile_cut_grid.hpp) of K levels, then the map
//                       preview (map_preview.hpp), then with the feature dagmh_dictionary
//                       the DAG-MH dictionary (pack_dictionary.hpp): grid_size covers
//                       them all (grid_crc)
//   tile index          tile_count * 32-byte TileIndexEntry sorted by id (index_crc); in a
//                       finished pack (kFeaturePayloadsOnly) the journal holds the payloads
//                       alone and the index is compact (serialize_compact_index)
//   end of file         == index_offset + 32 * tile_count, or the compact index's end
//                       (trailing bytes are rejected)
//
// While a build runs the file is "<name>.tmp" with state = building and only the header,
// params and journal; finish() writes the finished pack afresh (payloads only, grid,
// compact index, header last), fsyncs it and renames it into place. Resume re-reads the
// journal: each record carries its own CRCs, so a torn tail is found and cut off at the
// last complete cell record.
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/encoding.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

// Format constants.
inline constexpr std::array<uint8_t, 8> kPackMagic = {'S', 'T', 'P', 'A', 'C', 'K', '\r', '\n'};
inline constexpr uint32_t kPackVersion = 2;  // 2: the map preview follows the skip grid
inline constexpr uint32_t kPackHeaderBytes = 256;
inline constexpr uint32_t kRecordBytes = 32;      // tile and cell record headers
inline constexpr uint32_t kIndexEntryBytes = 32;  // one tile index entry
inline constexpr uint32_t kTileRecordMagic = 0x43455254;  // "TREC"
inline constexpr uint32_t kCellRecordMagic = 0x43455243;  // "CREC"
inline constexpr uint32_t kMaxParamsBytes = 1 << 20;
// Upper bound on tile_bytes and on any tile's raw or stored size: a hostile index can
// make a reader allocate at most this much per tile.
inline constexpr uint32_t kMaxTileBytes = 64u << 20;
inline constexpr uint32_t kMinTileBytes = 64;  // room for the smallest index tile (d = 1)
// The DAG-MH dictionary section that ends a grid section (pack_dictionary.hpp draws it).
inline constexpr uint32_t kPackDictionaryMagic = 0x44445453;  // "STDD"
inline constexpr uint32_t kPackDictionaryHeaderBytes = 16;
// The bound keeps MapInfo inside the protocol's 64 MiB frame ceiling with the largest skip
// grid (K = 10: 9.8 MB) and map preview (16 MiB) beside it; the writer shrinks a larger
// dictionary (shares only subtrees found in more tiles) until it fits.
inline constexpr uint64_t kMaxPackDictionaryBytes = 32ull << 20;
inline constexpr uint64_t kMinPackDictionaryBytes = 32;  // a DGMD header alone
// "[64 B, 64 MiB]": the bounds as error messages and --help state them.
std::string tile_bytes_bounds();
enum class PackState : uint32_t { building = 0, complete = 1 };

// Feature flags (header `flags`): what the pack uses, so a client can refuse what it lacks.
enum PackFeature : uint32_t {
  kFeatureExitDepths = 1u << 0,  // intervals traced exit depths (closed geometry); else hi = lo
  kFeatureHasTiles = 1u << 1,    // at least one tile (else the skip grid answers everything)
  kFeatureIndexTiles = 1u << 2,  // some subtree was cut deeper into index tiles
  // Deep shadow tiles (tiles/core/DEEP.md) for the partial occluders: a deep directory
  // and deep tiles in the tile index (kinds 3 and 4, ids with kDeepTileIdBit). Set by
  // the writer iff it appended them.
  kFeatureDeepShadow = 1u << 3,
  // Static-geometry intervals (voxel paper §6.1): an open first hit's interval reaches to
  // just below the next surface along the texel ray. Lossless only for receivers that lie
  // on a surface (tiles/PACK.md); lookups are unchanged.
  kFeatureStaticIntervals = 1u << 4,
  // A shadow-map stack (tiles/PACK.md "Stack packs"): the grid section is a StackGrid
  // (stack_grid.hpp) and every tile an MH octree buffer of one level-K cell's subtree.
  kFeatureStack = 1u << 5,
  // A DAG-MH pack whose grid section ends with a pack-wide dictionary of shared subtrees
  // (pack_dictionary.hpp, tiles/PACK.md "DAG-MH dictionary"); its encoded tiles may be
  // DAG-MH version 2, which reference it. Only with encoding dagmh, never with stack.
  kFeatureDagmhDictionary = 1u << 6,
  // The grid section (skip grid, map preview, DAG-MH dictionary) is stored as one zlib
  // stream behind an 8-byte header (tiles/PACK.md "Compressed grid section"); readers
  // inflate it at open and hand out the inflated section. With stack: the stack grid
  // (at most kStackMaxGridBytes inflated); readers before that refuse such a pack.
  kFeatureCompressedGrid = 1u << 7,
  // A finished pack without the build journal's records (tiles/PACK.md "Payloads only"):
  // the section from journal_offset to the padding before the grid holds the tiles'
  // stored payloads alone, back to back in tile index (id) order, so entry i's offset is
  // journal_offset + the stored sizes of entries 0..i-1, and the tile index is stored
  // compact (serialize_compact_index: a zlib stream of its columns, offsets implied), so
  // the file ends where that stream does. The journal's tile and cell records live only in
  // the "<name>.tmp" journal and in part files (resume, merge). Every build, resume and
  // merge writes it; a stack pack too (write_stack_pack, StackPackParams::payloads_only),
  // which readers before that refuse.
  kFeaturePayloadsOnly = 1u << 8,
  // A DAG-MH pack some of whose encoded tiles are MMH buffers (magic "STMM", MH quadtree
  // format with merged subtrees) because that tile stored in fewer bytes (tiles/PACK.md
  // "Mixed tiles"): each tile's magic says which; readers open it by its magic
  // (open_encoded). Only with encoding dagmh, never with stack. Readers before it refuse
  // the pack by this bit.
  kFeatureMixedTiles = 1u << 9,
  // A stack pack some of whose tiles are per-slice cells (magic "STSL", stack_slices.hpp,
  // tiles/core/MHOCT.md "Per-slice cells"): each slice's square of the cell as its own
  // DAG-MH or MMH tile, where that stored smaller than the cell's octree. Each tile's
  // magic says which; only with stack. Readers before it refuse the pack by this bit.
  kFeatureStackSliceTiles = 1u << 10,
  // Some encoded tiles are plane tiles (magic "STPN", tiles/core/PLANES.md): plane blocks
  // over an inner buffer of the pack's encoding (MH, MMH or DAG-MH; in a DAG-MH pack also
  // MMH, then with mixed_tiles); in a stack, some per-slice cells' slices are plane tiles
  // (only with stack_slice_tiles, tiles/core/MHOCT.md "Per-slice cells"). Never with vsdag.
  // Readers before it refuse the pack by this bit.
  kFeaturePlaneTiles = 1u << 11,
  // Some per-slice cells are stored grouped (magic "STSP", stack_slices.hpp, tiles/core/MHOCT.md
  // "Grouped per-slice cells"): an STSL cell's bytes reordered so like lies with like, the same
  // size; readers ungroup them as they load. Only with stack_slice_tiles. Readers before it
  // refuse the pack by this bit.
  kFeatureStackGroupedTiles = 1u << 12,
  // Some plane tiles are stored packed (magic "STPQ", plane_pack.hpp, tiles/core/PLANES.md
  // "Packed form"): the same size as their STPN bytes; readers unpack them as they load.
  // Only with plane_tiles. Readers before it refuse the pack by this bit.
  kFeaturePackedPlaneTiles = 1u << 13,
  // Some packed plane tiles predict their labels from their planes (magic "STPL",
  // plane_pack.hpp, tiles/core/PLANES.md "Predicted labels"). Only with packed_plane_tiles.
  // Readers before it refuse the pack by this bit.
  kFeaturePredictedPlaneLabels = 1u << 14,
  // A stack pack some of whose cells are split below the skip level (stack grid version 2,
  // stack_grid.hpp; tiles/core/MHOCT.md "Split cells"): a cell whose tile would overflow
  // the tile bound is answered by its children, one octree level deeper, instead of the
  // whole cut moving deeper. Only with stack. Readers before it refuse the pack by this bit.
  kFeatureStackSplitCells = 1u << 15,
  // Some plane tiles are version 3 (tiles/core/PLANES.md "Layout"): they hold wide labelled
  // blocks (8 planes, 3-bit labels). Set by the writers iff some plane tile (a 2D pack's,
  // or a stack's plane slice) is version 3; a reader refuses a version 3 plane tile in a pack
  // without it. Only with plane_tiles. Readers before it refuse the pack by this bit.
  kFeatureWidePlaneBlocks = 1u << 16,
  kKnownFeatures = 0x1FFFF,
};

// Header layout (offset: size field):
//   0:8 magic  8:4 version  12:4 header_size  16:4 state  20:4 flags
//   24:1 encoding  25:1 light_kind  26:1 map_level  27:1 skip_level  28:4 tile_bytes
//   32:8 scene_hash  40:144 light (18 x f64, LightSpace::to_array)
//   184:8 params_offset  192:8 params_size  200:8 journal_offset  208:8 grid_offset
//   216:8 grid_size  224:8 index_offset  232:8 tile_count
//   240:4 params_crc  244:4 grid_crc  248:4 index_crc  252:4 header_crc (of bytes 0..251)
struct PackHeader {
  PackState state = PackState::building;
  uint32_t flags = 0;
  Encoding encoding = Encoding::mh;
  LightKind light_kind = LightKind::sun;
  uint32_t map_level = 0, skip_level = 0;
  uint32_t tile_bytes = 0;  // bound on any tile's uncompressed (encoded) size
  uint64_t scene_hash = 0;
  std::array<double, 18> light{};
  uint64_t params_offset = 0, params_size = 0, journal_offset = 0;
  uint64_t grid_offset = 0, grid_size = 0, index_offset = 0, tile_count = 0;
  uint32_t params_crc = 0, grid_crc = 0, index_crc = 0;

  std::array<uint8_t, kPackHeaderBytes> serialize() const;  // computes header_crc
  // Checks magic, version, size, header CRC, enums and levels; `what` names the file.
  static PackHeader parse(std::span<const uint8_t> bytes, const std::string& what);
  // With the plain tile index; a payloads-only pack ends where its compact index does.
  uint64_t file_size() const { return index_offset + tile_count * kIndexEntryBytes; }
};

// encoded / index == EntryKind::tile / ::index. deep: a deep tile (DEEP.md) of the deep
// map; deep_directory: the deep map's directory (deep_pack.hpp). The skip grid never
// names the deep kinds: their ids carry kDeepTileIdBit (PACK.md "Deep tiles").
enum class TileKind : uint8_t { encoded = 1, index = 2, deep = 3, deep_directory = 4 };

// Deep ids: bit 63 set, then the same level (bits 62..58) and morton code as a tile id
// (tile_cut_grid.hpp) of the deep tile's root node in the deep map's own level
// hierarchy. No opaque id has bit 63 (levels <= 20). The directory has the one id whose
// level field is 31, which no tile has.
inline constexpr uint64_t kDeepTileIdBit = uint64_t(1) << 63;
inline constexpr uint64_t kDeepDirectoryId = kDeepTileIdBit | (uint64_t(31) << 58);
inline bool is_deep_id(uint64_t id) { return (id & kDeepTileIdBit) != 0; }
// True for a valid deep tile id (kind deep) or the directory id.
bool is_valid_deep_id(uint64_t id);
// Whether a tile record or index entry may pair this id with this kind: encoded and index
// with valid opaque ids, deep with valid deep tile ids, deep_directory with
// kDeepDirectoryId alone.
bool id_fits_kind(uint64_t id, TileKind kind);

// Tile record header in the journal (offset: size): 0:4 magic "TREC"  4:1 kind  5:3 zero
// 8:8 id  16:4 stored_size  20:4 raw_size  24:4 payload_crc  28:4 header_crc (of 0..27).
// Followed by stored_size bytes: the zlib stream of the raw tile.
struct TileRecord {
  TileKind kind = TileKind::encoded;
  uint64_t id = 0;
  uint32_t stored_size = 0, raw_size = 0, crc = 0;
  std::array<uint8_t, kRecordBytes> serialize() const;
};

// Cell record (0:4 magic "CREC"  4:1 entry kind  5:1 index_levels  6:2 zero  8:4 cx
// 12:4 cy  16:4 value  20:4 lo  24:4 hi  28:4 header_crc): level-K cell (cx, cy) is done;
// its entry and its root's admissible interval (for the coarse levels, MH §3.1 tiled).
struct CellRecord {
  uint32_t cx = 0, cy = 0;
  GridEntry entry;
  float lo = 0, hi = 0;
  std::array<uint8_t, kRecordBytes> serialize() const;
};

// Parses either record header from 32 bytes; returns false on a bad magic/CRC/field (a
// torn or corrupt journal record). Exactly one of `tile` / `cell` is filled.
enum class RecordType { none, tile, cell };
RecordType parse_record(std::span<const uint8_t, kRecordBytes> bytes, TileRecord* tile, CellRecord* cell);

// Tile index entry: 0:8 id  8:8 payload offset  16:4 stored_size  20:4 raw_size
// 24:4 crc (of the stored bytes)  28:1 kind  29:3 zero.
struct TileIndexEntry {
  uint64_t id = 0;
  uint64_t offset = 0;
  uint32_t stored_size = 0, raw_size = 0, crc = 0;
  TileKind kind = TileKind::encoded;
};
std::vector<uint8_t> serialize_index(std::span<const TileIndexEntry> entries);
// Checks sizes (raw <= tile_bytes, stored <= zlib's bound for it), kinds, ids, strict id
// order and that each payload lies in [journal_begin, journal_end) behind room for its
// 32-byte record; with `payloads_only` (kFeaturePayloadsOnly) instead that the payloads
// follow each other from journal_begin in index order with no gap, ending less than 8
// bytes (the padding) before journal_end. Throws st::FormatError naming the entry.
std::vector<TileIndexEntry> parse_index(std::span<const uint8_t> bytes, uint64_t base_offset,
                                        uint64_t journal_begin, uint64_t journal_end, uint32_t tile_bytes,
                                        const std::string& what, bool payloads_only = false);
// Compact tile index (kFeaturePayloadsOnly; tiles/PACK.md "Payloads only"): 0:4 magic
// "STIZ"  4:4 S  8:S a zlib stream inflating to exactly 21 n bytes (n = tile_count), the
// entries column by column: ids as u64 deltas (the first from 0), stored sizes, raw sizes,
// CRCs (u32 each), kinds (u8). Offsets are implied: payloads back to back from the
// journal's start. The section is the rest of the file (8 + S bytes; index_crc covers it).
inline constexpr uint32_t kCompactIndexMagic = 0x5A495453;  // "STIZ"
inline constexpr uint32_t kCompactIndexHeaderBytes = 8;
inline constexpr uint32_t kCompactIndexEntryBytes = 21;
std::vector<uint8_t> serialize_compact_index(std::span<const TileIndexEntry> entries, int level);
// Inflates the section (its sizes checked against tile_count before allocating), rebuilds
// the entries with their implied offsets and checks them as parse_index(payloads_only)
// does. Throws st::FormatError naming `what` and the field.
std::vector<TileIndexEntry> parse_compact_index(std::span<const uint8_t> section, uint64_t tile_count,
                                                uint64_t base_offset, uint64_t journal_begin, uint64_t journal_end,
                                                uint32_t tile_bytes, const std::string& what);
// The fewest bytes a tile's stored zlib stream takes (2-byte header, a deflate block of at
// least one byte, 4-byte Adler-32): bounds how many tiles a payloads-only journal holds.
inline constexpr uint32_t kMinStoredBytes = 8;
// Largest zlib stream of a raw tile of `raw` bytes a pack may hold: above libdeflate's own
// bound (5 bytes per >= 5000-byte block, plus 6 bytes of zlib header and checksum).
inline uint64_t max_stored_size(uint64_t raw) { return raw + raw / 256 + 64; }

// Build parameters blob: sorted "key=value\n" lines; keys [a-z0-9_.-]+, values without
// newlines.
using PackParamList = std::vector<std::pair<std::string, std::string>>;
std::vector<uint8_t> serialize_params(const PackParamList& params);
PackParamList parse_params(std::span<const uint8_t> bytes, const std::string& what);

uint32_t crc32_of(std::span<const uint8_t> bytes);
// zlib-format (RFC 1950) compression via libdeflate; level 0..12.
std::vector<uint8_t> zlib_compress(std::span<const uint8_t> raw, int level);
// Decompresses exactly `raw_size` bytes; throws st::FormatError(what + ...) if the stream
// is malformed, has trailing bytes or decodes to another size.
std::vector<uint8_t> zlib_decompress(std::span<const uint8_t> stored, uint32_t raw_size,
                                     const std::string& what);
// The same into `out`, which must be exactly the recorded raw size (a cache slot's first
// bytes): nothing is allocated and no copy follows.
void zlib_decompress_into(std::span<const uint8_t> stored, std::span<uint8_t> out, const std::string& what);

std::string hex32(uint32_t v);

// Compressed grid section (kFeatureCompressedGrid): "STGZ", u32 R = the inflated section's
// bytes, then a zlib stream of exactly R bytes.
inline constexpr uint32_t kCompressedGridMagic = 0x5A475453;  // "STGZ"
inline constexpr uint32_t kCompressedGridHeaderBytes = 8;
std::vector<uint8_t> compress_grid_section(std::span<const uint8_t> raw, int level);
// Inflates a stored section whose R must lie in [least, most]; throws st::FormatError
// naming `what` (and the field) otherwise, before allocating R bytes.
std::vector<uint8_t> inflate_grid_section(std::span<const uint8_t> stored, uint64_t least, uint64_t most,
                                          const std::string& what);
// The bounds [least, most] on a (non-stack) pack's inflated grid section.
std::pair<uint64_t, uint64_t> grid_section_bounds(uint32_t skip_level, bool dictionary);

}  // namespace st

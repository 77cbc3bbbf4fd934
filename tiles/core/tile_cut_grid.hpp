// The page table of a cut hierarchy (ARCHITECTURE.md "Tiles, skip grid and packs"; DAG-MH
// §3.7 skip list): a dense grid of entries at one level plus the values of every coarser
// level (a mip pyramid), and the stable ids of the tiles the entries point at.
//
// One CutGrid type serves twice:
//   - the skip grid of a pack: root (0, 0, 0), `levels` = K (the skip level);
//   - an index tile: root (l, x, y) = the subtree that was too big for one tile,
//     `levels` = d (1..kMaxIndexLevels); its entries point one step further down.
// Entry (i, j) covers node (root_level + levels, (root_x << levels) + i, ...); its value
// answers that node's level, and every finer level too when the entry is constant.
//
// Serialized layout (little-endian; format constants; pinned by tests/tiles/tile_cut_test.cpp):
//   off  size            field
//   0    4               magic "STGR"
//   4    4               levels k (u32)
//   8    4 * (4^k-1)/3   coarse values, levels 0..k-1, each level row-major (y rows),
//                        level j starting at value index (4^j - 1) / 3
//   ...  8 * 4^k         entries, row-major: f32 value, u8 kind, u8 index_levels, u16 0
// Decoding checks the magic, k, the exact length, every kind, index_levels, the zero
// padding and that no value is NaN: it never trusts the bytes.
#pragma once
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace st {

// Format constants.
inline constexpr uint32_t kGridMagic = 0x52475453;  // "STGR"
inline constexpr uint32_t kMaxSkipLevel = 10;       // 4^10 entries * 8 B = 8 MiB
inline constexpr uint32_t kMaxIndexLevels = 4;      // an index tile has <= 256 entries
inline constexpr uint32_t kGridEntryBytes = 8;

enum class EntryKind : uint8_t {
  constant = 0,  // nothing finer below: `value` answers every finer level
  tile = 1,      // an encoded tile (the pack's encoding) holds the subtree
  index = 2,     // an index tile (a CutGrid of `index_levels` levels) holds the subtree
};

struct GridEntry {
  float value = 0;
  EntryKind kind = EntryKind::constant;
  uint8_t index_levels = 0;  // d for kind == index, else 0
  bool operator==(const GridEntry&) const = default;
};

struct CutGrid {
  uint32_t levels = 0;          // k: entries live at relative level k
  std::vector<float> coarse;    // (4^k - 1) / 3 values, levels 0..k-1
  std::vector<GridEntry> entries;  // 4^k entries, row-major

  static size_t coarse_count(uint32_t k) { return ((size_t(1) << (2 * k)) - 1) / 3; }
  static size_t serialized_size(uint32_t k) {
    return 8 + 4 * coarse_count(k) + (size_t(kGridEntryBytes) << (2 * k));
  }
  // An all-constant grid of k levels whose every value is `v`.
  static CutGrid constant(uint32_t k, float v);

  float coarse_at(uint32_t level, uint64_t x, uint64_t y) const {
    return coarse[coarse_count(level) + (y << level) + x];
  }
  float& coarse_at(uint32_t level, uint64_t x, uint64_t y) {
    return coarse[coarse_count(level) + (y << level) + x];
  }
  const GridEntry& entry(uint64_t x, uint64_t y) const { return entries[(y << levels) + x]; }
  GridEntry& entry(uint64_t x, uint64_t y) { return entries[(y << levels) + x]; }
  // Value at relative level `level` <= k (level k: the entry's value).
  float value_at(uint32_t level, uint64_t x, uint64_t y) const {
    return level < levels ? coarse_at(level, x, y) : entry(x, y).value;
  }

  std::vector<uint8_t> serialize() const;
  // Throws st::FormatError("<what>: ... at byte N") on any malformed input.
  static CutGrid parse(std::span<const uint8_t> bytes, const std::string& what,
                       uint32_t max_levels = kMaxSkipLevel);
};

// Stable tile ids (a format constant: ids are stored in packs and sent on the wire).
//   bits 63..58  level of the tile's root (0..kMaxLevel)
//   bits 57..0   morton code of the root (x in even bits, y in odd bits), < 4^level
// Sorting by id orders tiles by level, then along the Z curve.
inline constexpr uint32_t kTileIdLevelShift = 58;

// The fields of an id (no validity check: is_valid_tile_id).
constexpr uint32_t tile_level(uint64_t id) { return uint32_t(id >> kTileIdLevelShift); }
constexpr uint64_t tile_morton(uint64_t id) { return id & ((uint64_t(1) << kTileIdLevelShift) - 1); }
// The tile j levels above `id`'s root that covers it (contract: j <= tile_level(id)).
constexpr uint64_t tile_parent(uint64_t id, uint32_t j) {
  return (uint64_t(tile_level(id) - j) << kTileIdLevelShift) | (tile_morton(id) >> (2 * j));
}
// Which of tile_parent(id, j)'s 4^j descendants j levels down `id` is: the morton code
// of its root within the parent's.
constexpr uint64_t tile_child_morton(uint64_t id, uint32_t j) { return tile_morton(id) & ((uint64_t(1) << (2 * j)) - 1); }

struct TileAddress {
  uint32_t level = 0;
  uint32_t x = 0, y = 0;
  bool operator==(const TileAddress&) const = default;
};

uint64_t make_tile_id(uint32_t level, uint32_t x, uint32_t y);  // asserts level <= 20
bool is_valid_tile_id(uint64_t id);
TileAddress tile_address(uint64_t id);  // throws st::FormatError on an invalid id
std::string describe_tile(uint64_t id);  // "tile 0x... (level l, x X, y Y)"

}  // namespace st

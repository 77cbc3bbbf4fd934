// The map preview: the answers of a few levels below the skip level K, under every
// skip-grid entry that is not constant, carried with the skip grid (tiles/PACK.md "Map
// preview") so that a client answers from level K + p, not K, while a tile streams in.
//
// Every value is what the fully resident pack answers at that node (its tiles' own
// values, MH 2016 §3.2: a node's value answers for its descendants), so with the preview
// and no tile a lookup at a level <= K + p answers exactly what it answers with every
// tile resident, and finer lookups answer the level-(K + p) node above them. Tiles still
// answer everything once resident: the lossless invariant is the tiles' own.
//
// Stored sparsely: a node is stored only where its value differs (bit pattern) from the
// value its parent answers; an unstored node answers its parent's value, and relative
// level 0 is the entry's own value.
//
// Serialized layout (little-endian; format constants; pinned by map_preview_test):
//   off         size      field
//   0           4         magic "STPR"
//   4           4         levels p (0..kMaxPreviewLevels)
//   8           4         cells c: the skip grid's non-constant entries, in row-major order
//   12          4         residual bytes r
//   16          8 * w * c stored-node masks, w = ceil(nodes(p) / 64) u64 words per cell,
//                         nodes(p) = (4^(p+1) - 4) / 3; node (j, x, y), 1 <= j <= p, x, y
//                         relative to the cell, is bit (4^j - 4)/3 + y 2^j + x (bit b in
//                         word b / 64, LSB first); bits >= nodes(p) are 0
//   16 + 8wc    r         one residual per stored node, cell by cell in bit order: an
//                         unsigned LEB128 varint (1..5 bytes, below 2^32) z, the residual
//                         e = (z >> 1) XOR -(z AND 1) (zigzag), the node's f32 bit pattern
//                         = prediction + e modulo 2^32
// Prediction (integers modulo 2^32 on bit patterns; a level's answers as an s x s grid,
// s = 2^j, an unstored node taking its parent's pattern, relative level 0 the entry's
// value, nodes row-major): L, U, UL the left, upper, upper-left neighbours, LL, UU two
// to the left / above: x, y >= 1: L + U - UL; else x >= 2: 2L - LL; else y >= 2: 2U - UU;
// else x = 1: L; else y = 1: U; else the parent. The answers of a plane tile (a plane at
// node centres) and of trees on slopes are nearly affine, so residuals are mostly tiny.
// The values' count is the masks' popcount; no value is NaN; 16 + 8wc + r <= kMaxPreviewBytes.
// The layout before residual values (magic "STPV", raw f32 values) is refused by its magic.
#pragma once
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/page_table.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

// Format constants.
inline constexpr uint32_t kPreviewMagic = 0x52505453;     // "STPR"
inline constexpr uint32_t kPreviewMagicRaw = 0x56505453;  // "STPV": the layout before residuals, refused
inline constexpr uint32_t kMaxPreviewLevels = 4;        // 340 nodes (6 mask words) a cell
inline constexpr uint64_t kMaxPreviewBytes = 16ull << 20;
inline constexpr uint32_t kPreviewHeaderBytes = 16;

class MapPreview {
 public:
  static uint32_t nodes(uint32_t p) { return uint32_t(((uint64_t(1) << (2 * (p + 1))) - 4) / 3); }
  static uint32_t words(uint32_t p) { return (nodes(p) + 63) / 64; }

  // An empty preview (p = 0) of a grid.
  MapPreview() = default;
  // Answers of levels K+1 .. K+p under `grid`'s non-constant entries, from `depth(level,
  // x, y)` (the full pack's answer).
  static MapPreview build(const CutGrid& grid, uint32_t p,
                          const std::function<float(uint32_t, uint64_t, uint64_t)>& depth);
  // Checks everything against `grid` (the cells must be its non-constant entries) and the
  // map level; throws st::FormatError("<what>: ... at byte N").
  static MapPreview parse(std::span<const uint8_t> bytes, const CutGrid& grid, uint32_t map_level,
                          const std::string& what);
  std::vector<uint8_t> serialize() const;
  uint64_t serialized_size() const { return kPreviewHeaderBytes + 8ull * masks_.size() + residuals_.size(); }

  uint32_t levels() const { return p_; }
  size_t cells() const { return base_.size(); }
  size_t stored_values() const { return values_.size(); }

  // What lookups read, as held (the GPU mirror uploads these: gpu/GPU_LAYOUT.md):
  // per skip-grid entry its cell ordinal (~0u: constant); per cell its first value's
  // index, its entry's value and words(p) mask words; the stored values.
  const std::vector<uint32_t>& ordinals() const { return ordinal_; }
  const std::vector<uint32_t>& bases() const { return base_; }
  const std::vector<float>& entry_values() const { return entry_value_; }
  const std::vector<uint64_t>& masks() const { return masks_; }
  const std::vector<float>& values() const { return values_; }

  // The answer at relative level j (0 <= j <= levels()) of node (lx, ly) (relative to
  // the cell) under skip-grid entry (ex, ey); `fallback` for a constant entry.
  float value(uint64_t ex, uint64_t ey, uint32_t j, uint64_t lx, uint64_t ly, float fallback) const noexcept;

  // The coarse answer for texel (level, x, y) when the walk `hit` (walk_page_table over
  // the skip grid of `k` levels) ended at a tile that is not at hand: the preview's node
  // at level min(level, k + p) when that is finer than the entry the walk reached, else
  // the entry's value (hit.value).
  float coarse_answer(uint32_t k, const PageHit& hit, uint32_t level, uint64_t x, uint64_t y) const noexcept;
  // For a walk that ended at a tile not at hand (hit.kind tile or absent): the shift s
  // such that every texel of `level` sharing (x >> s, y >> s) gets the same
  // coarse_answer: the preview node's square where the preview answers, else the
  // reached entry's (level - its level).
  uint32_t coarse_region_shift(uint32_t k, const PageHit& hit, uint32_t level) const noexcept;

 private:
  uint32_t p_ = 0, k_ = 0;
  std::vector<uint32_t> ordinal_;  // per skip-grid entry: its cell's ordinal, or ~0u (constant)
  std::vector<uint32_t> base_;     // per cell: index of its first value
  std::vector<float> entry_value_; // per cell: its skip-grid entry's value (relative level 0)
  std::vector<uint64_t> masks_;    // words(p) per cell
  std::vector<float> values_;
  std::vector<uint8_t> residuals_;  // the values as serialized (the residuals' varints)

  std::vector<uint8_t> encode_values() const;
};

}  // namespace st

// Plane tiles (plane_format.hpp, tiles/core/PLANES.md): opening and validating a buffer
// "STPN" of plane blocks over an inner DAG-MH, MMH or MH buffer. Safe for untrusted input:
// validate_plane_tile checks every field once and throws st::FormatError naming the field
// and its byte offset; after it, lookups never read out of bounds.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <span>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/plane_format.hpp"

namespace st {

// Whether `bytes` start with the plane tile magic "STPN".
bool is_plane_buffer(std::span<const uint8_t> bytes);

struct PlaneTileView {
  uint32_t finest_level = 0;
  uint32_t plane_count = 0;          // blocks
  uint32_t table_count = 0;          // distinct planes
  uint32_t label_count = 0;          // labels section slots (a labelled block one, a wide one two)
  std::span<const uint8_t> table;    // table_count * 24 bytes
  std::span<const uint8_t> records;  // plane_count * 8 bytes
  std::span<const uint8_t> labels;   // label_count * 24 bytes
  std::span<const uint8_t> inner;    // the inner buffer

  // Block i with the plane that answers its finest texel (fx, fy) (tile coordinates, inside
  // the block), resolved to the block's corner.
  planes::Plane plane_at(uint32_t i, uint32_t fx, uint32_t fy) const;
  // Block i with its first plane (a labelled block's palette entry 0).
  planes::Plane plane(uint32_t i) const;
  // Index of the plane whose block holds finest texel (x, y), or -1.
  int64_t find(uint32_t x, uint32_t y) const;

  // The block records' one reader (plane_format.hpp), for find and the evaluator's searches:
  // block i's first finest texel's Morton code, its side's log2, the code one past its
  // last texel, and the first block in [lo, hi) starting after code m (blocks are sorted
  // and disjoint: the one before it is the only block that can hold m).
  uint32_t block_start(uint32_t i) const;
  uint32_t block_shift(uint32_t i) const;
  uint64_t block_end(uint32_t i) const;
  uint32_t first_block_after(uint64_t m, uint32_t lo, uint32_t hi) const;
};

// Throws st::FormatError naming the first bad field; does not open the inner buffer.
PlaneTileView validate_plane_tile(std::span<const uint8_t> bytes);

// Opens a plane tile: validate_plane_tile, then the inner buffer with `open_inner` (which
// must refuse what it does not know); its finest level must be the tile's.
std::unique_ptr<Evaluator> open_plane_tile(
    std::span<const uint8_t> bytes,
    const std::function<std::unique_ptr<Evaluator>(std::span<const uint8_t>)>& open_inner);

}  // namespace st

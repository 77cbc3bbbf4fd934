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
  uint32_t plane_count = 0;
  std::span<const uint8_t> records;  // plane_count * 32 bytes
  std::span<const uint8_t> inner;    // the inner buffer

  planes::Plane plane(uint32_t i) const;
  // Index of the plane whose block holds finest texel (x, y), or -1.
  int64_t find(uint32_t x, uint32_t y) const;
};

// Throws st::FormatError naming the first bad field; does not open the inner buffer.
PlaneTileView validate_plane_tile(std::span<const uint8_t> bytes);

// Opens a plane tile: validate_plane_tile, then the inner buffer with `open_inner` (which
// must refuse what it does not know); its finest level must be the tile's.
std::unique_ptr<Evaluator> open_plane_tile(
    std::span<const uint8_t> bytes,
    const std::function<std::unique_ptr<Evaluator>(std::span<const uint8_t>)>& open_inner);

}  // namespace st

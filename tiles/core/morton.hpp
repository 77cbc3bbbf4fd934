// Morton (Z-order) codes of texel coordinates: x in the even bits, y in the odd bits.
// Tile ids (tile_cut_grid.hpp) and the hierarchy's node lists (tiles/encode/hierarchy.hpp)
// are ordered by them, so the four children of a node are contiguous in child order.
#pragma once
#include <cstdint>

namespace st {

inline uint64_t morton_spread(uint32_t v) {
  uint64_t x = v;
  x = (x | (x << 16)) & 0x0000FFFF0000FFFFull;
  x = (x | (x << 8)) & 0x00FF00FF00FF00FFull;
  x = (x | (x << 4)) & 0x0F0F0F0F0F0F0F0Full;
  x = (x | (x << 2)) & 0x3333333333333333ull;
  x = (x | (x << 1)) & 0x5555555555555555ull;
  return x;
}
inline uint32_t morton_compact(uint64_t x) {
  x &= 0x5555555555555555ull;
  x = (x | (x >> 1)) & 0x3333333333333333ull;
  x = (x | (x >> 2)) & 0x0F0F0F0F0F0F0F0Full;
  x = (x | (x >> 4)) & 0x00FF00FF00FF00FFull;
  x = (x | (x >> 8)) & 0x0000FFFF0000FFFFull;
  x = (x | (x >> 16)) & 0x00000000FFFFFFFFull;
  return uint32_t(x);
}
inline uint64_t morton_encode(uint32_t x, uint32_t y) {
  return morton_spread(x) | (morton_spread(y) << 1);
}

}  // namespace st

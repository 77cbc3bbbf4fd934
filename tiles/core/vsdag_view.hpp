// Reading a validated voxel shadow DAG buffer in place (VSDAG.md): vsdag::validate checks
// every header field, section extent, node, reference and leaf index once, so these
// lookups need no bounds checks. Every reference a walk follows was checked to hold a
// node of the level the walk is at (or a leaf index for a z-node's child).
#pragma once
#include <bit>
#include <cstdint>
#include <cstring>
#include <span>

#include "common/bit_count.hpp"
#include "tiles/core/vsdag_format.hpp"

namespace st::vsdag {

// Mixed children before slot c of a mask (their references follow the mask in slot order).
inline uint32_t mixed_bits(uint32_t mask) { return (mask >> 1) & ~mask & 0x5555u; }
inline uint32_t ref_slot(uint32_t mask, uint32_t c) {
  return bit_count(mixed_bits(mask) & ((1u << (2 * c)) - 1));
}

struct View {
  Shape shape;
  const uint8_t* leaves = nullptr;
  const uint8_t* grid = nullptr;
  const uint8_t* nodes = nullptr;
  uint32_t leaf_count = 0, node_words = 0;

  uint32_t node_word(uint32_t w) const { uint32_t v; std::memcpy(&v, nodes + 4 * size_t(w), 4); return v; }
  uint32_t grid_word(uint32_t c) const { uint32_t v; std::memcpy(&v, grid + 4 * size_t(c), 4); return v; }
  uint64_t leaf(uint32_t i) const { uint64_t v; std::memcpy(&v, leaves + 8 * size_t(i), 8); return v; }
  uint32_t slabs() const { return 1u << shape.z_bits; }

  // Voxel (x, y, k) lit? (§4: descend while the child is mixed; a leaf answers by its bit.)
  bool lit(uint64_t x, uint64_t y, uint32_t k) const {
    const uint32_t cell = grid_word(shape.grid_cell(x, y, k));
    if ((cell >> kStateShift) != kMixed) return (cell >> kStateShift) == kLit;
    uint32_t w = cell & kIndexMask;
    for (uint32_t i = 0; i < shape.levels; ++i) {
      const uint32_t mask = node_word(w), c = shape.child(i, x, y, k), s = (mask >> (2 * c)) & 3;
      if (s != kMixed) return s == kLit;
      w = node_word(w + 1 + ref_slot(mask, c));
    }
    const uint32_t mask = node_word(w), c = k & 7, s = (mask >> (2 * c)) & 3;
    if (s != kMixed) return s == kLit;
    return (leaf(node_word(w + 1 + ref_slot(mask, c))) >> leaf_bit(x, y)) & 1;
  }

  // The column's transition: the smallest slab f with voxel f shadowed and f - 1 lit,
  // found by bisection (z_bits + 1 walks); slabs() if the top slab is lit. The encoder
  // writes every column lit above one transition and shadowed below it, so f is then the
  // first shadowed slab (VSDAG.md "Depth values"); on any other buffer it is still a
  // slab where the column turns from lit to shadowed.
  uint32_t first_shadow_slab(uint64_t x, uint64_t y) const {
    uint32_t a = 0, b = slabs();
    while (a < b) {
      const uint32_t m = a + (b - a) / 2;
      if (lit(x, y, m)) a = m + 1;
      else b = m;
    }
    return a;
  }
};

// Checks the whole buffer (VSDAG.md "Validation"); throws st::FormatError("vsdag: <field>
// at byte <offset>: <what>") on the first violation. The view borrows `bytes`.
View validate(std::span<const uint8_t> bytes);

}  // namespace st::vsdag

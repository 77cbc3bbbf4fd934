// The octree encoder's working form of an OctHierarchy (private to tiles/encode): every
// node once, level by level in code order, so a node's children are contiguous, in slot
// order, from first_child, and every child comes after its parent. Shared by the encoder
// (mh_octree_encode.cpp) and its subtree merger (mh_octree_merge.cpp).
#pragma once
#include <bit>
#include <cstdint>
#include <vector>

#include "tiles/core/mh_octree_format.hpp"

namespace st::moct_detail {

struct Flat {
  std::vector<uint32_t> first_child;
  std::vector<uint8_t> mask, level, valued;
  std::vector<float> value;
  std::vector<float> lo, hi;  // valued nodes: the interval the builder gave (OctNode::lo, hi)
  size_t size() const { return mask.size(); }
  uint32_t children(uint32_t n) const { return uint32_t(std::popcount(unsigned(mask[n]))); }
  uint32_t kind(uint32_t n) const {
    return valued[n] ? (mask[n] ? moct::kCodeInner : moct::kCodeLeaf) : moct::kCodeEmpty;
  }
  uint32_t code_mask(uint32_t n) const {
    uint32_t m = 0, c = first_child[n];
    for (uint32_t slot = 0; slot < moct::kSlots; ++slot)
      if (mask[n] >> slot & 1u) m |= kind(c++) << (2 * slot);
    return m;
  }
};

}  // namespace st::moct_detail

// A sparse multiresolution hierarchy (MH §3.1) of one square tile, in memory: what the
// constructions (bottom-up Alg. 2, top-down Alg. 1) produce and every encoding consumes.
//
// Levels 0..depth; level l is a 2^l x 2^l grid over the tile (level `depth` = the tile's
// texels). Only *present* nodes are stored: valued nodes (inner-full or leaf) and empty
// nodes that exist only to connect valued descendants (MH §3.2). The root is always
// present and valued.
//
// Child numbering (morton codes: tiles/core/morton.hpp): child c of node (x, y) at level l is (2x + (c & 1), 2y + (c >> 1)) at
// level l + 1. Morton codes interleave x in the even bits and y in the odd bits, so the
// children of a node are contiguous in the next level's morton-sorted node list, in
// child order, starting at the sum of popcount(child_mask) over the nodes before it.
//
// Meaning: depth(l, x, y) is the value of the deepest valued node on the root path to
// (l, x, y) at a level <= l. A valued node's [lo, hi] is the set of values it may take
// without breaking the lossless invariant of any texel it answers for; `value` lies in it.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tiles/core/morton.hpp"

namespace st {

struct HNode {
  uint64_t morton = 0;     // position at its level
  float value = 0;         // meaningful iff has_value
  float lo = 0, hi = 0;    // admissible values (has_value nodes only)
  uint8_t child_mask = 0;  // bit c set: child c present at level + 1
  uint8_t has_value = 0;   // 1 valued, 0 empty (then child_mask != 0)
};

struct Hierarchy {
  uint32_t depth = 0;                      // finest level; the tile is 2^depth a side
  std::vector<std::vector<HNode>> levels;  // levels[l]: present nodes, sorted by morton

  // first_child[l][j]: index in levels[l+1] of node j's first child (prefix popcounts).
  std::vector<std::vector<uint32_t>> first_child_index() const;
  size_t node_count() const;
  size_t valued_count() const;
  // Reference lookup by walking the node lists (slow; tests and encoders' self-checks).
  float depth_at(uint32_t level, uint64_t x, uint64_t y) const;
};

}  // namespace st

// The sparse multiresolution hierarchy of a shadow-map stack (MH 2016 §4): N coherent
// maps of the same size (samples along a sun's path, points on an area light) stacked
// along a third axis w and decomposed as one octree, bottom-up, with every step of
// MH §3.1 Alg. 2 carried over to eight children.
//
// Geometry (tiles/core/mh_octree_format.hpp `moct::Geometry`): slices are 2^n a side,
// the stack is padded to 2^k >= N slices with placeholders; the finest min(n, k) steps
// halve x, y and w, the coarser ones only the longer axis. Placeholders (slices N..2^k-1
// and, in the paper's cube, everything beyond the stack) take the interval that contains
// every depth: MH §4 gives them [0, 1], the whole depth range; we use [-FLT_MAX, FLT_MAX],
// which is the same for depths in [0, 1] and stays neutral for any finite input. Such a
// child is always covered by its parent's value and never stored.
//
// Node codes: the root is code 0; child slot c (cx | cy << 1 | cw << 2) of a node with
// code P at level l has code (P << a) | compact(c), a = 3, 2 or 1 bits for a step that
// halves x, y, w / x, y / w (compact keeps the bits of the halved axes). Each level's
// present nodes are sorted by code, so the children of a node are contiguous in the next
// level, in slot order.
//
// Meaning: depth_at(l, x, y, w) is the value of the deepest valued node on the path to
// (l, x, y, w) at a level <= l; a valued node's [lo, hi] is exactly the intersection of
// the intervals of the texels it answers for, and its value is the roundest float of its
// middle three quarters (mh_internal.hpp `central_roundest`: the value choice that makes
// equal subtrees, MHOCT.md).
#pragma once
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "tiles/core/interval.hpp"
#include "tiles/core/mh_octree_format.hpp"

namespace st {

// N slices of the depth-interval map of level `level`: texel (x, y) of slice w is
// data[(w * side + y) * side + x], side = 2^level.
struct IntervalStack {
  uint32_t level = 0;
  uint32_t slices = 0;
  std::vector<Interval> data;

  uint64_t side() const { return uint64_t(1) << level; }
  Interval& at(uint64_t x, uint64_t y, uint64_t w) { return data[(w * side() + y) * side() + x]; }
  const Interval& at(uint64_t x, uint64_t y, uint64_t w) const { return data[(w * side() + y) * side() + x]; }
};

struct OctNode {
  uint64_t code = 0;       // position at its level (see above)
  float value = 0;         // meaningful iff has_value
  float lo = 0, hi = 0;    // admissible values (valued nodes)
  uint8_t child_mask = 0;  // bit c: child slot c present at level + 1
  uint8_t has_value = 0;   // 1 valued, 0 empty (then child_mask != 0)
};

struct OctHierarchy {
  moct::Geometry geo;
  uint32_t slices = 0;                       // N real slices; w >= N are placeholders
  std::vector<std::vector<OctNode>> levels;  // levels[l]: present nodes sorted by code

  size_t node_count() const;
  size_t valued_count() const;
  // Reference lookup by walking the node lists (tests, self-checks): (x, y, w) at level l,
  // x, y < 2^geo.xy_bits(l), w < 2^geo.w_bits(l).
  float depth_at(uint32_t l, uint64_t x, uint64_t y, uint64_t w) const;
};

// Code of (x, y, w) at level l, and back.
uint64_t oct_code(const moct::Geometry& g, uint32_t l, uint64_t x, uint64_t y, uint64_t w);
void oct_coords(const moct::Geometry& g, uint32_t l, uint64_t code, uint64_t& x, uint64_t& y, uint64_t& w);

// Builds the octree of a stack (slices <= 2^14 a side, 1..4096 slices, intervals finite
// with lo <= hi). Throws st::Error naming the texel and slice of a bad interval, or the
// bad shape. The result satisfies the lossless invariant on every texel of every slice:
// depth_at(L, x, y, w) lies in the texel's interval (L = geo.depth()).
//
// `w_level` (blocked builds, tiles/encode/stack_blocked.hpp): pad to 2^w_level slices
// instead of the smallest power of two >= slices (slices <= 2^w_level), so the result is
// the subtree of one node of a larger stack whose slices past `slices` are placeholders.
OctHierarchy build_octree(const IntervalStack& stack, std::optional<uint32_t> w_level = std::nullopt);

// The levels 0..lb of an octree whose level-lb nodes are known (a blocked build): `iv[c]`
// and `child_mask[c]` are the interval and child mask of the level-lb node of code c as
// build_octree gives its subtree's root (a node wholly in the padding: the placeholder
// interval [-FLT_MAX, FLT_MAX] and mask 0). Runs the same level steps as build_octree
// above level lb and returns, per level 0..lb and code, the value of the deepest valued
// node on the path to it (the value a lookup stopping there answers); `present_nodes`
// gets the count of stored nodes at levels 0..lb-1.
std::vector<std::vector<float>> octree_top_values(const moct::Geometry& g, uint32_t lb, const std::vector<Interval>& iv,
                                                  const std::vector<uint8_t>& child_mask,
                                                  size_t* present_nodes = nullptr);

}  // namespace st

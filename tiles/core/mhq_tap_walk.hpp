// The single-tap walk of an MH or MMH tree (MHQUAD.md) for batches of taps: the walk of
// TreeEvaluator::depth_region (mh_quadtree_reader.cpp), one level per step, resumed from
// the last walk's path (tap_batch.hpp's WalkPath), written for taps that each walk
// several levels, as on a real level's open mesh, where almost every region is one
// texel and the taps of a view fall a dozen texels apart (a pixel's footprint at 8192^2):
//  - a node on the path is 8 bytes (its word index with its child code in the top two
//    bits, and its value: MMH the decoded float's bits, MH the word of the last valued
//    node's float, read once at the end), so the path stays in a few cache lines;
//  - a step has no data-dependent branch except the two that end the walk: the child's
//    words-before-it come from a table (the build has no popcount instruction), and the
//    value is chosen with selects (an empty child keeps its parent's, an absolute flag
//    takes the stored float as is, else MMH adds it), so the only mispredicted branch is
//    usually the one where the walk stops;
//  - every step reads the node word, then the child's value word, in the child's line.
// Each walk is depth_region's, level for level, from a node on its own path: the same
// value bits and the same region (tests/tiles/mhq_tap_walk_test.cpp checks every texel,
// in many orders). Callers pass a validated tree (mhq::validate): every child block and
// value word a walk reads lies inside it.
#pragma once
#include <array>
#include <cstdint>

#include "common/bytes.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st::mhq {

// A node the last walk entered: its word index (bits 0-29; a tree holds < 2^30 words)
// and its code (bits 30-31: kCodeLeaf, kCodeEmpty, kCodeInner), and its value (MMH: the
// decoded float's bits; MH: the word index of the last valued node's float).
struct TapStep {
  uint32_t node = 0, value = 0;
};
using TapWalkPath = WalkPath<TapStep>;

// child_skip(mask, slot) for every 8-bit mask and slot, indexed (mask << 2) | slot.
inline constexpr std::array<uint8_t, 1024> kChildSkip = [] {
  std::array<uint8_t, 1024> t{};
  for (uint32_t m = 0; m < 256; ++m)
    for (uint32_t s = 0; s < 4; ++s) {
      uint32_t n = 0;
      for (uint32_t b = 0; b < 2 * s; ++b) n += (m >> b) & 1u;
      t[(m << 2) | s] = uint8_t(n);
    }
  return t;
}();

template <bool kRelative>
class TapWalker {
 public:
  static constexpr uint32_t kPosMask = (1u << 30) - 1;

  // tree: the first tree word; shift: MH's per-level offset shifts (MMH keeps its own in
  // each node word).
  TapWalker(const uint8_t* tree, bool root_leaf, const std::array<uint8_t, kMaxLevels>& shift)
      : tree_(tree), shift_(shift) {
    root_.node = root_leaf ? kCodeLeaf << 30 : kCodeInner << 30;
    const uint32_t vp = root_leaf ? 0 : 1;
    root_.value = kRelative ? word(vp) : vp;
  }

  // depth_region(level, x, y) for x, y < 2^level, level < kLevels of the path (33) and at
  // most the tree's finest level: the walk resumed from the deepest node of `path` on
  // this texel's path, which it leaves holding this walk's nodes.
  DepthRegion walk(TapWalkPath& path, uint32_t level, uint64_t x, uint64_t y) const noexcept {
    uint32_t l = 0;
    TapStep at;
    if (path.resume(level, x, y, l)) {
      at = path.at[l];
      path.hi = l;
    } else {
      at = root_;
      path.lo = path.hi = 0;
      path.at[0] = at;
    }
    path.level = level, path.x = x, path.y = y;
    for (;;) {
      const uint32_t code = at.node >> 30, pos = at.node & kPosMask;
      if (code == kCodeLeaf || l == level) {
        path.hi = l;
        return {value_of(at.value), level - l};
      }
      const uint32_t w = word(pos);
      const uint32_t bit = level - l - 1;
      const uint32_t slot = uint32_t((x >> bit) & 1u) | uint32_t(((y >> bit) & 1u) << 1);
      const uint32_t c = (w >> (2 * slot)) & 3u;
      if (c == kCodeNone) {  // the missing child's region
        path.hi = l;
        return {value_of(at.value), bit};
      }
      const uint32_t shift = kRelative ? word_shift(w) : shift_[l];
      const uint32_t child = uint32_t(block_start(pos, shift, word_offset(w))) + kChildSkip[((w & 0xFFu) << 2) | slot];
      const uint32_t vp = child + (c >> 1 & c);  // an inner child's value is its second word
      // Selects as masks (a compiler turns a ?: of these into branches, mispredicted about
      // half the time): an empty child keeps its parent's value.
      const uint32_t keep = 0u - uint32_t(c == kCodeEmpty);
      uint32_t own;
      if constexpr (kRelative) {
        const uint32_t stored = word(vp);  // an empty child's own word: read, not used
        const uint32_t sum = float_bits(mmh_add(bits_float(at.value), bits_float(stored)));
        const uint32_t absolute = 0u - ((word_abs_flags(w) >> slot) & 1u);
        own = (stored & absolute) | (sum & ~absolute);
      } else {
        own = vp;
      }
      at = TapStep{child | (c << 30), (at.value & keep) | (own & ~keep)};
      ++l;
      path.at[l] = at;
    }
  }

 private:
  uint32_t word(uint32_t w) const { return st::load_le<uint32_t>(tree_ + 4 * size_t(w)); }
  float value_of(uint32_t v) const {
    if constexpr (kRelative) return bits_float(v);
    return bits_float(word(v));
  }

  const uint8_t* tree_;
  std::array<uint8_t, kMaxLevels> shift_;
  TapStep root_;
};

}  // namespace st::mhq

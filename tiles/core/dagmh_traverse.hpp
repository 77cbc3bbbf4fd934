// DAG-MH traversal (DAG-MH §3.5, Alg. 1) over a buffer's sections. Used by the evaluator,
// by the encoder to fill the skip table and by the validator to check it.
//
// A lookup of texel (x, y) of `level` walks inner nodes keeping two value indices
// (§3.5): `base`, the depth-first index of the current node's first value, and `last`,
// the index of the deepest valued node passed. Entering child c adds the child's stored
// value offset to `base`. A treelet answers bottom-up from its bitmap (Alg. 1).
//
// Safety (after open_dagmh's validation): every reference is a node start or treelet
// number in range, child references point strictly forward (so the walk ends; it also
// never goes below `level`), and every node's value offsets equal the value counts of
// its subtree, so every index a walk returns is < value_count. Coordinates only select
// child bits, so any x, y is harmless.
#pragma once
#include <algorithm>
#include <bit>
#include <cstdint>

#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/dagmh_values.hpp"

namespace st::dagmh {

// Nodes in the subtree of a treelet node at treelet level n (itself included).
inline constexpr uint32_t kTreeletSubtree[kTreeletLevels] = {85, 21, 5, 1};

inline bool treelet_bit(uint64_t low, uint32_t high, uint32_t p) {
  return p < 64 ? (low >> p) & 1 : (high >> (p - 64)) & 1;
}
// Set bits of the 85-bit treelet bitmap before position p.
inline uint32_t treelet_rank(uint64_t low, uint32_t high, uint32_t p) {
  return p < 64 ? bit_count(uint64_t(low & ((uint64_t(1) << p) - 1)))
                : bit_count(uint64_t(low)) + bit_count(uint64_t(high & ((1u << (p - 64)) - 1)));
}
// Whether any of the bitmap's bits [from, to) is set (to <= 85).
inline bool treelet_any(uint64_t low, uint32_t high, uint32_t from, uint32_t to) {
  auto bits = [](uint32_t a, uint32_t b) -> uint64_t {  // mask of bits [a, b), a < b <= 64
    return (b >= 64 ? ~uint64_t(0) : (uint64_t(1) << b) - 1) & ~((uint64_t(1) << a) - 1);
  };
  if (from < std::min(to, 64u) && (low & bits(from, std::min(to, 64u)))) return true;
  const uint32_t hf = from > 64 ? from - 64 : 0, ht = to > 64 ? to - 64 : 0;
  return hf < ht && (uint64_t(high) & bits(hf, ht));
}

struct View {
  const uint8_t* skip = nullptr;
  const uint8_t* nodes = nullptr;
  const uint8_t* treelets = nullptr;
  const uint8_t* chunks = nullptr;
  const uint8_t* multipliers = nullptr;
  uint32_t finest_level = 0, skip_level = 0, root_ref = 0, value_count = 0;
  // A tile with kFlagDictionary (DAGMH.md "Dictionary"): references below the dictionary's node
  // words / treelet count name the dictionary's, the others the tile's own, offset by
  // them. Without the flag they stay zero (every reference is the tile's own).
  uint32_t dict_node_words = 0, dict_treelet_count = 0;
  const uint8_t* dict_nodes = nullptr;
  const uint8_t* dict_treelets = nullptr;

  // The inner node / treelet with this reference index (no allocation, one compare).
  const uint8_t* node_at(uint32_t index) const {
    return index < dict_node_words ? dict_nodes + size_t(index) * 4 : nodes + size_t(index - dict_node_words) * 4;
  }
  const uint8_t* treelet_at(uint32_t index) const {
    return index < dict_treelet_count ? dict_treelets + size_t(index) * kTreeletBytes
                                      : treelets + size_t(index - dict_treelet_count) * kTreeletBytes;
  }

  Cursor root() const { return {root_ref, 0, 0, 0}; }

  // The skip-list cursor for texel (x, y) of `level` >= skip_level (§3.7).
  Cursor skip_entry(uint32_t level, uint64_t x, uint64_t y) const {
    const uint32_t shift = level - skip_level;
    const uint64_t index = ((y >> shift) << skip_level) + (x >> shift);
    Cursor c;
    std::memcpy(&c, skip + index * sizeof(Cursor), sizeof(Cursor));
    return c;
  }

  // Where skip_entry(level, x, y) reads its entry (for a prefetch; skip_level > 0).
  const uint8_t* skip_entry_at(uint32_t level, uint64_t x, uint64_t y) const {
    const uint32_t shift = level - skip_level;
    return skip + (((y >> shift) << skip_level) + (x >> shift)) * sizeof(Cursor);
  }

  // Cheapest valid start for a walk to a node of level `stop` on the path to (x, y) at
  // `level`: the skip table when stop >= skip_level, else the root.
  Cursor start(uint32_t stop, uint32_t level, uint64_t x, uint64_t y) const {
    return skip_level > 0 && stop >= skip_level ? skip_entry(level, x, y) : root();
  }

  // Walks inner nodes from `c` towards (x, y) of `level` and stops at the first of: an
  // inner node at level `stop` (its own value not yet applied), a treelet, or a missing
  // child (ref = kRefNone, level = the missing child's level).
  Cursor descend(Cursor c, uint32_t stop, uint32_t level, uint64_t x, uint64_t y) const {
    while ((c.ref & kRefTagMask) == kRefInner && c.level < stop) {
      const uint8_t* node = node_at(c.ref & kRefIndexMask);
      const uint32_t flags = st::load_le<uint32_t>(node);
      if (flags & kNodeValuedBit) c.last = c.base;
      const uint32_t shift = level - c.level - 1;
      const uint32_t child = uint32_t((x >> shift) & 1) | uint32_t(((y >> shift) & 1) << 1);
      ++c.level;
      if (!((flags >> child) & 1)) {
        c.ref = kRefNone;
        return c;
      }
      // popcount of the 4-bit mask below the child, from a nibble table in a constant
      const uint32_t below = flags & kNodeChildMask & ((1u << child) - 1);
      const uint32_t rank = uint32_t(0x4332322132212110ull >> (4 * below)) & 0xF;
      const uint8_t* entry = node + 4 + 8 * rank;
      c.base += st::load_le<uint32_t>(entry + 4);
      c.ref = st::load_le<uint32_t>(entry) | ((flags >> (kNodeTreeletShift + child)) & 1 ? kRefTreelet : kRefInner);
    }
    return c;
  }

  // A treelet cursor's path to texel (x, y) of `level` (Alg. 1): the treelet's 85-bit
  // bitmap, the deepest treelet level on the path and each level's bit position.
  struct TreeletPath {
    uint64_t low = 0;
    uint32_t high = 0, depth = 0;
    uint32_t pos[kTreeletLevels] = {0, 0, 0, 0};
  };
  TreeletPath treelet_path(const Cursor& c, uint32_t level, uint64_t x, uint64_t y) const {
    TreeletPath tp;
    const uint8_t* t = treelet_at(c.ref & kRefIndexMask);
    tp.low = st::load_le<uint64_t>(t);
    tp.high = st::load_le<uint32_t>(t + 8);
    tp.depth = std::min<uint32_t>(level - c.level, kTreeletLevels - 1);
    for (uint32_t n = 1; n <= tp.depth; ++n) {
      const uint32_t s = level - c.level - n;
      const uint32_t child = uint32_t((x >> s) & 1) | uint32_t(((y >> s) & 1) << 1);
      tp.pos[n] = tp.pos[n - 1] + 1 + kTreeletStride[n - 1] * child;
    }
    return tp;
  }
  // Alg. 1's answer on that path: from the deepest treelet level up to the treelet root,
  // the first valued node answers, its index = base + set bits before it (depth-first);
  // `answered` is 1 + its treelet level, or 0 when none is set (c.last answers).
  static uint32_t treelet_answer(const Cursor& c, const TreeletPath& tp, uint32_t& answered) {
    for (uint32_t n = tp.depth + 1; n-- > 0;)
      if (treelet_bit(tp.low, tp.high, tp.pos[n])) {
        answered = n + 1;
        return c.base + treelet_rank(tp.low, tp.high, tp.pos[n]);
      }
    answered = 0;
    return c.last;
  }

  // The value index for (x, y) of `level`, given descend(c, level, level, x, y)'s cursor.
  uint32_t finish(const Cursor& c, uint32_t level, uint64_t x, uint64_t y) const {
    const uint32_t tag = c.ref & kRefTagMask;
    if (tag == kRefInner) return st::load_le<uint32_t>(node_at(c.ref & kRefIndexMask)) & kNodeValuedBit ? c.base : c.last;
    if (tag != kRefTreelet) return c.last;
    uint32_t answered;
    return treelet_answer(c, treelet_path(c, level, x, y), answered);
  }

  // finish() and the square of texels of `level` that share its answer, as a shift
  // (DepthRegion): below a missing child, every texel; in a treelet, the shallowest node
  // on the path, at or below the one that answered, with no set bit strictly inside its
  // subtree (no texel under it can find a deeper value), or the treelet's deepest node on
  // the path when the query level lies below the treelet (its subtree ends there).
  uint32_t finish_region(const Cursor& c, uint32_t level, uint64_t x, uint64_t y, uint32_t& shift) const {
    const uint32_t tag = c.ref & kRefTagMask;
    if (tag == kRefInner) {  // stopped at an inner node of `level` itself
      shift = 0;
      return finish(c, level, x, y);
    }
    if (tag != kRefTreelet) {  // the missing child at c.level
      shift = level - c.level;
      return c.last;
    }
    const TreeletPath tp = treelet_path(c, level, x, y);
    const uint64_t low = tp.low;
    const uint32_t high = tp.high, depth = tp.depth;
    const uint32_t* const pos = tp.pos;
    uint32_t answered;
    const uint32_t index = treelet_answer(c, tp, answered);
    uint32_t m = answered ? answered - 1 : 0;
    while (m < depth && treelet_any(low, high, pos[m] + 1, pos[m] + kTreeletSubtree[m])) ++m;
    shift = level - c.level - m;
    return index;
  }

  // finish_region's answer and a region at least as wide, for callers that keep answers
  // (the tile batch): the texels of `level` under a node `s` >= 1 levels above them (those
  // sharing x >> s, y >> s) whose child at bit s - 1 (the child index descend takes there)
  // is in the 4-bit `mask`. In a treelet, when the region node of finish_region lies below
  // the deepest set bit on the path (or none is set), every child of its parent whose
  // subtree holds no set bit (down to treelet level `depth`: the node's own bit there)
  // shares the answer too: its texels' paths pass the same set bits. Else the mask is the
  // region node alone. An inner node of `level` answers its texel alone; the missing-child
  // case is the caller's (it knows the parent's flags).
  uint32_t finish_siblings(const Cursor& c, uint32_t level, uint64_t x, uint64_t y, uint32_t& s,
                           uint32_t& mask) const {
    auto child_at = [&](uint32_t shift) {
      return uint32_t((x >> shift) & 1) | uint32_t(((y >> shift) & 1) << 1);
    };
    if ((c.ref & kRefTagMask) != kRefTreelet) {  // an inner node of `level`
      s = 1, mask = 1u << child_at(0);
      return finish(c, level, x, y);
    }
    const TreeletPath tp = treelet_path(c, level, x, y);
    const uint64_t low = tp.low;
    const uint32_t high = tp.high, depth = tp.depth;
    const uint32_t* const pos = tp.pos;
    uint32_t answered;  // 1 + the treelet level of the set bit that answers
    const uint32_t index = treelet_answer(c, tp, answered);
    uint32_t m = answered ? answered - 1 : 0;
    while (m < depth && treelet_any(low, high, pos[m] + 1, pos[m] + kTreeletSubtree[m])) ++m;
    const uint32_t shift = level - c.level - m;  // finish_region's region
    s = shift + 1;
    if (m == 0 || m < answered) {
      mask = 1u << child_at(shift);
      return index;
    }
    const uint32_t size = m == depth ? 1 : kTreeletSubtree[m];
    mask = 0;
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t p = pos[m - 1] + 1 + kTreeletStride[m - 1] * k;
      if (!treelet_any(low, high, p, p + size)) mask |= 1u << k;
    }
    return index;
  }

  float value(uint32_t index) const { return read_value(chunks, multipliers, index); }
  // The chunk value(index) reads first (for a prefetch).
  const uint8_t* chunk_at(uint32_t index) const { return chunks + size_t(index / kChunkValues) * sizeof(ChunkInfo); }
  // The multiplier bits value(index) reads after the chunk, or nullptr (value_bits_at).
  const uint8_t* value_bits_at(uint32_t index) const { return dagmh::value_bits_at(chunks, multipliers, index); }

  uint32_t lookup_index(uint32_t level, uint64_t x, uint64_t y) const {
    const Cursor c = descend(start(level, level, x, y), level, level, x, y);
    return finish(c, level, x, y);
  }
};

}  // namespace st::dagmh

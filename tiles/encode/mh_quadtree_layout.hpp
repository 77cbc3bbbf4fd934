// Encoder side of the MH quadtree and MMH (tiles/core/mh_quadtree_format.hpp): the
// hierarchy flattened into arrays, the depth-first block layout with per-level offset
// scales found by search (MH §3.2 after Lefebvre & Hoppe 2007), and the serializer.
// Internal to tiles/core; callers use encode_mh / encode_mmh (encoding.hpp).
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/mh_quadtree_format.hpp"

namespace st::mhq {

// A Hierarchy in level order: node n of level l has flat index level_begin[l] + j. The
// children of a node are contiguous in the next level (hierarchy.hpp), so one index
// (first_child) and the 4-bit presence mask locate them.
struct FlatTree {
  uint32_t depth = 0;
  std::vector<uint32_t> level_begin;  // depth + 2 entries; last = node count
  std::vector<uint32_t> first_child;  // flat index of the first present child
  std::vector<uint8_t> mask;          // HNode::child_mask (bit c: child slot c present)
  std::vector<uint8_t> level;
  std::vector<uint8_t> valued;
  std::vector<float> value, lo, hi;

  size_t size() const { return mask.size(); }
  uint32_t child(uint32_t n, uint32_t slot) const {
    return first_child[n] + popcount8(uint32_t(mask[n]) & ((1u << slot) - 1u));
  }
  // The node's own 2-bit code (kCodeLeaf / kCodeEmpty / kCodeInner).
  uint32_t code(uint32_t n) const {
    return valued[n] ? (mask[n] ? kCodeInner : kCodeLeaf) : kCodeEmpty;
  }
  // The node word's child mask: 2 bits per slot from the children's codes.
  uint32_t code_mask(uint32_t n) const;
};

// Checks the hierarchy's shape (levels, morton order, child counts, finite values; with
// `need_intervals` also lo <= value <= hi) and flattens it. Throws st::Error naming the
// level and node at fault.
FlatTree flatten(const Hierarchy& h, bool need_intervals);

// What the layout emits. Empty vectors mean the plain MH tree: every node emitted, each
// node points at its own children, values stored as they are.
struct EmitPlan {
  bool relative = false;                      // MMH format (magic, flags, pad byte)
  std::vector<uint8_t> alive;                 // node emitted (MMH: not inside a merged-away subtree)
  std::vector<uint32_t> block_owner;          // node whose children block this node points at
  std::vector<uint32_t> block_parent_levels;  // per owner: bitmask of its parents' levels
  std::vector<float> stored;                  // value word (MMH: relative or absolute)
  std::vector<uint8_t> absolute;              // MMH: value stored absolute
};

struct LayoutStats {
  std::array<uint8_t, kMaxLevels> shift{};  // chosen per-level log2 scales
  uint64_t words = 0, padding_words = 0;
  uint32_t nodes = 0;
  uint32_t layout_passes = 0;
};

// Lays the plan out depth-first (a node's children block follows the blocks of its
// earlier siblings' subtrees, so offsets shrink level by level, MH §3.2), searches the
// per-level scales and writes the buffer. Throws st::Error when the buffer would exceed
// the 32-bit byte_size (the caller cuts such a tile deeper).
// The plain tree laid out without scaling: each node's word and each children block's
// word. MMH uses it to keep merged pointers within 16-bit reach.
void unscaled_layout(const FlatTree& t, std::vector<uint32_t>& pos, std::vector<uint32_t>& block);

std::vector<uint8_t> serialize(const FlatTree& t, const EmitPlan& plan, LayoutStats* stats = nullptr);

}  // namespace st::mhq

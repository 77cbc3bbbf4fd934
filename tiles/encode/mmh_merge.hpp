// MMH: the MH quadtree with compatible subtrees merged (ARCHITECTURE.md "Encodings", after the
// MH/MMH authors' public demo). Plans which subtrees share one children block and what
// each shared node stores; mh_quadtree_layout.cpp then lays the plan out.
//
// Rules (each one keeps the lossless invariant provable, see MHQUAD.md):
// - Values are stored relative to the decoded value of the nearest valued ancestor
//   (decoder: mmh_add(ancestor, stored)) so a pattern repeated at another depth offset
//   stores the same numbers; a value no relative number decodes into stays absolute
//   (flag bit in the parent's node word).
// - Candidates (nodes with children, height <= max_height) are grouped by height and a
//   shape hash; each is tested against at most `window` later candidates of its group;
//   a quick reject when the first values cannot meet; then a full recursive comparison
//   of topology (masks, node kinds) and values. Never a hash alone.
// - A merge picks, for every shared valued node, one stored number that decodes inside
//   that node's interval on every path into the block (the merger and all its
//   mergees), each path with its own ancestor value, checked with mmh_add exactly;
//   otherwise the pair is not merged. The chosen numbers sit mid-intersection, so later
//   merges into the same block keep room.
// - The mergee is the earlier node in depth-first pre-order, so the shared block (laid
//   out when the merger is visited) lies after every parent: offsets stay forward.
// - Big subtrees first (heights descending): when a height is done, no value at or
//   above it changes again, so every path into a node (through the shared blocks above
//   it, each with its own decoded ancestors) can be enumerated and stays valid. Nodes
//   inside shared blocks may merge again (nested repeats), checked on all their paths;
//   a merger is never itself merged away; at most max_paths paths reach one block.
// After planning, every node of the original tree is decoded as the reader would and
// checked against its interval (an always-on check).
#pragma once
#include <cstdint>

#include "tiles/encode/mh_quadtree_layout.hpp"

namespace st::mhq {

struct MergeOptions {
  uint32_t window = 1024;    // later candidates each candidate is tested against (demo: 1,024)
  uint32_t max_height = 12;  // candidates only in the bottom 12 levels (demo)
  uint32_t max_paths = 16;   // root paths reaching one shared block
};

struct MergeStats {
  uint64_t candidates = 0, tests = 0, quick_rejects = 0, full_rejects = 0;
  uint64_t merges = 0, cross_level_merges = 0, nodes_removed = 0, absolute_values = 0;
};

EmitPlan plan_mmh(const FlatTree& t, const MergeOptions& options, MergeStats* stats = nullptr);

}  // namespace st::mhq

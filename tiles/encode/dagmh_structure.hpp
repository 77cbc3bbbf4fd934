// DAG-MH structure (DAG-MH §3.1, §3.2): the sparse quadtree's *topology* stored as a
// DAG. Only which nodes hold a value matters to a lookup (empty nodes exist only to
// connect valued ones, MH §3.2), so a subtree is identified by the valued flags of its
// nodes, recursively; its values live apart, in depth-first order (dagmh_values.hpp),
// and each inner node records per child the offset of the child's first value
// ("attribute DAG", [DKB*16]), so a traversal knows the depth-first index it needs.
//
// Subtrees of height <= 3 become treelets: an 85-bit depth-first bitmap of a full
// 4-level quadtree (§3.2). Identical inner nodes and identical treelets are stored once:
// found through a hash, and merged only after comparing the whole key (flags + child
// ids for inner nodes, where equal child ids already mean equal subtrees by induction
// bottom-up; the whole bitmap for treelets). A hash collision therefore costs time,
// never correctness (tested with a constant hash).
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tiles/core/dagmh_format.hpp"
#include "tiles/encode/dagmh_values_encode.hpp"
#include "tiles/encode/hierarchy.hpp"

namespace st::dagmh {

using TreeletBits = std::array<uint32_t, kTreeletWords>;

struct InnerNode {
  uint32_t flags = 0;            // format word 0 (child mask, treelet bits, valued bit)
  uint32_t child[4] = {};        // per present child, in child order: its inner or treelet id
  uint32_t value_offset[4] = {}; // per present child: own value + earlier children's values
  uint32_t height = 0;           // levels below this node (>= 4 for inner nodes)
  uint32_t count = 0;            // values in the subtree
};

struct DagStructure {
  std::vector<InnerNode> inner;       // unique inner nodes, children before parents
  std::vector<TreeletBits> treelets;  // unique treelets
  uint32_t root = 0;                  // kRefInner | inner id, or kRefTreelet | treelet id
  std::vector<ValueSlot> values;      // the valued nodes' intervals, depth-first order
  uint64_t tree_inner = 0;            // inner nodes and treelets before sharing
  uint64_t tree_treelets = 0;
};

// Hash over a key of `count` words; replaceable so tests can force collisions.
using StructureHash = uint64_t (*)(const uint32_t* words, size_t count);
uint64_t default_structure_hash(const uint32_t* words, size_t count);

// Throws st::Error if the hierarchy is malformed (levels missing, children out of morton
// order, root without a value, a valued node with lo > hi or a NaN bound).
DagStructure build_structure(const Hierarchy& h, StructureHash hash = default_structure_hash);

// Depth-first position of the treelet node at treelet level n (0..3) on the path of
// child indices l[0..n-1] (DAG-MH §3.5): n + 21*l0 + 5*l1 + l2.
inline uint32_t treelet_position(uint32_t n, const uint32_t l[3]) {
  uint32_t p = n;
  for (uint32_t t = 0; t < n; ++t) p += kTreeletStride[t] * l[t];
  return p;
}

}  // namespace st::dagmh

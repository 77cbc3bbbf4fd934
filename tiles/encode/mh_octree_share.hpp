// How much identical-subtree sharing an octree of a shadow-map stack holds (the measure
// behind "bring DAG-style sharing to the octree if it pays", MH 2016 §4 with the DAG
// idea of Kämpe et al. 2013 / DAG-MH): subtrees are hash-consed bottom-up, exactly (two
// subtrees get one id iff their values, kinds and child slots are equal all the way
// down; ids are compared, never hashes alone).
//
// Word counts use the STOC encoding's sizes (MHOCT.md: leaf 1 word, empty 1, inner 2):
// - words:           the tree as encode_octree stores it (header not included);
// - dag_words:       every distinct subtree stored once, pointers free: the most any
//                    subtree sharing could save (an upper bound);
// - block_dag_words: every distinct children block stored once (a node's children are
//                    one contiguous block reached by one offset, so a format that let
//                    the offset point back at an earlier identical block would save
//                    exactly this, and pay nothing for the pointer).
#pragma once
#include <cstdint>

#include <utility>
#include <vector>

#include "tiles/encode/mh_octree_build.hpp"

namespace st {

struct OctreeSharing {
  uint64_t nodes = 0, unique_subtrees = 0;
  uint64_t blocks = 0, unique_blocks = 0;     // children blocks (nodes with children)
  uint64_t words = 0, dag_words = 0, block_dag_words = 0;
  uint64_t repeated_inner = 0;  // distinct subtrees with children that occur 2+ times
  uint64_t largest_repeated_words = 0;  // words of the largest subtree that occurs 2+ times
};

// `roundest`: every valued node's value replaced by the roundest float of its interval
// (the most trailing zero bits; any point of the interval is lossless, MH 2016 §3.1), the
// value choice that makes nearly equal subtrees equal.
OctreeSharing measure_octree_sharing(const OctHierarchy& h, bool roundest = false);

// Cost model of a per-region choice between the octree and separate quadtrees (what an
// octree with anisotropic splits could reach at best where the slices disagree): bottom-up
// over the octree's present nodes, best(node) = min(own words + sum of best(children),
// the words of the N quadtrees' subtrees over the node's (x, y) cell in its slices, plus
// W - 1 words of w splits). `quad_words[w]` maps (level, morton) of slice w's quadtree to
// its subtree's words (STOC sizes: leaf 1, empty 1, inner 2; an absent quadtree cell
// costs nothing, as if it inherited from the octree above: an optimistic model).
struct QuadSubtreeWords {
  std::vector<std::vector<std::pair<uint64_t, uint32_t>>> levels;  // per level: (morton, words), sorted
};
uint64_t hybrid_octree_quad_words(const OctHierarchy& h, const std::vector<QuadSubtreeWords>& quad_words);

}  // namespace st

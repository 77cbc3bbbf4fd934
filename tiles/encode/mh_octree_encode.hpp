// Encoder of the MH octree (tiles/core/mh_octree_format.hpp, MHOCT.md): an OctHierarchy
// laid out depth-first in one flat buffer with 16-bit child offsets scaled per level
// (MH §3.2 after Lefebvre & Hoppe 2007, carried to octrees by MH §4). A node whose
// children block equals one already laid out for another node of its level (the same
// children all the way down, compared exactly by hash-consed ids) points back at that
// block instead of storing it again (DAG-MH style): by its signed offset where it
// reaches, else through a far word (format version 3) when an earlier layout round
// found the block copied out of reach. Before that, compatible subtrees (same topology,
// values that can meet) are made equal by choosing their values (MMH style, absolute
// values; tiles/encode/mh_octree_merge.hpp).
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "tiles/encode/mh_octree_build.hpp"

namespace st {

struct OctEncodeStats {
  std::array<uint8_t, moct::kMaxLevels> shift{};  // chosen per-level log2 scales
  uint64_t words = 0, padding_words = 0;
  uint32_t nodes = 0;        // nodes stored
  uint64_t shared_blocks = 0;  // nodes whose block is shared
  uint64_t out_of_reach = 0;   // nodes with an equal block laid out earlier, beyond reach, copied
  uint64_t far_blocks = 0;     // nodes whose block is reached through a far word (shared or not)
  uint64_t far_words = 0;      // far words reserved (unused ones are zero padding)
  // The subtree merger (OctEncodeOptions::merge; MHOCT.md "Version 3, merged subtrees measured").
  uint64_t merge_candidates = 0, merge_tests = 0, merge_quick_rejects = 0, merge_full_rejects = 0;
  uint64_t merges = 0;         // candidate pairs whose blocks were made equal
  uint64_t merged_values = 0;  // nodes whose value the merger moved
};

struct OctEncodeOptions {
  // Merge compatible subtrees: nodes of one level whose children blocks have the same
  // topology and admit common values share one block, every value inside the central
  // window (mh_internal.hpp `central_window`) of every node it answers for. Off (the
  // default): only subtrees equal as built share. Measured to save under 0.1% of the
  // bytes on the bench's stacks (MHOCT.md "Version 3, merged subtrees measured"), so it
  // stays off: with it on, decoded values are no longer the hierarchy's bit for bit.
  bool merge = false;
  uint32_t merge_window = 64;      // later candidates of its group each candidate is tested against
  uint32_t merge_max_pairs = 4096; // node pairs one comparison may visit
};

// Checks the hierarchy's shape (level count, sorted codes, masks naming the next level's
// nodes in the slots the geometry splits, finite values) and encodes it. Throws st::Error
// naming the node at fault, or when the buffer would exceed the 32-bit byte_size.
//
// Values: with options.merge, a valued node whose value lies in the central window of
// its [lo, hi] (as build_octree makes them) may be stored with another value of that
// window where the merger shares its block; every other node, and every node without
// options.merge, keeps its value bit for bit.
// Every encoded buffer is walked once against the hierarchy before it is returned (an
// always-on check: each node found with its kind and mask, each value in its window;
// st::Error "internal error" otherwise). So decoding answers, on every texel of every
// slice and level, a value inside the interval of the node the hierarchy answers with
// (depth_at), and without merging exactly that node's value.
std::vector<uint8_t> encode_octree(const OctHierarchy& h, OctEncodeStats* stats = nullptr,
                                   const OctEncodeOptions& options = {});

}  // namespace st

// Encoder of the MH octree (tiles/core/mh_octree_format.hpp, MHOCT.md): an OctHierarchy
// laid out depth-first in one flat buffer with 16-bit child offsets scaled per level
// (MH §3.2 after Lefebvre & Hoppe 2007, carried to octrees by MH §4). A node whose
// children block equals one already laid out for another node of its level (the same
// children all the way down, compared exactly by hash-consed ids) points back at that
// block instead of storing it again (DAG-MH style): by its signed offset where it
// reaches, else through a far word (format version 3) when an earlier layout round
// found the block copied out of reach.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "tiles/build/mh_octree_build.hpp"

namespace st {

struct OctEncodeStats {
  std::array<uint8_t, moct::kMaxLevels> shift{};  // chosen per-level log2 scales
  uint64_t words = 0, padding_words = 0;
  uint32_t nodes = 0;        // nodes stored
  uint64_t shared_blocks = 0;  // nodes whose block is shared
  uint64_t out_of_reach = 0;   // nodes with an equal block laid out earlier, beyond reach, copied
  uint64_t far_blocks = 0;     // nodes whose block is reached through a far word (shared or not)
  uint64_t far_words = 0;      // far words reserved (unused ones are zero padding)
};

// Checks the hierarchy's shape (level count, sorted codes, masks naming the next level's
// nodes in the slots the geometry splits, finite values) and encodes it. Throws st::Error
// naming the node at fault, or when the buffer would exceed the 32-bit byte_size.
std::vector<uint8_t> encode_octree(const OctHierarchy& h, OctEncodeStats* stats = nullptr);

}  // namespace st

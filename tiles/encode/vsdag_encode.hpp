// The voxel shadow DAG encoder (voxelized shadows 2014 §3-§6.1; tiles/core/VSDAG.md).
//
// From a tile's hierarchy: every texel's admissible interval [lo, hi] (the interval of the
// valued node answering for it, hierarchy.hpp) gives its column of 2^z_bits depth slabs
// three states (§4, §6.1): lit above the slab of lo, shadowed below the slab of hi,
// undefined between (inside a closed object, or behind an open first hit under the
// static-geometry rule). Each column is resolved to one transition slab t in
// [floor(lo * 2^z), floor(hi * 2^z) + 1] (the one with the most trailing zero bits,
// so neighbouring columns agree and whole nodes become uniform), the volume is built
// top down against a min-max pyramid of t (§6.1), and identical subtrees are merged
// bottom up (§3, Kampe et al. 2013): a node whose mask and references equal an earlier
// node's reuses it, candidates found by hash always compared in full.
#pragma once
#include <cstdint>
#include <vector>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/vsdag_format.hpp"

namespace st {

struct VsdagOptions {
  uint32_t z_bits = vsdag::kDefaultZBits;  // depth resolution: 2^z_bits slabs over [0, 1]
};

// Throws st::Error for a broken hierarchy, z_bits outside 3..20 or a tile whose counts
// exceed the format (2^30 words). The buffer is opened and every column's transition
// checked against the intended one before it is returned.
std::vector<uint8_t> encode_vsdag(const Hierarchy& h, const VsdagOptions& options);

// The transition slab the encoder picks for an admissible interval (exposed for tests).
uint32_t vsdag_transition(float lo, float hi, uint32_t z_bits);

}  // namespace st

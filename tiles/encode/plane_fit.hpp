// Plane blocks of a tile (tiles/core/PLANES.md): find the aligned squares of a tile's
// finest texels that one plane answers exactly, take their subtrees out of the hierarchy,
// and wrap the rest's encoding behind the planes (plane_format.hpp).
//
// Why: on open geometry every texel's interval is one float wide (hi = lo), so a planar
// surface seen at a slant stores one value per texel in every tree encoding. Each of those
// values is the canonical depth of one triangle's plane (tiles/bake/canonical_depth.hpp),
// so a block on one triangle's plane is an affine function of the texel, rounded once.
// The encoder does not need to know the triangles: it finds, per block, integers (a, b, c)
// whose decoded depths (plane_format.hpp, integer arithmetic) lie in every texel's
// admissible interval, as a linear feasibility problem in three unknowns (Seidel's
// randomized LP), and verifies every texel with the decoder's own function. So a block is
// a plane only when it reproduces exactly what the intervals admit, for every receiver.
//
// A texel's admissible interval is taken from the hierarchy: its own leaf's [lo, hi], or
// the [lo, hi] of the deepest valued node that answers it (hierarchy.hpp: that interval is
// admissible for every texel the node answers for).
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/plane_format.hpp"

namespace st {

struct PlaneFitOptions {
  uint32_t min_shift = 3;          // smallest block: 2^min_shift a side
  uint32_t min_stored_nodes = 16;  // a block must take at least this many valued nodes out
  uint32_t max_tile_depth = 10;    // tiles deeper than this are not searched (memory, time)
};

struct PlaneSplit {
  std::vector<planes::Plane> planes;  // sorted by start, disjoint
  Hierarchy pruned;                   // the hierarchy without the nodes below each block
  uint64_t texels = 0;                // finest texels the planes answer
};

// Blocks are tried top-down (the largest first, down to min_shift); no plane: `planes` is
// empty and `pruned` a copy of h.
PlaneSplit fit_planes(const Hierarchy& h, const PlaneFitOptions& o = {});

// The plane tile: header, records, then `inner` (the encoding of PlaneSplit::pruned).
std::vector<uint8_t> wrap_planes(const std::vector<planes::Plane>& planes, uint32_t finest_level,
                                 std::span<const uint8_t> inner);

// One block: integers (a, b, c) whose depth lies in [lo[i], hi[i]] for texel i = y * side + x
// of the 2^shift square, verified with planes::Plane::depth; false when none was found.
bool fit_block(std::span<const float> lo, std::span<const float> hi, uint32_t shift, planes::Plane& out);

}  // namespace st

// Checks of a Hierarchy (tiles/encode/hierarchy.hpp) against its contract, shared by the
// construction tests and the encoders' tests. Each returns "" when the property holds,
// else a one-line description of the first failure.
#pragma once
#include <string>
#include <vector>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/interval.hpp"

namespace st::fields {

// Dense value maps of every level: out[l][morton] = depth(l, x, y) (hierarchy.hpp
// "Meaning"). 4/3 floats per finest texel; for tiles up to a few thousand a side.
std::vector<std::vector<float>> expand_levels(const Hierarchy& h);

// Structure: depth+1 levels, one valued root, strictly increasing in-range morton codes,
// child masks matching the next level exactly, empty nodes with children, no children
// at the finest level, valued nodes finite with lo <= value <= hi.
std::string check_well_formed(const Hierarchy& h);

// Lossless invariant on every texel of `tile` (depth(depth, x, y) in [lo, hi]).
std::string check_lossless(const Hierarchy& h, const IntervalTile& tile);

// Multiresolution: every level is a complete map whose value at (l, x, y) lies within
// [min lo, max hi] of the texels below it.
std::string check_levels_complete(const Hierarchy& h, const IntervalTile& tile);

// Every valued node's [lo, hi] is exactly (`exact`) or is inside (not `exact`) the
// intersection of the intervals of the texels it answers for (those whose deepest valued
// ancestor-or-self it is). With `exact`, every valued node answers for some texel; else
// a node answering for none (it serves coarser levels only) may hold any [lo, hi].
std::string check_admissible(const Hierarchy& h, const IntervalTile& tile, bool exact = true);

}  // namespace st::fields

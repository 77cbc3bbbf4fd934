// DAG-MH buffer validation: open_dagmh checks the whole buffer once, so that lookups
// need no bounds checks (the safety argument is in dagmh_traverse.hpp).
#pragma once
#include <cstdint>
#include <span>

#include "tiles/core/dagmh_traverse.hpp"

namespace st::dagmh {

// Checks every header field, section length and offset, every inner node (flags, child
// references in range and strictly forward, value offsets equal to the subtree value
// counts, reachable from the root), every treelet's padding bits, every chunk (factor
// bits, multipliers inside the section, mask bits past the last value clear) and the
// skip table (recomputed from the DAG), and rejects trailing bytes. Throws
// st::FormatError("dagmh: <field> at byte <offset>: <what>") on the first violation.
View validate(std::span<const uint8_t> bytes);

}  // namespace st::dagmh

// The encoders of a hierarchy, one per format tag of tiles/core/encoding.hpp: each turns
// a Hierarchy into one self-contained buffer that the matching opener of tiles/core reads
// in place. Encoders verify what they write (every decoded value lies in its node's
// interval) and throw st::Error when the hierarchy is broken.
#pragma once
#include <cstdint>
#include <vector>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/encoding.hpp"

namespace st {

std::vector<uint8_t> encode_mh(const Hierarchy& h);     // MH quadtree, MH §3.2
std::vector<uint8_t> encode_mmh(const Hierarchy& h);    // merged MH (mmh_merge.hpp)
std::vector<uint8_t> encode_dagmh(const Hierarchy& h);  // DAG-MH 2021 (dagmh_encode.hpp)
// Voxel shadow DAG (vsdag_encode.hpp) at the default depth resolution; encode_vsdag(h,
// VsdagOptions) takes another.

// Dispatch by tag (vsdag at its default depth resolution).
std::vector<uint8_t> encode(const Hierarchy& h, Encoding e);

}  // namespace st

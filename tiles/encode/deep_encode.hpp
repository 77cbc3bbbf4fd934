// Encoding one deep shadow tile (deep_format.hpp, DEEP.md) from the compressed visibility
// functions of its mip-0 texels, building the mip levels on the way (DSM 2000 §5.3): a
// texel of mip m + 1 is the exact average of its 2 x 2 children at mip m, recompressed
// with epsilon / 2^(m + 1) so the bounds sum to under 2 epsilon at every mip.
//
// Error contract: if every input function is within epsilon of the box-filtered truth,
// every stored texel of mip m is within epsilon (2 - 2^-m) + deep::kQuantisation of the
// box filter of its 2^m x 2^m block of that truth (averaging does not grow an error).
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "tiles/core/visibility_function.hpp"

namespace st {

struct DeepEncodeStats {
  uint64_t vertices[9] = {};  // per mip (deep::kMaxSideBits + 1)
  uint64_t bytes = 0;
};

// `finest`: 4^side_bits functions, row-major, each passing check(). Throws st::Error
// for a wrong count, side_bits above deep::kMaxSideBits, an invalid function, epsilon
// not finite or negative, a texel over deep::kMaxVertices vertices, or a tile over
// `max_bytes` (at most 2^32 - 1).
std::vector<uint8_t> encode_deep_tile(std::span<const VisibilityFunction> finest,
                                      uint32_t side_bits, double epsilon,
                                      DeepEncodeStats* stats = nullptr,
                                      uint64_t max_bytes = 0xFFFFFFFFull);

}  // namespace st

// DAG-MH value encoding (DAG-MH §3.3, §3.4, Alg. 2): chooses each chunk's base value and
// multipliers so that every decoded value, computed with the decoder's arithmetic
// (tiles/core/dagmh_values.hpp, affine_value), lies in its node's interval.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "tiles/core/dagmh_values.hpp"

namespace st::dagmh {

// One valued node: its admissible interval (any float in [lo, hi] is lossless) and the
// value the hierarchy chose (used for raw fallbacks).
struct ValueSlot {
  float lo = 0, hi = 0, value = 0;
};

struct ValueStats {
  uint64_t chunks = 0;
  uint64_t base_only_chunks = 0;  // every value equals the base
  uint64_t raw_chunks = 0;        // k = 32
  uint64_t multipliers = 0;       // values not equal to their chunk's base
  uint64_t multiplier_bits = 0;
};

struct EncodedValues {
  std::vector<ChunkInfo> chunks;
  std::vector<uint8_t> multipliers;  // multiple of 4 bytes, ends with kMultiplierPadBytes zeros
  ValueStats stats;
};

// Encodes the values; every decoded value is verified to lie in its slot's [lo, hi]
// (throws st::Error if a slot has lo > hi or a NaN bound: the hierarchy is broken).
EncodedValues encode_values(std::span<const ValueSlot> slots);

}  // namespace st::dagmh

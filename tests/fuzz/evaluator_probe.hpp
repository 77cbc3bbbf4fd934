// Lookups a harness runs on an evaluator that a decoder accepted from fuzzed bytes: a
// few texels at every level (corners, where offsets are largest, and texels picked by a
// hash of the input) and PCF kernels around them. Under ASan, any out-of-bounds read
// in a lookup is a finding; beyond that, PCF must equal the average of its single
// lookups (evaluator.hpp's contract, which the encodings' shared traversals must keep,
// MH §3.3) and a lookup must be deterministic.
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

#include "tests/fuzz/fuzz_harness.hpp"
#include "tiles/core/evaluator.hpp"

namespace st::fuzz {

// FNV-1a of the input: picks the probed texels, so each input probes its own.
inline uint64_t input_hash(const uint8_t* data, size_t size) {
  uint64_t h = 1469598103934665603ull;
  for (size_t i = 0; i < size; ++i) h = (h ^ data[i]) * 1099511628211ull;
  return h;
}

// The reference PCF: r*r single lookups (Evaluator::pcf's base implementation).
inline float reference_pcf(const Evaluator& ev, uint32_t level, uint64_t x, uint64_t y,
                           uint32_t r, float receiver) {
  const uint64_t side = uint64_t(1) << level;
  uint32_t lit = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i)
      lit += receiver <= ev.depth(level, pcf_tap(x, i, r, side), pcf_tap(y, j, r, side));
  return float(lit) / float(r * r);
}

// Probes levels 0..min(finest, max_level). Errors the evaluator documents (a
// PackEvaluator throws st::FormatError on a corrupt tile) propagate to the harness.
inline void probe_evaluator(const Evaluator& ev, uint64_t hash, uint32_t max_level = 24) {
  const uint32_t finest = std::min(ev.finest_level(), max_level);
  for (uint32_t l = 0; l <= finest; ++l) {
    const uint64_t side = uint64_t(1) << l, mask = side - 1;
    const uint64_t xs[5] = {0, mask, mask, hash & mask, (hash >> 20) & mask};
    const uint64_t ys[5] = {0, mask, 0, (hash >> 40) & mask, (hash >> 7) & mask};
    for (int k = 0; k < 5; ++k) {
      const float v = ev.depth(l, xs[k], ys[k]);
      FUZZ_CHECK(std::bit_cast<uint32_t>(v) == std::bit_cast<uint32_t>(ev.depth(l, xs[k], ys[k])));
      // PCF only at a few levels (the finest and one hashed): r*r lookups each.
      if (l != finest && l != hash % (finest + 1)) continue;
      const uint32_t r = 1 + uint32_t((hash >> (8 * k)) % Evaluator::kMaxPcf);
      for (float receiver : {v, std::nextafter(v, 2.0f), 0.5f}) {
        const float got = ev.pcf(l, xs[k], ys[k], r, receiver);
        FUZZ_CHECK(got >= 0.0f && got <= 1.0f);
        FUZZ_CHECK(got == reference_pcf(ev, l, xs[k], ys[k], r, receiver));
      }
    }
  }
}

}  // namespace st::fuzz

// One evaluator interface for every encoding (MH quadtree, MMH, DAG-MH, packs, the
// client's cache). Every level of the hierarchy is a complete shadow map of 2^level
// texels a side (ARCHITECTURE.md "Definitions").
//
// Thread safety: const methods may be called concurrently from many threads.
// Coordinates are integer texels of the given level; callers clamp (x, y < 2^level).
#pragma once
#include <cstdint>

namespace st {

class Evaluator {
 public:
  virtual ~Evaluator() = default;

  // Finest level stored (the map is 2^finest_level() texels a side).
  virtual uint32_t finest_level() const = 0;

  // The value answering for texel (x, y) of level `level` (level <= finest_level()).
  virtual float depth(uint32_t level, uint64_t x, uint64_t y) const = 0;

  // Fraction of the r x r kernel's taps that are lit (receiver <= depth), 1 <= r <= 9.
  // The kernel covers texels [x - (r-1)/2, x - (r-1)/2 + r) on each axis, each tap clamped to
  // the map's edges (pcf_tap). The result is exactly (lit taps) / (r * r) computed in float, so it
  // equals the average of the corresponding single lookups. The base implementation
  // does r*r independent lookups; encodings override it with traversal shared down to
  // the lowest common node (MH §3.3, Fig. 5).
  virtual float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const;

  // Lit test at full resolution: receiver_depth <= stored value.
  bool lit(uint64_t x, uint64_t y, float receiver_depth) const {
    return receiver_depth <= depth(finest_level(), x, y);
  }

  // Hierarchical PCF: picks the level at which one texel covers about `footprint`
  // finest-level texels (MH §3.3), then r x r PCF there. (u, v) in [0,1).
  float pcf_footprint(double u, double v, float receiver, double footprint, uint32_t r) const;

  static constexpr uint32_t kMaxPcf = 9;
};

// Coordinate of tap i (0 <= i < r) of an r-tap kernel around x, clamped to [0, side).
inline uint64_t pcf_tap(uint64_t x, uint32_t i, uint32_t r, uint64_t side) {
  int64_t t = int64_t(x) - int64_t((r - 1) / 2) + int64_t(i);
  return t < 0 ? 0 : uint64_t(t) >= side ? side - 1 : uint64_t(t);
}

}  // namespace st

// Depth intervals: the contract every module shares (ARCHITECTURE.md "Definitions").
//
// For each texel the ray from the light through its centre gives `lo` = first hit and
// `hi` = where it leaves all closed objects (MH §3, voxel paper §6.1); open geometry has
// hi = lo. Depth d in [0,1] is linear between the light's near and far planes.
//
// No-hit sentinel: a texel whose ray hits nothing has lo = hi = kLitDepth = 1.0f, which
// is >= every receiver depth, so it is lit for every receiver. Lit test everywhere:
//     lit  <=>  receiver_depth <= stored_value
// Lossless invariant: every stored/decoded full-resolution value v satisfies
// lo <= v <= hi bit-exactly (float comparisons, no epsilon).
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

namespace st {

inline constexpr float kLitDepth = 1.0f;
inline constexpr uint32_t kMaxLevel = 20;  // maps are at most 2^20 texels a side

struct Interval {
  float lo = kLitDepth;
  float hi = kLitDepth;
  bool contains(float v) const { return lo <= v && v <= hi; }
  bool operator==(const Interval&) const = default;
};

// A rectangular region of the depth-interval map of level `level` (2^level texels a
// side). Texel (x0 + i, y0 + j) is data[j * width + i]. Row-major, y down the rows.
struct IntervalTile {
  uint32_t level = 0;
  uint64_t x0 = 0, y0 = 0;
  uint32_t width = 0, height = 0;
  std::vector<Interval> data;

  Interval& at(uint32_t i, uint32_t j) { return data[size_t(j) * width + i]; }
  const Interval& at(uint32_t i, uint32_t j) const { return data[size_t(j) * width + i]; }
};

inline bool is_power_of_two(uint64_t v) { return v != 0 && (v & (v - 1)) == 0; }
inline uint32_t log2_exact(uint64_t v) { return uint32_t(63 - __builtin_clzll(v)); }

}  // namespace st

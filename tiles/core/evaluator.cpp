#include "tiles/core/evaluator.hpp"

#include <algorithm>
#include <cmath>

#include "tiles/core/filter_level.hpp"
#include "tiles/core/light.hpp"

namespace st {

float Evaluator::pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const {
  r = std::clamp<uint32_t>(r, 1, kMaxPcf);
  const uint64_t side = uint64_t(1) << level;
  uint32_t lit_taps = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i)
      lit_taps += receiver <= depth(level, pcf_tap(x, i, r, side), pcf_tap(y, j, r, side));
  return float(lit_taps) / float(r * r);
}

DepthRegion Evaluator::depth_region(uint32_t level, uint64_t x, uint64_t y) const { return {depth(level, x, y), 0}; }

void Evaluator::pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const {
  for (size_t i = 0; i < queries.size(); ++i) {
    const PcfQuery& q = queries[i];
    out[i] = pcf(q.level, q.x, q.y, q.r, q.receiver);
  }
}

float Evaluator::pcf_footprint(double u, double v, float receiver, float footprint, uint32_t r) const {
  const FilterLevels f = filter_levels(finest_level(), footprint);
  const auto tf = LightSpace::texel_of(f.fine, u, v);
  const float a = pcf(f.fine, tf[0], tf[1], r, receiver);
  if (f.t == 0.0f) return a;  // a + 0 * (c - a) == a: the coarse level is not needed
  const auto tc = LightSpace::texel_of(f.coarse, u, v);
  return filter_blend(a, pcf(f.coarse, tc[0], tc[1], r, receiver), f.t);
}

}  // namespace st

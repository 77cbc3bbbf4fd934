#include "tiles/core/evaluator.hpp"

#include <algorithm>
#include <cmath>

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

float Evaluator::pcf_footprint(double u, double v, float receiver, double footprint,
                               uint32_t r) const {
  const uint32_t finest = finest_level();
  uint32_t coarser = 0;
  if (footprint > 1) coarser = uint32_t(std::min<double>(finest, std::ceil(std::log2(footprint))));
  const uint32_t level = finest - coarser;
  auto t = LightSpace::texel_of(level, u, v);
  return pcf(level, t[0], t[1], r, receiver);
}

}  // namespace st

#include "tiles/core/receiver_plane.hpp"

#include <algorithm>

#include "tiles/core/filter_level.hpp"
#include "tiles/core/light.hpp"

namespace st {

void pcf_plane_bounds(const ReceiverPlane& p, uint32_t level, uint64_t x, uint64_t y, uint32_t r, float& least,
                      float& greatest) {
  const uint64_t side = uint64_t(1) << level;
  const uint64_t x0 = pcf_tap(x, 0, r, side), x1 = pcf_tap(x, r - 1, r, side);
  const uint64_t y0 = pcf_tap(y, 0, r, side), y1 = pcf_tap(y, r - 1, r, side);
  // Monotone in each axis (receiver_plane.hpp): the least where each slope is least.
  least = receiver_plane_depth(p, level, p.gx < 0 ? x1 : x0, p.gy < 0 ? y1 : y0);
  greatest = receiver_plane_depth(p, level, p.gx < 0 ? x0 : x1, p.gy < 0 ? y0 : y1);
}

float pcf_plane(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) {
  r = std::clamp<uint32_t>(r, 1, Evaluator::kMaxPcf);
  float least = 0, greatest = 0;
  pcf_plane_bounds(p, level, x, y, r, least, greatest);
  // Every tap lit at the greatest depth: each tap's own depth is at most that.
  if (eval.pcf(level, x, y, r, greatest) == 1.0f) return 1.0f;
  if (eval.pcf(level, x, y, r, least) == 0.0f) return 0.0f;
  return pcf_plane_taps(eval, level, x, y, r, p);
}

float pcf_plane_taps(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) {
  r = std::clamp<uint32_t>(r, 1, Evaluator::kMaxPcf);
  const uint64_t side = uint64_t(1) << level;
  uint32_t lit = 0;
  DepthRegion last{};
  uint64_t lx = 0, ly = 0;
  bool have = false;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i) {
      const uint64_t tx = pcf_tap(x, i, r, side), ty = pcf_tap(y, j, r, side);
      // A tap in the last walk's square shares its value (DepthRegion): no walk.
      if (!have || (tx >> last.shift) != lx || (ty >> last.shift) != ly) {
        last = eval.depth_region(level, tx, ty);
        lx = tx >> last.shift, ly = ty >> last.shift, have = true;
      }
      lit += receiver_plane_depth(p, level, tx, ty) <= last.value;
    }
  return float(lit) / float(r * r);
}

float pcf_footprint_plane(const Evaluator& eval, double u, double v, const ReceiverPlane& p, float footprint,
                          uint32_t r) {
  const FilterLevels f = filter_levels(eval.finest_level(), footprint);
  const auto tf = LightSpace::texel_of(f.fine, u, v);
  const float a = pcf_plane(eval, f.fine, tf[0], tf[1], r, p);
  if (f.t == 0.0f) return a;
  const auto tc = LightSpace::texel_of(f.coarse, u, v);
  return filter_blend(a, pcf_plane(eval, f.coarse, tc[0], tc[1], r, p), f.t);
}

}  // namespace st

// StackMap's filtered lookups with the receiver plane (stack_map.hpp *_on_plane): per slice
// the 2D rule of receiver_plane.hpp in that slice's light, taps counted one by one.
#include <algorithm>
#include <cmath>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/stack_map.hpp"

namespace st {

float StackMap::filtered_on_plane(const Vec3d& p, const Vec3d& normal, uint32_t w, uint32_t pcf_radius,
                                  float footprint, bool closed, bool* exact) const {
  if (w >= grid_.slices) return 1.0f;
  const uint32_t n = grid_.geo.n;
  const LightSpace& ls = lights_[w];
  LightPoint lp;
  ReceiverPlane plane;
  if (!receiver_plane_at(ls, n, p, normal, closed, lp, plane)) return 1.0f;  // outside the slice's map: lit
  const uint32_t r = 2 * std::min<uint32_t>(pcf_radius, (Evaluator::kMaxPcf - 1) / 2) + 1;
  FilterLevels f{n, n, 0.0f};
  if (footprint > 0) f = filter_levels(n, float(double(footprint) / ls.texel_size(p, n)));
  auto kernel = [&](uint32_t level) {
    const auto t = LightSpace::texel_of(level, lp.u, lp.v);
    const uint64_t side = uint64_t(1) << level;
    uint32_t lit_taps = 0;
    for (uint32_t j = 0; j < r; ++j)
      for (uint32_t i = 0; i < r; ++i) {
        const uint64_t tx = pcf_tap(t[0], i, r, side), ty = pcf_tap(t[1], j, r, side);
        lit_taps += receiver_plane_depth(plane, level, tx, ty) <= depth(tx, ty, w, level, exact);
      }
    return float(lit_taps) / float(r * r);
  };
  const float a = kernel(f.fine);
  if (f.t == 0.0f) return a;
  return filter_blend(a, kernel(f.coarse), f.t);
}

float StackMap::visibility_filtered_on_plane(const Vec3d& p, const Vec3d& normal, double time, uint32_t pcf_radius,
                                             float footprint, bool closed, bool* exact) const {
  const uint32_t n = grid_.slices;
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(n - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) return filtered_on_plane(p, normal, uint32_t(near), pcf_radius, footprint, closed, exact);
  const uint32_t a = uint32_t(std::floor(s));
  const float f = float(s - double(a));
  const float va = filtered_on_plane(p, normal, a, pcf_radius, footprint, closed, exact);
  const float vb = filtered_on_plane(p, normal, a + 1, pcf_radius, footprint, closed, exact);
  return va + f * (vb - va);
}

float StackMap::soft_visibility_filtered_on_plane(const Vec3d& p, const Vec3d& normal, uint32_t pcf_radius,
                                                  float footprint, bool closed, bool* exact) const {
  float sum = 0;
  for (uint32_t w = 0; w < grid_.slices; ++w) sum += filtered_on_plane(p, normal, w, pcf_radius, footprint, closed, exact);
  return sum / float(grid_.slices);
}

}  // namespace st

#include "tiles/core/receiver_plane.hpp"

#include <algorithm>
#include <cmath>

#include "tiles/core/filter_level.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st {

bool receiver_plane_at(const LightSpace& light, uint32_t map_level, const Vec3d& pos, const Vec3d& normal,
                       bool closed, LightPoint& lp, ReceiverPlane& plane) {
  const double texel = light.texel_size(pos, map_level);
  const Vec3d p = pos + normal * ((closed ? kClosedReceiverOffsetTexels : kOpenReceiverOffsetTexels) * texel);
  lp = light.to_light(p);
  if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) return false;
  const double side = std::ldexp(1.0, int(map_level));
  // Two directions along the surface, one texel long, through the light's transform: the
  // plane's depth change against its texel change, solved for d(depth)/dx and /dy.
  const Vec3d n = normal;
  const Vec3d t1 = normalize(cross(n, std::fabs(n.x) < 0.9 ? Vec3d{1, 0, 0} : Vec3d{0, 1, 0}));
  const Vec3d t2 = cross(n, t1);
  const LightPoint a = light.to_light(p + t1 * texel), b = light.to_light(p + t2 * texel);
  const double ax = (a.u - lp.u) * side, ay = (a.v - lp.v) * side, ad = a.d - lp.d;
  const double bx = (b.u - lp.u) * side, by = (b.v - lp.v) * side, bd = b.d - lp.d;
  const double det = ax * by - bx * ay;
  double gx = (ad * by - bd * ay) / det, gy = (ax * bd - bx * ad) / det;
  // The clamp: kMaxReceiverSlope texels of depth along the light ray per texel across.
  const Vec3d toward = light.parallel() ? -light.forward() : normalize(light.origin() - p);
  const double cap = kMaxReceiverSlope * std::fabs(light.to_light(p + toward * texel).d - lp.d);
  if (!std::isfinite(gx) || !std::isfinite(gy)) gx = gy = 0;
  gx = std::clamp(gx, -cap, cap), gy = std::clamp(gy, -cap, cap);
  plane.finest = map_level;
  plane.fx = std::min(uint64_t(lp.u * side), uint64_t(side) - 1);
  plane.fy = std::min(uint64_t(lp.v * side), uint64_t(side) - 1);
  plane.gx = float(gx), plane.gy = float(gy);
  const double fu = lp.u * side - double(plane.fx), fv = lp.v * side - double(plane.fy);
  plane.corner = float(lp.d - double(plane.gx) * fu - double(plane.gy) * fv);
  return true;
}


void pcf_plane_bounds(const ReceiverPlane& p, uint32_t level, uint64_t x, uint64_t y, uint32_t r, float& least,
                      float& greatest) {
  const uint64_t side = uint64_t(1) << level;
  const uint64_t x0 = pcf_tap(x, 0, r, side), x1 = pcf_tap(x, r - 1, r, side);
  const uint64_t y0 = pcf_tap(y, 0, r, side), y1 = pcf_tap(y, r - 1, r, side);
  // Monotone in each axis (receiver_plane.hpp): the least where each slope is least.
  least = receiver_plane_depth(p, level, p.gx < 0 ? x1 : x0, p.gy < 0 ? y1 : y0);
  greatest = receiver_plane_depth(p, level, p.gx < 0 ? x0 : x1, p.gy < 0 ? y0 : y1);
}

float Evaluator::pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const {
  return pcf_plane_extremes(*this, level, x, y, r, p);
}

float pcf_plane_by_taps(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                        const ReceiverPlane& p) {
  r = std::clamp<uint32_t>(r, 1, Evaluator::kMaxPcf);
  return pcf_plane_each_tap(level, x, y, r, p, [&](uint64_t tx, uint64_t ty) { return eval.depth(level, tx, ty); });
}

float window_pcf_plane(const WindowDepths& win, uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                       const ReceiverPlane& p) {
  r = std::clamp<uint32_t>(r, 1, Evaluator::kMaxPcf);
  const uint64_t side = uint64_t(1) << level;
  const uint64_t x0 = pcf_tap(x, 0, r, side), x1 = pcf_tap(x, r - 1, r, side);
  const uint64_t y0 = pcf_tap(y, 0, r, side), y1 = pcf_tap(y, r - 1, r, side);
  const uint32_t w = uint32_t(x1 - x0 + 1), h = uint32_t(y1 - y0 + 1);
  if (w == r && h == r) return pcf_fraction(win.count_window_plane(level, x0, y0, r, r, p), r);  // no tap clamped
  float depths[Evaluator::kMaxPcf * Evaluator::kMaxPcf];
  win.depth_window(level, x0, y0, w, h, depths);
  return pcf_plane_each_tap(level, x, y, r, p,
                            [&](uint64_t tx, uint64_t ty) { return depths[(tx - x0) * h + (ty - y0)]; });
}

float pcf_plane_extremes(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                         const ReceiverPlane& p) {
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

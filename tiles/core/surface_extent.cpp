#include "tiles/core/surface_extent.hpp"

#include <algorithm>
#include <vector>

#include "tiles/core/interval.hpp"

namespace st {
namespace {

double percentile(std::vector<double>& v, double p) {
  size_t i = std::min(v.size() - 1, size_t(p * double(v.size())));
  std::nth_element(v.begin(), v.begin() + long(i), v.end());
  return v[i];
}

}  // namespace

SurfaceExtent surface_extent(const LightSpace& light, const CutGrid& grid) {
  SurfaceExtent w;
  const uint32_t k = grid.levels;
  const uint64_t side = uint64_t(1) << k;
  std::vector<double> xs, ys, zs;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const float v = grid.entry(x, y).value;
      if (!(v < kLitDepth) || !(v >= 0)) continue;  // no hit: nothing there
      const LightRay r = light.texel_ray(k, x, y);
      // Inverse of LightSpace::depth_of_t (sun: d = t; spot: linear between near/far).
      const double t =
          light.parallel() ? double(v) : light.near_plane() + double(v) * (light.far_plane() - light.near_plane());
      const Vec3d p = r.origin + r.dir * t;
      xs.push_back(p.x);
      ys.push_back(p.y);
      zs.push_back(p.z);
      w.box.extend(p);
    }
  w.points = xs.size();
  if (xs.size() < 4) {
    // Nothing hit at level K: the light box itself (its lowest corner is the ground).
    const Vec3d o = light.origin(), a = light.axis_u() * light.extent_uv(), b = light.axis_v() * light.extent_uv();
    Aabb box;
    for (int i = 0; i < 4; ++i) box.extend(o + a * double(i & 1) + b * double(i >> 1));
    w.ground = box.lo.y;
    w.top = box.lo.y + 0.1 * std::max(box.extent().x, box.extent().z);
    w.x0 = box.lo.x, w.x1 = box.hi.x, w.z0 = box.lo.z, w.z1 = box.hi.z;
    return w;
  }
  w.x0 = percentile(xs, 0.01), w.x1 = percentile(xs, 0.99);
  w.z0 = percentile(zs, 0.01), w.z1 = percentile(zs, 0.99);
  w.ground = percentile(ys, 0.05);
  const double span = std::max(w.x1 - w.x0, w.z1 - w.z0);
  w.top = std::max(percentile(ys, 0.98), w.ground + 1e-3 * std::max(span, 1e-9));
  if (!(w.x1 > w.x0)) w.x1 = w.x0 + 1;
  if (!(w.z1 > w.z0)) w.z1 = w.z0 + 1;
  return w;
}

}  // namespace st

// The client's filtered lookups with the receiver plane (tiles/core/receiver_plane.hpp):
// every tap compares the plane's least depth over its own texel with the stored value,
// as render's filtered path does (receiver_plane_at: the same lookup point, slopes and
// clamp), counted through pcf_shared's cut of a kernel's window into resident tiles and
// kept regions (count_window_shared with PlaneTaps), each part at once where the plane lies
// on one side of its value and through the tile's own window walk
// (WindowDepths::count_window_plane) otherwise. Missing tiles answer coarsely, as
// depth_shared does, and queue their fetch.
#include <algorithm>
#include <cmath>
#include <shared_mutex>

#include "client/remote_map.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/receiver_plane.hpp"

namespace st::client {

float RemoteMap::pcf_plane_shared(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p,
                                  LookupScratch& sc) const noexcept {
  r = std::clamp<uint32_t>(r, 1, kMaxPcf);
  const uint64_t side = uint64_t(1) << level;
  const uint64_t x0 = pcf_tap(x, 0, r, side), x1 = pcf_tap(x, r - 1, r, side);
  const uint64_t y0 = pcf_tap(y, 0, r, side), y1 = pcf_tap(y, r - 1, r, side);
  if (level <= header_.map_level && x1 - x0 == r - 1 && y1 - y0 == r - 1)  // no tap clamped: each texel once
    return pcf_fraction(count_window_shared(level, x0, y0, x1, y1, PlaneTaps{p, level}, sc), r);
  // The map's edge: taps repeat, each against its own clamped texel.
  return pcf_plane_each_tap(level, x, y, r, p,
                            [&](uint64_t tx, uint64_t ty) { return depth_shared(level, tx, ty, sc); });
}

float RemoteMap::pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                              const ReceiverPlane& p) const noexcept {
  LookupScratch sc;
  float v;
  {
    std::shared_lock lock(mu_);
    v = pcf_plane_shared(level, x, y, r, p, sc);
  }
  finish_lookups(sc);
  return v;
}

void RemoteMap::visibility_plane_batch(std::span<const WorldPoint> points, std::span<const WorldPoint> normals,
                                       std::span<const float> footprints, std::span<float> out, uint32_t pcf_radius,
                                       bool closed) const noexcept {
  size_t n = std::min({points.size(), normals.size(), out.size()});
  if (!footprints.empty()) n = std::min(n, footprints.size());
  const uint32_t L = header_.map_level;
  const uint32_t r = 2 * std::min<uint32_t>(pcf_radius, (kMaxPcf - 1) / 2) + 1;
  LookupScratch sc;
  {
    std::shared_lock lock(mu_);
    for (size_t i = 0; i < n; ++i) {
      const Vec3d w{points[i].x, points[i].y, points[i].z};
      Vec3d nrm{normals[i].x, normals[i].y, normals[i].z};
      // A normal far from unit length is made unit (a unit one is taken as it is, so its
      // bits are render's).
      const double len2 = dot(nrm, nrm);
      if (len2 > 0 && std::fabs(len2 - 1.0) > 1e-3) nrm = nrm * (1.0 / std::sqrt(len2));
      LightPoint lp;
      ReceiverPlane pl;
      if (!receiver_plane_at(light_, L, w, nrm, closed, lp, pl)) {
        out[i] = 1.0f;  // outside the map: lit
        continue;
      }
      FilterLevels f{L, L, 0.0f};
      if (!footprints.empty() && footprints[i] > 0)
        f = filter_levels(L, float(double(footprints[i]) / light_.texel_size(w, L)));
      const auto tf = LightSpace::texel_of(f.fine, lp.u, lp.v);
      const float a = pcf_plane_shared(f.fine, tf[0], tf[1], r, pl, sc);
      if (f.t == 0.0f) {
        out[i] = a;
        continue;
      }
      const auto tc = LightSpace::texel_of(f.coarse, lp.u, lp.v);
      out[i] = filter_blend(a, pcf_plane_shared(f.coarse, tc[0], tc[1], r, pl, sc), f.t);
    }
  }
  finish_lookups(sc);
}

}  // namespace st::client

#include "gpu/shadow_reference.hpp"

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <limits>
#include <vector>

#include "shadowtile/cache_view.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/stack_grid.hpp"

static_assert(FLT_EVAL_METHOD == 0, "the shadow pass's twin must evaluate in float");
#if defined(__FAST_MATH__)
#error "gpu/ must not be built with -ffast-math: the CPU twin must round like the shader"
#endif

namespace st::gpu {

// The float32 rows of an affine world -> light map: u = (p - origin) . u_row / E, likewise
// v, d = (p - origin) . d_row / (far - near) - near / (far - near); each rounded once.
static ShadowLight light_rows(const LightSpace& ls, const Vec3d& u, const Vec3d& v, const Vec3d& f) {
  ShadowLight l;
  const Vec3d o = ls.origin();
  const double e = ls.extent_uv(), depth = ls.far_plane() - ls.near_plane();
  l.origin = {float(o.x), float(o.y), float(o.z)};
  l.axis_u = {float(u.x / e), float(u.y / e), float(u.z / e)};
  l.axis_v = {float(v.x / e), float(v.y / e), float(v.z / e)};
  l.forward = {float(f.x / depth), float(f.y / depth), float(f.z / depth)};
  l.near_scaled = float(ls.near_plane() / depth);
  return l;
}

ShadowLight shadow_light(const PackHeader& h) {
  if (h.light_kind != LightKind::sun && h.light_kind != LightKind::sun_ground)
    throw GpuError("GpuMap: the GPU shadow pass supports sun lights only");
  return shadow_light(LightSpace::from_array(h.light_kind, h.light));
}

// A perspective light (spot, spot_window): the rows scaled so that x / z needs no
// further scale (au = axis_u / (E (far - near)), fw = forward / (far - near)) and d = z -
// near', and the image centre as an offset (hpp).
static ShadowLight perspective_rows(const LightSpace& ls) {
  ShadowLight l = light_rows(ls, ls.forward(), ls.forward(), ls.forward());
  const double e = ls.extent_uv(), depth = ls.far_plane() - ls.near_plane();
  const Vec3d u = ls.axis_u(), v = ls.axis_v();
  l.axis_u = {float(u.x / (e * depth)), float(u.y / (e * depth)), float(u.z / (e * depth))};
  l.axis_v = {float(v.x / (e * depth)), float(v.y / (e * depth)), float(v.z / (e * depth))};
  const std::array<double, 2> c = ls.window_shift();
  l.centre_u = float(0.5 - c[0] / e);
  l.centre_v = float(0.5 - c[1] / e);
  l.perspective = true;
  return l;
}

ShadowLight shadow_light(const LightSpace& ls) {
  switch (ls.kind()) {
    case LightKind::sun_ground:
      return ground_shadow_light(ls);
    case LightKind::spot:
    case LightKind::spot_window:
      return perspective_rows(ls);
    case LightKind::sun:
      break;
  }
  return light_rows(ls, ls.axis_u(), ls.axis_v(), ls.forward());
}

// The ground frame (LightKind::sun_ground): the rows of its affine world -> light map
// (light.cpp), the dual basis of axis_u, axis_v and the ray axis g, each rounded once:
// au = (axis_u - (g . axis_u) n) / E, av likewise, fw = n / (far - near).
ShadowLight ground_shadow_light(const LightSpace& ls) {
  const Vec3d n = ls.depth_axis(), g = ls.ray_axis();
  return light_rows(ls, ls.axis_u() - n * dot(g, ls.axis_u()), ls.axis_v() - n * dot(g, ls.axis_v()), n);
}

LightUvd light_uvd(const ShadowLight& l, const float* receiver) {
  float r[3];
  for (int i = 0; i < 3; ++i) r[i] = receiver[i] - l.origin[i];
  auto dot = [&](const std::array<float, 3>& a) {
    const float x = r[0] * a[0], y = r[1] * a[1], z = r[2] * a[2];
    const float xy = x + y;
    return xy + z;
  };
  LightUvd out{dot(l.axis_u), dot(l.axis_v), 0};
  const float z = dot(l.forward);
  if (l.perspective) {
    const float qu = out.u / z, qv = out.v / z;
    out.u = qu + l.centre_u;
    out.v = qv + l.centre_v;
  }
  out.d = z - l.near_scaled;
  return out;
}

std::array<uint32_t, 2> finest_texel(const LightUvd& c, uint32_t finest) {
  const float side = std::ldexp(1.0f, int(finest));
  const uint32_t top = (1u << finest) - 1;
  return {std::min(uint32_t(std::floor(c.u * side)), top), std::min(uint32_t(std::floor(c.v * side)), top)};
}

ReceiverPlane plane_through(const LightUvd& c, uint32_t x, uint32_t y, uint32_t finest, float gx, float gy) {
  const float side = std::ldexp(1.0f, int(finest));
  const float su = c.u * side, sv = c.v * side;
  const float in_u = su - std::floor(su), in_v = sv - std::floor(sv);
  const float du = gx * in_u, dv = gy * in_v;
  const float corner_u = c.d - du;
  ReceiverPlane p;
  p.fx = x, p.fy = y, p.finest = finest, p.corner = corner_u - dv, p.gx = gx, p.gy = gy;
  return p;
}

float dot_reference(const std::array<float, 3>& p, const std::array<float, 3>& q) {
  const float x = p[0] * q[0], y = p[1] * q[1], z = p[2] * q[2];
  const float xy = x + y;
  return xy + z;
}

float receiver_slope_cap(const LightSpace& ls, const ShadowLight& l, uint32_t finest) {
  if (l.perspective) return 0.0f;
  const Vec3d t = ls.forward() * -1.0;  // toward the light (receiver_plane_at's for a parallel light)
  const float texel = float(ls.texel_size(ls.origin(), finest));
  const float cl = dot_reference(l.forward, {float(t.x), float(t.y), float(t.z)});
  const float reach = texel * std::fabs(cl);
  return kMaxReceiverSlope * reach;
}

StackTime stack_time(uint32_t slices, double time) {
  StackTime t;
  if (slices <= 1) return t;
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(slices - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) {
    t.a = t.b = uint32_t(near);
    return t;
  }
  t.a = uint32_t(std::floor(s));
  t.b = t.a + 1;
  t.f = float(s - double(t.a));
  return t;
}

float slice_pcf(const client::Map& map, uint32_t w, uint32_t level, uint32_t x, uint32_t y, uint32_t r, float d) {
  const uint64_t s = uint64_t(1) << level;
  uint32_t lit = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i) lit += d <= map.slice_depth(w, level, pcf_tap(x, i, r, s), pcf_tap(y, j, r, s));
  return float(lit) / float(r * r);
}

float slice_pcf_plane(const client::Map& map, uint32_t w, uint32_t level, uint32_t x, uint32_t y, uint32_t r,
                      const ReceiverPlane& p) {
  return pcf_plane_each_tap(level, x, y, r, p,
                            [&](uint64_t tx, uint64_t ty) { return map.slice_depth(w, level, tx, ty); });
}

std::vector<ShadowLight> slice_lights(const client::StackTables& g) {
  std::vector<ShadowLight> lights;
  for (const client::LightParams& l : g.lights)
    lights.push_back(shadow_light(LightSpace::from_array(LightKind(l.kind), l.params)));
  return lights;
}

namespace {

// r x r PCF of the receiver plane at `level` (st_pcf_plane): each tap's plane depth
// against Map::depth (pcf_plane_each_tap).
float plane_pcf(const client::Map& map, uint32_t level, uint32_t x, uint32_t y, uint32_t r, const ReceiverPlane& p) {
  return pcf_plane_each_tap(level, x, y, r, p, [&](uint64_t tx, uint64_t ty) { return map.depth(level, tx, ty); });
}

}  // namespace

void receiver_lookup_reference(const client::Map& map, std::span<const float> receivers, const ReceiverLookup& q,
                               std::span<float> out, std::span<const float> slopes) {
  const client::CacheView view(map);
  const client::StackTables* g = view.stack();
  const uint32_t finest = g ? g->xy_level : view.shape().finest_level;
  const bool kernel_ok = q.kernel >= 1 && q.kernel <= Evaluator::kMaxPcf && q.kernel % 2 == 1;
  std::vector<ShadowLight> lights;
  if (g) {
    lights = slice_lights(*g);
  } else {
    const client::LightParams lp = view.light();
    const auto kind = LightKind(lp.kind);
    if (kind == LightKind::sun || kind == LightKind::sun_ground)  // else GpuMap gives the shader none: lit
      lights.push_back(shadow_light(LightSpace::from_array(kind, lp.params)));
  }
  // Slice w's value (2D: w = 0) at one receiver, st_shadow_uvd's steps.
  auto slice = [&](const float* receiver, float footprint, uint32_t w, float gx, float gy) {
    if (!kernel_ok) return std::numeric_limits<float>::quiet_NaN();
    if (w >= lights.size()) return 1.0f;
    const LightUvd c = light_uvd(lights[w], receiver);
    if (!in_light_box(c)) return 1.0f;
    const std::array<uint32_t, 2> t = finest_texel(c, finest);
    if (gx == 0.0f && gy == 0.0f)
      return filtered(finest, t[0], t[1], footprint, [&](uint32_t level, uint32_t x, uint32_t y) {
        return g ? slice_pcf(map, w, level, x, y, q.kernel, c.d) : map.pcf(level, x, y, q.kernel, c.d);
      });
    // st_shadow_uvd_plane: the plane's depth at the texel's low corner, then its taps.
    const ReceiverPlane p = plane_through(c, t[0], t[1], finest, gx, gy);
    return filtered(finest, t[0], t[1], footprint, [&](uint32_t level, uint32_t x, uint32_t y) {
      return g ? slice_pcf_plane(map, w, level, x, y, q.kernel, p) : plane_pcf(map, level, x, y, q.kernel, p);
    });
  };
  const size_t n = std::min(receivers.size() / 4, out.size());
  for (size_t p = 0; p < n; ++p) {
    const float* r = receivers.data() + 4 * p;
    const bool sloped = slopes.size() >= 2 * (p + 1);
    const float gx = sloped ? slopes[2 * p] : 0.0f, gy = sloped ? slopes[2 * p + 1] : 0.0f;
    if (!(r[3] >= 0.0f)) {
      out[p] = std::numeric_limits<float>::quiet_NaN();
    } else if (g && q.soft) {
      float sum = 0;
      for (uint32_t w = 0; w < g->slices; ++w) sum = sum + slice(r, r[3], w, gx, gy);
      out[p] = sum / float(g->slices);
    } else {
      const float va = slice(r, r[3], g ? q.slice_a : 0, gx, gy);
      out[p] = !g || q.slice_a == q.slice_b ? va : va + q.blend * (slice(r, r[3], q.slice_b, gx, gy) - va);
    }
  }
}

}  // namespace st::gpu

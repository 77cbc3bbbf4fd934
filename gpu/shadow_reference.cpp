#include "gpu/shadow_reference.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cfloat>
#include <cmath>
#include <limits>
#include <vector>

#include "gpu/gpu_deep.hpp"
#include "shadowtile/cache_view.hpp"
#include "tiles/core/filter_level.hpp"
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

namespace {

struct Point {
  float u, v, d;
};

// A receiver's light-space point (st_light_uvd): r = receiver - origin per component, the
// rows' dot products (products, then sums left to right), a perspective divide, d from near.
Point receiver_point(const ShadowLight& l, const float* receiver) {
  float r[3];
  for (int i = 0; i < 3; ++i) r[i] = receiver[i] - l.origin[i];
  auto dot = [&](const std::array<float, 3>& a) {
    const float x = r[0] * a[0], y = r[1] * a[1], z = r[2] * a[2];
    const float xy = x + y;
    return xy + z;
  };
  Point out{dot(l.axis_u), dot(l.axis_v), 0};
  const float z = dot(l.forward);
  if (l.perspective) {
    const float qu = out.u / z, qv = out.v / z;
    out.u = qu + l.centre_u;
    out.v = qv + l.centre_v;
  }
  out.d = z - l.near_scaled;
  return out;
}

bool light_point_at(const ShadowLight& l, const ShadowPassInput& in, size_t p, float off, Point& out) {
  const float* q = in.positions.data() + 4 * p;
  const float* n = in.normals.data() + 4 * p;
  if (q[3] == 0.0f) return false;
  float r[3];
  for (int i = 0; i < 3; ++i) {
    const float moved = n[i] * off;
    r[i] = q[i] + moved;
  }
  out = receiver_point(l, r);
  return true;
}

bool in_light_box(const Point& c) { return c.u >= 0 && c.u < 1 && c.v >= 0 && c.v < 1 && c.d >= 0 && c.d <= 1; }

// The finest texel of an in-box point: floor(u * 2^finest), clamped to the map.
std::array<uint32_t, 2> finest_texel(const Point& c, uint32_t finest) {
  const float side = std::ldexp(1.0f, int(finest));
  const uint32_t top = (1u << finest) - 1;
  return {std::min(uint32_t(std::floor(c.u * side)), top), std::min(uint32_t(std::floor(c.v * side)), top)};
}

// The receiver plane through c with slopes (gx, gy) (st_plane_corner): its depth at the low
// corner of c's finest texel (x, y), (d - gx * in_u) - gy * in_v, (in_u, in_v) c's place in it.
ReceiverPlane plane_through(const Point& c, uint32_t x, uint32_t y, uint32_t finest, float gx, float gy) {
  const float side = std::ldexp(1.0f, int(finest));
  const float su = c.u * side, sv = c.v * side;
  const float in_u = su - std::floor(su), in_v = sv - std::floor(sv);
  const float du = gx * in_u, dv = gy * in_v;
  const float corner_u = c.d - du;
  ReceiverPlane p;
  p.fx = x, p.fy = y, p.finest = finest, p.corner = corner_u - dv, p.gx = gx, p.gy = gy;
  return p;
}

// Filtering at the finest texel (x, y) (filter_level.hpp, st_lookup): pcf(level, x, y) at the
// footprint's fine level, and where t > 0 blended with its coarse one.
template <class Pcf>
float filtered(uint32_t finest, uint32_t x, uint32_t y, float footprint, Pcf&& pcf) {
  const FilterLevels f = filter_levels(finest, footprint);
  const float a = pcf(f.fine, x >> (finest - f.fine), y >> (finest - f.fine));
  return f.t == 0.0f ? a : filter_blend(a, pcf(f.coarse, x >> (finest - f.coarse), y >> (finest - f.coarse)), f.t);
}

bool light_point(const ShadowLight& l, const ShadowPassInput& in, size_t p, Point& out) {
  return light_point_at(l, in, p, in.normal_offset, out);
}

// Pixel p's light-space point and its finest texel (x, y), and the footprint the pass
// filters with (the shader's st_footprint_of when asked); false where the pixel
// has no receiver or its point lies outside the map (the pass answers lit).
struct Texel {
  Point c;
  uint32_t x, y;
  float footprint;
};
bool pixel_texel(const ShadowLight& l, const ShadowPassInput& in, size_t p, uint32_t finest, Texel& t) {
  Point& c = t.c;
  if (!light_point(l, in, p, c) || !in_light_box(c)) return false;
  const float side = std::ldexp(1.0f, int(finest));
  const std::array<uint32_t, 2> xy = finest_texel(c, finest);
  t.x = xy[0], t.y = xy[1];
  t.footprint = in.footprint;
  if (in.neighbour_footprint) {
    float f = 0;
    Point nb;
    const size_t px = p % in.width, py = p / in.width;
    if (px + 1 < in.width && light_point(l, in, p + 1, nb))
      f = std::max(f, std::max(std::fabs(nb.u - c.u), std::fabs(nb.v - c.v)));
    if (py + 1 < in.height && light_point(l, in, p + in.width, nb))
      f = std::max(f, std::max(std::fabs(nb.u - c.u), std::fabs(nb.v - c.v)));
    t.footprint = f * side;
  }
  return true;
}

}  // namespace

bool shadow_pass_texel(const ShadowLight& light, const ShadowPassInput& in, size_t p, uint32_t finest, uint32_t& x,
                       uint32_t& y) {
  Texel t;
  if (!pixel_texel(light, in, p, finest, t)) return false;
  x = t.x, y = t.y;
  return true;
}

void shadow_pass_reference(const Evaluator& ev, const PackHeader& h, const ShadowPassInput& in, std::span<float> out) {
  const ShadowLight l = shadow_light(h);
  const uint32_t finest = h.map_level;
  const float cap = receiver_slope_cap(LightSpace::from_array(h.light_kind, h.light), l, finest);
  const size_t pixels = size_t(in.width) * in.height;
  for (size_t p = 0; p < pixels; ++p) {
    Texel t;
    if (!pixel_texel(l, in, p, finest, t)) {
      out[p] = 1.0f;
      continue;
    }
    if (in.receiver_plane) {  // shadow_pass.comp's st_plane_slope, st_plane_corner, st_lookup_plane
      const float* n = in.normals.data() + 4 * p;
      const std::array<float, 2> g = receiver_slope_reference(l, finest, {n[0], n[1], n[2]}, cap);
      const ReceiverPlane pl = plane_through(t.c, t.x, t.y, finest, g[0], g[1]);
      out[p] = filtered(finest, t.x, t.y, t.footprint, [&](uint32_t level, uint32_t x, uint32_t y) {
        return pcf_plane_by_taps(ev, level, x, y, in.kernel, pl);
      });
      continue;
    }
    // Evaluator::pcf_footprint's filtering on the finest texel (filter_level.hpp).
    out[p] = filtered(finest, t.x, t.y, t.footprint,
                      [&](uint32_t level, uint32_t x, uint32_t y) { return ev.pcf(level, x, y, in.kernel, t.c.d); });
  }
}

std::array<float, 3> deep_shadow_reference(const client::CacheView& view, float bias, uint32_t finest, float u, float v,
                                           float d, float footprint, uint32_t kernel) {
  const float moved = d - bias;
  const float texels = float(kernel) * (footprint > 1.0f ? footprint : 1.0f);
  const float width = texels * std::ldexp(1.0f, -int(finest));
  return view.deep_transmittance(double(u), double(v), moved, double(width));
}

void shadow_pass_light_reference(const client::Map& map, const ShadowPassInput& in, std::span<const float> vis,
                                 std::span<float> light_rgb) {
  const client::CacheView view(map);
  const size_t pixels = size_t(in.width) * in.height;
  const client::DeepShape shape = view.deep_tiles([](const client::DeepTile&) {});
  const bool deep = view.has_deep() && !view.stack();
  if (!deep) {
    for (size_t p = 0; p < pixels; ++p) light_rgb[3 * p] = light_rgb[3 * p + 1] = light_rgb[3 * p + 2] = vis[p];
    return;
  }
  const client::LightParams lp = view.light();
  const ShadowLight l = shadow_light(LightSpace::from_array(LightKind(lp.kind), lp.params));
  const uint32_t finest = view.shape().finest_level;
  const float bias = shape.level ? deep_depth_bias(lp, shape.level) : 0.0f;
  for (size_t p = 0; p < pixels; ++p) {
    std::array<float, 3> t{1, 1, 1};
    Point c, surface;
    if (light_point(l, in, p, c) && light_point_at(l, in, p, 0.0f, surface)) {
      Texel tx;
      const float footprint = pixel_texel(l, in, p, finest, tx) ? tx.footprint : in.footprint;
      t = deep_shadow_reference(view, bias, finest, surface.u, surface.v, surface.d, footprint, in.kernel);
    }
    for (int ch = 0; ch < 3; ++ch) light_rgb[3 * p + size_t(ch)] = vis[p] * t[size_t(ch)];
  }
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

namespace {

// r x r PCF in slice w at `level` (st_stack_pcf): lit taps / (r * r), taps clamped.
float slice_pcf(const client::Map& map, uint32_t w, uint32_t level, uint32_t x, uint32_t y, uint32_t r, float d) {
  const uint64_t s = uint64_t(1) << level;
  uint32_t lit = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i) lit += d <= map.slice_depth(w, level, pcf_tap(x, i, r, s), pcf_tap(y, j, r, s));
  return float(lit) / float(r * r);
}

std::vector<ShadowLight> slice_lights(const client::StackTables& g) {
  std::vector<ShadowLight> lights;
  for (const client::LightParams& l : g.lights)
    lights.push_back(shadow_light(LightSpace::from_array(LightKind(l.kind), l.params)));
  return lights;
}

// r x r PCF in slice w at `level` with each tap against the receiver plane (st_stack_pcf_plane).
float slice_pcf_plane(const client::Map& map, uint32_t w, uint32_t level, uint32_t x, uint32_t y, uint32_t r,
                      const ReceiverPlane& p) {
  const uint64_t s = uint64_t(1) << level;
  uint32_t lit = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i) {
      const uint64_t tx = pcf_tap(x, i, r, s), ty = pcf_tap(y, j, r, s);
      lit += receiver_plane_depth(p, level, tx, ty) <= map.slice_depth(w, level, tx, ty);
    }
  return float(lit) / float(r * r);
}

}  // namespace

void stack_shadow_pass_reference(const client::Map& map, const ShadowPassInput& in, std::span<float> out) {
  const client::CacheView view(map);
  const client::StackTables* g = view.stack();
  if (!g) throw GpuError("stack_shadow_pass_reference: not a stack map");
  const uint32_t finest = g->xy_level;
  const uint32_t r = std::clamp<uint32_t>(in.kernel, 1, Evaluator::kMaxPcf);
  const std::vector<ShadowLight> lights = slice_lights(*g);
  std::vector<float> caps;  // each slice's kStLightSlopeCap
  for (uint32_t w = 0; w < g->slices; ++w)
    caps.push_back(receiver_slope_cap(LightSpace::from_array(LightKind(g->lights[w].kind), g->lights[w].params),
                                      lights[w], finest));
  auto slice = [&](size_t p, uint32_t w) {
    Texel t;
    if (!pixel_texel(lights[w], in, p, finest, t)) return 1.0f;
    if (in.receiver_plane) {  // stack_shadow_pass.comp's st_plane_slope, st_plane_corner, st_stack_lookup_plane
      const float* n = in.normals.data() + 4 * p;
      const std::array<float, 2> sl = receiver_slope_reference(lights[w], finest, {n[0], n[1], n[2]}, caps[w]);
      const ReceiverPlane pl = plane_through(t.c, t.x, t.y, finest, sl[0], sl[1]);
      return filtered(finest, t.x, t.y, t.footprint, [&](uint32_t level, uint32_t x, uint32_t y) {
        return slice_pcf_plane(map, w, level, x, y, r, pl);
      });
    }
    return filtered(finest, t.x, t.y, t.footprint,
                    [&](uint32_t level, uint32_t x, uint32_t y) { return slice_pcf(map, w, level, x, y, r, t.c.d); });
  };
  const size_t pixels = size_t(in.width) * in.height;
  if (in.soft) {
    for (size_t p = 0; p < pixels; ++p) {
      float sum = 0;
      for (uint32_t w = 0; w < g->slices; ++w) sum = sum + slice(p, w);
      out[p] = sum / float(g->slices);
    }
    return;
  }
  const StackTime t = stack_time(g->slices, in.time);
  for (size_t p = 0; p < pixels; ++p) {
    const float va = slice(p, t.a);
    out[p] = t.a == t.b ? va : va + t.f * (slice(p, t.b) - va);
  }
}

namespace {

// st_slope_clamp: within +-cap (NaN: 0), and below 2^-60 in magnitude 0.
float slope_clamp(float g, float cap) {
  const float c = std::fabs(g) <= cap ? g : g > 0.0f ? cap : g < 0.0f ? -cap : 0.0f;
  return std::fabs(c) < 0x1p-60f ? 0.0f : c;
}

// r x r PCF of the receiver plane at `level` (st_pcf_plane): each tap's plane depth
// against Map::depth, lit taps / (r * r).
float plane_pcf(const client::Map& map, uint32_t level, uint32_t x, uint32_t y, uint32_t r, const ReceiverPlane& p) {
  const uint64_t s = uint64_t(1) << level;
  uint32_t lit = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i) {
      const uint64_t tx = pcf_tap(x, i, r, s), ty = pcf_tap(y, j, r, s);
      lit += receiver_plane_depth(p, level, tx, ty) <= map.depth(level, tx, ty);
    }
  return float(lit) / float(r * r);
}

}  // namespace

namespace {

// The float dot product of the shaders: the products, then (x + y) + z.
float dot_reference(const std::array<float, 3>& p, const std::array<float, 3>& q) {
  const float x = p[0] * q[0], y = p[1] * q[1], z = p[2] * q[2];
  const float xy = x + y;
  return xy + z;
}

}  // namespace

std::array<float, 2> receiver_slope_reference(const ShadowLight& l, uint32_t finest, const std::array<float, 3>& n,
                                              float cap) {
  if (l.perspective) return {0.0f, 0.0f};
  const std::array<float, 3>&a = l.axis_u, &b = l.axis_v, &c = l.forward;
  auto cross = [](const std::array<float, 3>& p, const std::array<float, 3>& q) {
    std::array<float, 3> o;
    for (int i = 0; i < 3; ++i) {
      const int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
      const float m1 = p[i1] * q[i2], m2 = p[i2] * q[i1];
      o[i] = m1 - m2;
    }
    return o;
  };
  const float pu = dot_reference(n, cross(b, c)), pv = dot_reference(n, cross(c, a)),
              pw = dot_reference(n, cross(a, b));
  const float den = pw * std::ldexp(1.0f, int(finest));
  return {slope_clamp(-pu / den, cap), slope_clamp(-pv / den, cap)};
}

std::array<float, 2> receiver_slope_reference(const ShadowLight& l, uint32_t finest, const std::array<float, 3>& n,
                                              const std::array<float, 3>& to_light, float texel) {
  const float cl = dot_reference(l.forward, to_light);
  const float reach = texel * std::fabs(cl);
  const float cap = kMaxReceiverSlope * reach;  // st_plane.glsl's kStMaxReceiverSlope
  return receiver_slope_reference(l, finest, n, cap);
}

float receiver_slope_cap(const LightSpace& ls, const ShadowLight& l, uint32_t finest) {
  if (l.perspective) return 0.0f;
  const Vec3d t = ls.forward() * -1.0;  // toward the light (receiver_plane_at's for a parallel light)
  const float texel = float(ls.texel_size(ls.origin(), finest));
  const float cl = dot_reference(l.forward, {float(t.x), float(t.y), float(t.z)});
  const float reach = texel * std::fabs(cl);
  return kMaxReceiverSlope * reach;
}

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
    const Point c = receiver_point(lights[w], receiver);
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

#include "tests/gpu/shadow_twins.hpp"

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <vector>

#include "gpu/gpu_deep.hpp"
#include "shadowtile/cache_view.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/receiver_plane.hpp"

static_assert(FLT_EVAL_METHOD == 0, "the shadow pass's twins must evaluate in float");
#if defined(__FAST_MATH__)
#error "the GPU twins must not be built with -ffast-math: they must round like the shaders"
#endif

namespace st::gpu {

namespace {

bool light_point_at(const ShadowLight& l, const ShadowPassInput& in, size_t p, float off, LightUvd& out) {
  const float* q = in.positions.data() + 4 * p;
  const float* n = in.normals.data() + 4 * p;
  if (q[3] == 0.0f) return false;
  float r[3];
  for (int i = 0; i < 3; ++i) {
    const float moved = n[i] * off;
    r[i] = q[i] + moved;
  }
  out = light_uvd(l, r);
  return true;
}

bool light_point(const ShadowLight& l, const ShadowPassInput& in, size_t p, LightUvd& out) {
  return light_point_at(l, in, p, in.normal_offset, out);
}

// Pixel p's light-space point and its finest texel (x, y), and the footprint the pass
// filters with (the shader's st_footprint_of when asked); false where the pixel
// has no receiver or its point lies outside the map (the pass answers lit).
struct Texel {
  LightUvd c;
  uint32_t x, y;
  float footprint;
};
bool pixel_texel(const ShadowLight& l, const ShadowPassInput& in, size_t p, uint32_t finest, Texel& t) {
  LightUvd& c = t.c;
  if (!light_point(l, in, p, c) || !in_light_box(c)) return false;
  const float side = std::ldexp(1.0f, int(finest));
  const std::array<uint32_t, 2> xy = finest_texel(c, finest);
  t.x = xy[0], t.y = xy[1];
  t.footprint = in.footprint;
  if (in.neighbour_footprint) {
    float f = 0;
    LightUvd nb;
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
    LightUvd c, surface;
    if (light_point(l, in, p, c) && light_point_at(l, in, p, 0.0f, surface)) {
      Texel tx;
      const float footprint = pixel_texel(l, in, p, finest, tx) ? tx.footprint : in.footprint;
      t = deep_shadow_reference(view, bias, finest, surface.u, surface.v, surface.d, footprint, in.kernel);
    }
    for (int ch = 0; ch < 3; ++ch) light_rgb[3 * p + size_t(ch)] = vis[p] * t[size_t(ch)];
  }
}

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

}  // namespace st::gpu

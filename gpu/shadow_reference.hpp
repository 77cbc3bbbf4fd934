// The shadow pass's light transform (a sun's light space in float32, as an engine's
// shader does it), and the float steps of the shaders' lookups that the CPU twins share:
// the same float operations in the same order as shaders/shadow_pass.comp and
// shadowtile.glsl, so a twin answers bit for bit as the GPU. The library's one twin is
// receiver_lookup_reference (shadowtile/gpu.hpp: `shadowtile view --twin`); the twins
// only the GPU tests call are in tests/gpu/shadow_twins.hpp, built on these steps.
//
//   r = (p + n * normal_offset) - origin           per component, product then sum
//   u = r.x * au.x + r.y * au.y + r.z * au.z        au = axis_u / extent (rounded once)
//   v = ... av,   d = (r . fw) - near_scaled        fw = forward / (far - near)
//   outside u, v in [0, 1), d in [0, 1]: lit (1); else texel floor(u * 2^L), and
//   footprint = max over the right and lower neighbours of max(|du|, |dv|) * 2^L.
// A sun path's ground frame (LightKind::sun_ground) fills the same words with the rows
// of its sheared (oblique) map: au, av and fw are then the dual basis of the ground axes
// and the sun's ray axis (shadow_light below), the same formulas in the shader.
// Float positions lose precision far from the light box's origin; engines that need
// more keep positions camera-relative (a documented limit, GPU_LAYOUT.md).
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "gpu/gpu_map.hpp"
#include "shadowtile/cache_view.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/receiver_plane.hpp"

namespace st::gpu {

// A perspective light (a spot, or an area light's sample: LightKind::spot, spot_window)
// in a stack pass, as an engine's shader projects (the stack block's light words,
// GPU_LAYOUT.md "The stack block"):
//   r as above; x = r . au, y = r . av, z = r . fw       au = axis_u / (E (far - near)),
//   u = x / z + cu,  v = y / z + cv,  d = z - near_scaled   av likewise, fw = forward / (far - near)
//   cu = 0.5 - c_u / E, cv = 0.5 - c_v / E (c: a spot_window's shift; 0 for a spot), each
//   rounded once from double; every product, sum and the quotient rounded once (the
//   shader's st_fdiv makes the device's division exact in integers, since Vulkan's may be
//   off by 2.5 ulp).
// The same box test, texel and neighbour footprint follow. z <= 0 (behind the light) gives
// d < 0 (near > 0) or a quotient that fails the box test: lit, on both sides.
struct ShadowLight {
  std::array<float, 3> origin{}, axis_u{}, axis_v{}, forward{};
  float near_scaled = 0;
  float centre_u = 0, centre_v = 0;  // perspective only
  bool perspective = false;
};

// The float light of a pack's header (suns only: the 2D pass refuses spots, GpuError), or
// of one light space (any kind; sun_ground: ground_shadow_light; spot, spot_window:
// perspective rows as drawn above).
ShadowLight shadow_light(const PackHeader& h);
ShadowLight shadow_light(const LightSpace& ls);
ShadowLight ground_shadow_light(const LightSpace& ls);

// A point in a float light's map space: (u, v) in [0, 1) on the map, d its depth.
struct LightUvd {
  float u, v, d;
};

// A receiver's light-space point (st_light_uvd): r = receiver - origin per component, the
// rows' dot products (products, then sums left to right), a perspective divide, d from near.
LightUvd light_uvd(const ShadowLight& l, const float* receiver);

// Inside the light's box: u, v in [0, 1), d in [0, 1] (else the shaders answer lit).
inline bool in_light_box(const LightUvd& c) {
  return c.u >= 0 && c.u < 1 && c.v >= 0 && c.v < 1 && c.d >= 0 && c.d <= 1;
}

// The finest texel of an in-box point: floor(u * 2^finest), clamped to the map.
std::array<uint32_t, 2> finest_texel(const LightUvd& c, uint32_t finest);

// The receiver plane through c with slopes (gx, gy) (st_plane_corner): its depth at the low
// corner of c's finest texel (x, y), (d - gx * in_u) - gy * in_v, (in_u, in_v) c's place in it.
ReceiverPlane plane_through(const LightUvd& c, uint32_t x, uint32_t y, uint32_t finest, float gx, float gy);

// The float dot product of the shaders: the products, then (x + y) + z.
float dot_reference(const std::array<float, 3>& p, const std::array<float, 3>& q);

// A light's receiver-slope cap (the light block's kStLightSlopeCap word, GpuMap writes it;
// st_plane.glsl): kMaxReceiverSlope * (texel * |c . to_light|) in float, as st_receiver_slope
// computes it, with texel = float(ls.texel_size(origin, finest)), to_light = float(-ls.forward())
// (the CPU's receiver_plane_at's) and c = l.forward; 0 for a perspective light.
float receiver_slope_cap(const LightSpace& ls, const ShadowLight& l, uint32_t finest);

// Filtering at the finest texel (x, y) (filter_level.hpp, st_lookup): pcf(level, x, y) at the
// footprint's fine level, and where t > 0 blended with its coarse one.
template <class Pcf>
float filtered(uint32_t finest, uint32_t x, uint32_t y, float footprint, Pcf&& pcf) {
  const FilterLevels f = filter_levels(finest, footprint);
  const float a = pcf(f.fine, x >> (finest - f.fine), y >> (finest - f.fine));
  return f.t == 0.0f ? a : filter_blend(a, pcf(f.coarse, x >> (finest - f.coarse), y >> (finest - f.coarse)), f.t);
}

// r x r PCF in slice w of a stack map at `level` (st_stack_pcf): lit taps / (r * r), taps
// clamped, depths from Map::slice_depth.
float slice_pcf(const client::Map& map, uint32_t w, uint32_t level, uint32_t x, uint32_t y, uint32_t r, float d);

// r x r PCF in slice w at `level` with each tap against the receiver plane (st_stack_pcf_plane).
float slice_pcf_plane(const client::Map& map, uint32_t w, uint32_t level, uint32_t x, uint32_t y, uint32_t r,
                      const ReceiverPlane& p);

// Each slice's float light (shadow_light of its light space).
std::vector<ShadowLight> slice_lights(const client::StackTables& g);

}  // namespace st::gpu

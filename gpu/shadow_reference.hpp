// The shadow pass's light transform (a sun's light space in float32, as an engine's
// shader does it) and its CPU twin: the same float operations in the same order as
// shaders/shadow_pass.comp, so tests compare the GPU image with it bit for bit.
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
#include <span>

#include "gpu/gpu_map.hpp"
#include "shadowtile/cache_view.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/pack_format.hpp"

namespace st::gpu {

// A perspective light (a spot, or an area light's sample: LightKind::spot, spot_window)
// in a stack pass, as an engine's shader projects (the stack block's light words,
// GPU_LAYOUT.md "The stack block"):
//   r as above; x = r . au, y = r . av, z = r . fw       au = axis_u / (E (far - near)),
//   u = x / z + cu,  v = y / z + cv,  d = z - near_scaled   av likewise, fw = forward / (far - near)
//   cu = 0.5 - c_u / E, cv = 0.5 - c_v / E (c: a spot_window's shift; 0 for a spot), each
//   rounded once from double; every product, sum and the quotient rounded once (the
//   shader divides in integers, st_fdiv, since Vulkan's division may be off by 2.5 ulp).
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

// The CPU twin of shadowtile.glsl's st_receiver_slope: a 2D map's receiver-plane slopes
// (gx, gy) per finest texel from a surface normal through the float light `l`
// (shadow_light), the unit direction toward the light and one finest texel in world
// units, with the shader's float operations in its order (st_fdiv's quotients are IEEE
// division's). (0, 0) for a perspective light.
std::array<float, 2> receiver_slope_reference(const ShadowLight& l, uint32_t finest, const std::array<float, 3>& normal,
                                              const std::array<float, 3>& to_light, float texel);
// The same with the slopes clamped to +-cap (st_plane_slope).
std::array<float, 2> receiver_slope_reference(const ShadowLight& l, uint32_t finest, const std::array<float, 3>& normal,
                                              float cap);
// A light's cap (the light block's kStLightSlopeCap word, GpuMap writes it; st_plane.glsl):
// kMaxReceiverSlope * (texel * |c . to_light|) in float, as st_receiver_slope computes it,
// with texel = float(ls.texel_size(origin, finest)), to_light = float(-ls.forward()) (the
// CPU's receiver_plane_at's) and c = l.forward; 0 for a perspective light.
float receiver_slope_cap(const LightSpace& ls, const ShadowLight& l, uint32_t finest);

// The CPU twin of a stack map's shadow pass: the same float operations per slice as
// shaders/stack_shadow_pass.comp, depths from Map::slice_depth (the Map's cache, the same
// state the GpuMap mirrors). Any light kind of a stack (suns, ground-frame suns, spots and
// an area light's windowed spots). At in.time, or with in.soft the average over the N
// slices: sum = 0; for w = 0..N-1: sum = sum + v_w (float, one rounding per add); then
// sum / float(N), one rounding: StackMap::soft_visibility_filtered's order, with v_w each
// slice's filtered value in the pass's float light and footprint. Throws GpuError for a
// map that is not a stack.
void stack_shadow_pass_reference(const client::Map& map, const ShadowPassInput& in, std::span<float> out);

// The finest-level texel (x, y) the shadow pass reads for pixel p of `in` in `light` (the
// twin's float operations); false where the pass answers lit without a lookup (no
// surface, or outside the light's box). Tests use it to name the tiles a pass needs.
bool shadow_pass_texel(const ShadowLight& light, const ShadowPassInput& in, size_t p, uint32_t finest, uint32_t& x,
                       uint32_t& y);

// The CPU twin of the shadow pass over `ev` (the Map's evaluator, the same cache state).
void shadow_pass_reference(const Evaluator& ev, const PackHeader& h, const ShadowPassInput& in, std::span<float> out);

// The CPU twin of the deep part's factor of a 2D shadow lookup (st_deep_shadow,
// shaders/st_deep.glsl): at the surface point's float light-space (u, v, d) (no normal
// offset), d - bias (bias: the deep block's kDpDepthBias, deep_depth_bias), over a
// footprint of kernel x max(1, footprint) finest texels times 2^-finest map units (one
// texel: bilinear at the deep map's mip 0, never a point lookup), the CPU's own lookup
// (CacheView::deep_transmittance). Each float operation rounded once.
std::array<float, 3> deep_shadow_reference(const client::CacheView& view, float bias, uint32_t finest, float u, float v,
                                           float d, float footprint, uint32_t kernel);

// The CPU twin of a 2D pass's light per channel (GpuMap::wait's light_rgb, the engine
// pass's light image rgb) for the visibility `vis` it gave: per pixel with a surface,
// vis * deep_shadow_reference at the pixel's surface point with the footprint the pass
// filtered with (in.footprint outside the light's box), one rounding per channel; vis
// where it has none, or for a map without a deep part (or a stack map).
void shadow_pass_light_reference(const client::Map& map, const ShadowPassInput& in, std::span<const float> vis,
                                 std::span<float> light_rgb);

}  // namespace st::gpu

// The CPU twins of the GPU passes that only the GPU tests compare with (bit for bit):
// the same float operations in the same order as the shaders, over the same cache state
// as the GpuMap mirrors, on gpu/shadow_reference.hpp's shared steps (the light transform,
// light_uvd, filtered, slice_pcf). Compiled with -ffp-contract=off, as gpu/ is.
#pragma once
#include <array>
#include <span>

#include "gpu/gpu_map.hpp"
#include "gpu/shadow_reference.hpp"
#include "shadowtile/cache_view.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/pack_format.hpp"

namespace st::gpu {

// The CPU twin of shadowtile.glsl's st_receiver_slope: a 2D map's receiver-plane slopes
// (gx, gy) per finest texel from a surface normal through the float light `l`
// (shadow_light), the unit direction toward the light and one finest texel in world
// units, with the shader's float operations in its order (st_fdiv's quotients are IEEE
// division's). (0, 0) for a perspective light.
std::array<float, 2> receiver_slope_reference(const ShadowLight& l, uint32_t finest, const std::array<float, 3>& normal,
                                              const std::array<float, 3>& to_light, float texel);
// The same with the slopes clamped to +-cap (st_plane_slope; receiver_slope_cap gives a
// light's cap).
std::array<float, 2> receiver_slope_reference(const ShadowLight& l, uint32_t finest, const std::array<float, 3>& normal,
                                              float cap);

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

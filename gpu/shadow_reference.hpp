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
#include "tiles/core/evaluator.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/pack_format.hpp"

namespace st::gpu {

struct ShadowLight {
  std::array<float, 3> origin{}, axis_u{}, axis_v{}, forward{};
  float near_scaled = 0;
};

// The float light of a pack's header, or of one light space. Throws GpuError for a spot
// light (the GPU shadow pass supports suns only).
ShadowLight shadow_light(const PackHeader& h);
ShadowLight shadow_light(const LightSpace& ls);
ShadowLight ground_shadow_light(const LightSpace& ls);

// The CPU twin of a stack map's shadow pass: the same float operations per slice as
// shaders/stack_shadow_pass.comp, depths from Map::slice_depth (the Map's cache, the same
// state the GpuMap mirrors). Throws GpuError for a map that is not a stack of suns.
void stack_shadow_pass_reference(const client::Map& map, const ShadowPassInput& in, std::span<float> out);

// The CPU twin of the shadow pass over `ev` (the Map's evaluator, the same cache state).
void shadow_pass_reference(const Evaluator& ev, const PackHeader& h, const ShadowPassInput& in, std::span<float> out);

}  // namespace st::gpu

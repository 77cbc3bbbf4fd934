#version 450
// The engine-mode shadow pass (GpuMap::record_shadow_pass): the engine's G-buffer images
// (world positions, normals) -> its R32F visibility image, through shadowtile.glsl (the
// include an engine's own shaders use). Per pixel the same operations as shadow_pass.comp
// (2D maps) and stack_shadow_pass.comp (stack maps, at a time or soft): the neighbour
// footprint per slice in that slice's light, the receiver plane from the pixel's normal
// (kFlagReceiverPlane), the blend or the soft average; so the answers
// equal theirs and their CPU twins (tests/gpu/shadow_twins.hpp) bit for bit. Compiled a
// second time with ST_PASS_LIGHT (ShadowPassImages::light): it also writes the light per
// channel, visibility x the deep part's transmittance (st_deep_shadow at the pixel's
// surface point, the pixel's footprint), as rgb, and the visibility as a. One call site of
// the lookup (slices in a loop), and specialization constant 0 (GpuMap::is_stack: 1 a 2D
// map, 2 a stack map) leaves the other kind's walk out: a pipeline compile from a cold
// shader cache inlines the tile walk once.
#extension GL_GOOGLE_include_directive : require
#define ST_MAP_KIND_ID 0
#define ST_SET 0
#define ST_BINDING_POOL 0
#define ST_BINDING_PAGE 1
#define ST_BINDING_FEEDBACK 2
#include "shadowtile.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(set = 0, binding = 3) uniform sampler2D st_positions;
layout(set = 0, binding = 4) uniform sampler2D st_normals;
layout(set = 0, binding = 5, r32f) uniform writeonly image2D st_visibility_image;
#ifdef ST_PASS_LIGHT
layout(set = 0, binding = 6, rgba32f) uniform writeonly image2D st_light_image;
#endif
layout(push_constant) uniform StEnginePush { uint w[kPcWords]; } pc;

float pc_float(uint i) { return uintBitsToFloat(pc.w[i]); }

// The receiver of pixel q; false where it holds no surface (w == 0).
bool gbuffer_receiver(ivec2 q, out vec3 r) {
  const vec4 p = texelFetch(st_positions, q, 0);
  r = vec3(0.0);
  if (p.w == 0.0) return false;
  r = st_receiver(p.xyz, texelFetch(st_normals, q, 0).xyz, pc_float(kPcNormalOffset));
  return true;
}

// Visibility of the pixel (receiver r) in slice w, the footprint from its right and lower
// neighbours in that slice's light (or the push constant's).
// `footprint`: the one it filtered with (the push constant's outside the light's box).
float slice_visibility(uint w, ivec2 q, vec3 r, inout StProbe probe, out float footprint) {
  const uint lb = st_light_block(w);
  const vec3 uvd = st_light_uvd(lb, r);
  footprint = pc_float(kPcFootprint);
  if (!st_in_light_box(uvd)) return 1.0;
  if ((pc.w[kPcFlags] & kFlagNeighbourFootprint) != 0u) {
    vec3 rr, rd;
    const bool has_right = uint(q.x) + 1u < pc.w[kPcCount] && gbuffer_receiver(q + ivec2(1, 0), rr);
    const bool has_down = uint(q.y) + 1u < pc.w[kPcHeight] && gbuffer_receiver(q + ivec2(0, 1), rd);
    footprint = st_footprint_of(uvd, has_right ? st_light_uvd(lb, rr) : uvd, has_right,
                                has_down ? st_light_uvd(lb, rd) : uvd, has_down);
  }
  // Each tap against the receiver's plane through uvd with the pixel's normal (st_plane.glsl);
  // without kFlagReceiverPlane zero slopes: one receiver depth, st_shadow_uvd's answer.
  const vec2 slope = (pc.w[kPcFlags] & kFlagReceiverPlane) == 0u ? vec2(0.0)
                                                                 : st_receiver_slope(lb, texelFetch(st_normals, q, 0).xyz);
  return st_shadow_uvd_plane(w, uvd, slope, footprint, pc.w[kPcKernel], probe);
}

void main() {
  const ivec2 q = ivec2(gl_GlobalInvocationID.xy);
  if (uint(q.x) >= pc.w[kPcCount] || uint(q.y) >= pc.w[kPcHeight]) return;
  vec3 r;
  if (!gbuffer_receiver(q, r) || st_light_block(0u) == 0u) {
    imageStore(st_visibility_image, q, vec4(1.0));
#ifdef ST_PASS_LIGHT
    imageStore(st_light_image, q, vec4(1.0));
#endif
    return;
  }
  StProbe probe = st_probe();
  // One call site of slice_visibility: a 2D map's light, a stack's slices a and b at a time
  // (blended va + f * (vb - va)), or every slice (soft: summed in slice order, then divided).
  const uint slices = st_slices();
  const bool soft = slices != 0u && (pc.w[kPcFlags] & kFlagSoft) != 0u;
  const uint wa = pc.w[kPcSliceA], wb = pc.w[kPcSliceB];
  const uint count = slices == 0u ? 1u : soft ? slices : (wa == wb ? 1u : 2u);
  if (slices != 0u) st_oct_path_reset((pc.w[kPcFlags] & kFlagResumeWalks) != 0u);
  precise float sum = 0.0;
  float va = 1.0, vb = 1.0, footprint = 0.0;
  for (uint i = 0u; i < count; ++i) {
    const uint w = slices == 0u ? 0u : soft ? i : (i == 0u ? wa : wb);
    const float v = slice_visibility(w, q, r, probe, footprint);
    sum = sum + v;
    if (i == 0u) va = v;
    else vb = v;
  }
  float answer = va;
  if (soft) {
    answer = st_fdiv(sum, float(slices));
  } else if (count == 2u) {
    precise float step = vb - va;
    precise float scaled = pc_float(kPcTimeWeight) * step;
    precise float blended = va + scaled;
    answer = blended;
  }
  vec3 t = vec3(1.0);
#ifdef ST_PASS_LIGHT
  if (slices == 0u) t = st_transmittance(texelFetch(st_positions, q, 0).xyz, footprint, pc.w[kPcKernel], probe);
#endif
  imageStore(st_visibility_image, q, vec4(answer));
#ifdef ST_PASS_LIGHT
  precise vec3 light = answer * t;
  imageStore(st_light_image, q, vec4(light, answer));
#endif
  st_finish(probe);
}

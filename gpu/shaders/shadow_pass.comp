#version 450
// The shadow pass (GpuMap::shadow_pass): world positions (and normals) of a G-buffer ->
// visibility. A sun's light space in float32, the same operations as the CPU twin
// gpu::shadow_pass_reference (gpu/shadow_reference.cpp); see GPU_LAYOUT.md. With
// kFlagReceiverPlane each PCF tap compares the receiver's plane (st_plane.glsl).
#include "st_buffers.glsl"

#include "st_light.glsl"
#include "st_deep.glsl"
#include "st_plane.glsl"

// The transmittance at pixel p's surface point itself (no normal offset).
vec3 st_deep_surface(uint p, float footprint) {
  if (ST_PAGE(kPtDeep) == 0u) return vec3(1.0);
  float su, sv, sd;
  st_light_point_at(p, 0.0, su, sv, sd);
  return st_deep_shadow(vec3(su, sv, sd), footprint, st_pc.w[kPcKernel]);
}

// A map with a deep part (page word kPtDeep != 0): the light per channel, visibility x
// transmittance (st_deep_shadow at the pixel's surface point, the pass's footprint and
// kernel), follows the visibility image at st_output[count + 3 p + c] (GPU_LAYOUT.md "The
// deep block").
void st_write_light(uint p, uint count, float vis, vec3 t) {
  if (ST_PAGE(kPtDeep) == 0u) return;
  precise vec3 light = vis * t;
  st_output[count + 3u * p] = light.x;
  st_output[count + 3u * p + 1u] = light.y;
  st_output[count + 3u * p + 2u] = light.z;
}

void main() {
  const uint width = st_pc.w[kPcCount], height = st_pc.w[kPcHeight];
  const uint p = gl_GlobalInvocationID.x;
  if (p >= width * height) return;
  float u, v, d;
  if (!st_light_point(p, u, v, d)) {
    st_output[p] = 1.0;
    st_write_light(p, width * height, 1.0, vec3(1.0));
    return;
  }
  if (!(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0 && d >= 0.0 && d <= 1.0)) {
    st_output[p] = 1.0;
    st_write_light(p, width * height, 1.0, st_deep_surface(p, st_pcf_word(kPcFootprint)));
    return;
  }
  const uint finest = st_page_words[kPtMapLevel];
  const float side = uintBitsToFloat((127u + finest) << 23u);  // 2^finest, exact
  precise float fu = floor(u * side), fv = floor(v * side);
  const uint x = min(uint(fu), (1u << finest) - 1u), y = min(uint(fv), (1u << finest) - 1u);
  float footprint = st_pcf_word(kPcFootprint);
  if ((st_pc.w[kPcFlags] & kFlagNeighbourFootprint) != 0u) {
    // the footprint: how far the next pixel right and down moves in finest texels
    precise float f = 0.0;
    float nu, nv, nd;
    const uint px = p % width, py = p / width;
    if (px + 1u < width && st_light_point(p + 1u, nu, nv, nd)) f = max(f, max(abs(nu - u), abs(nv - v)));
    if (py + 1u < height && st_light_point(p + width, nu, nv, nd)) f = max(f, max(abs(nu - u), abs(nv - v)));
    footprint = f * side;
  }
  StProbe probe = st_probe();
  // With kFlagReceiverPlane each tap against the receiver's plane through (u, v, d) with the
  // pixel's normal, the slopes in the map's light (kPtLight: the rows of the push constants)
  // and its cap; without, zero slopes: one receiver depth (the plane's corner is then d, bit
  // for bit). One call site of the walk: a compiler inlines it once.
  vec2 slope = vec2(0.0);
  if ((st_pc.w[kPcFlags] & kFlagReceiverPlane) != 0u) {
    const uint b = 4u * p;
    const vec3 n = vec3(uintBitsToFloat(st_normal_words[b]), uintBitsToFloat(st_normal_words[b + 1u]),
                        uintBitsToFloat(st_normal_words[b + 2u]));
    slope = st_plane_slope(st_page_words[kPtLight], finest, n);
  }
  const vec3 plane = vec3(st_plane_corner(vec3(u, v, d), slope, side), slope.x, slope.y);
  const float vis = st_lookup_plane(x, y, plane, footprint, st_pc.w[kPcKernel], probe);
  st_output[p] = vis;
  if (probe.hole) atomicAdd(st_fb_words[kFbHoles], 1u);
  st_write_light(p, width * height, vis, st_deep_surface(p, footprint));
}

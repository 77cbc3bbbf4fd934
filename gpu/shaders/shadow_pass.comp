#version 450
// The shadow pass (GpuMap::shadow_pass): world positions (and normals) of a G-buffer ->
// visibility. A sun's light space in float32, the same operations as the CPU twin
// gpu::shadow_pass_reference (gpu/shadow_reference.cpp); see GPU_LAYOUT.md.
#include "st_buffers.glsl"

#include "st_light.glsl"

void main() {
  const uint width = st_pc.w[kPcCount], height = st_pc.w[kPcHeight];
  const uint p = gl_GlobalInvocationID.x;
  if (p >= width * height) return;
  float u, v, d;
  if (!st_light_point(p, u, v, d) || !(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0 && d >= 0.0 && d <= 1.0)) {
    st_output[p] = 1.0;
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
  st_output[p] = st_lookup(x, y, d, footprint, st_pc.w[kPcKernel], probe);
  if (probe.hole) atomicAdd(st_fb_words[kFbHoles], 1u);
}

#version 450
// The baseline of bench_gpu: the same lookups on the map's finest level as an
// uncompressed R32F image (binding 0 holds side * side floats, row-major), so the
// compressed evaluators are timed next to a plain shadow map on the same device.
// Flags bit 1 clear: queries (single tap or r x r PCF at the finest level); set: the
// shadow pass over positions and normals, as shadow_pass.comp at the finest level.
#include "st_buffers.glsl"
#include "st_light.glsl"

float st_r32f_pcf(uint x, uint y, uint r, float receiver) {
  const uint finest = st_page_words[kPtMapLevel];
  const uint side = 1u << finest;
  uint lit = 0u;
  for (uint j = 0u; j < r; ++j) {
    const uint row = st_pcf_tap(y, j, r, side) << finest;
    for (uint i = 0u; i < r; ++i) lit += st_lit(receiver, uintBitsToFloat(st_pool_words[row + st_pcf_tap(x, i, r, side)])) ? 1u : 0u;
  }
  return uintBitsToFloat(st_page_words[st_page_words[kPtPcfTable] + (r - 1u) * kPcfTableStride + lit]);
}

void main() {
  const uint i = gl_GlobalInvocationID.x;
  if ((st_pc.w[kPcFlags] & 2u) == 0u) {
    if (i >= st_pc.w[kPcCount]) return;
    const uint b = i * kQueryWords;
    st_output[i] = st_r32f_pcf(st_input_words[b + kQueryX], st_input_words[b + kQueryY], clamp(st_input_words[b + kQueryR], 1u, kMaxPcf),
                               uintBitsToFloat(st_input_words[b + kQueryReceiver]));
    return;
  }
  const uint width = st_pc.w[kPcCount], height = st_pc.w[kPcHeight];
  if (i >= width * height) return;
  float u, v, d;
  if (!st_light_point(i, u, v, d) || !(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0 && d >= 0.0 && d <= 1.0)) {
    st_output[i] = 1.0;
    return;
  }
  const uint finest = st_page_words[kPtMapLevel];
  const float side = uintBitsToFloat((127u + finest) << 23u);
  precise float fu = floor(u * side), fv = floor(v * side);
  const uint x = min(uint(fu), (1u << finest) - 1u), y = min(uint(fv), (1u << finest) - 1u);
  st_output[i] = st_r32f_pcf(x, y, st_pc.w[kPcKernel], d);
}

#version 450
// The shadow pass of a stack map (GpuMap::submit_shadow_pass with ShadowPassInput::time):
// world positions (and normals) of a G-buffer -> visibility at a time of the light set,
// the two nearest slices blended (StackLookup::visibility's contract: exact at the
// samples, va + f * (vb - va) between), or with kFlagSoft the soft shadow: the average
// over all N slices (sum in slice order, then / N). Each slice's light space in float32
// comes from the stack block (a sun's affine rows, or a spot's rows and the perspective
// divide); per slice the same operations as the 2D pass (shadow_pass.comp) and as the CPU
// twin gpu::stack_shadow_pass_reference (tests/gpu/shadow_twins.cpp). With kFlagResumeWalks
// every tile walk resumes from the pixel's previous walk in that tile (st_oct_depth_resumed:
// consecutive PCF taps, levels and slices share the top of their paths); same answers.
// With kFlagReceiverPlane each tap compares the receiver's plane in the slice's light
// (st_plane.glsl, st_stack_lookup_plane).
#include "st_buffers.glsl"

#include "st_stack.glsl"
#include "st_plane.glsl"

float st_light_word(uint base, uint i) { return uintBitsToFloat(st_page_words[base + i]); }

// Light-space (u, v, d) of pixel p in the light whose kStLightWords words start at `lb`.
bool st_stack_light_point(uint p, uint lb, out float u, out float v, out float d) {
  const uint b = 4u * p;
  u = 0.0;
  v = 0.0;
  d = 0.0;
  if (uintBitsToFloat(st_input_words[b + 3u]) == 0.0) return false;
  const float off = uintBitsToFloat(st_pc.w[kPcNormalOffset]);
  precise float rx = uintBitsToFloat(st_input_words[b]) + uintBitsToFloat(st_normal_words[b]) * off;
  precise float ry = uintBitsToFloat(st_input_words[b + 1u]) + uintBitsToFloat(st_normal_words[b + 1u]) * off;
  precise float rz = uintBitsToFloat(st_input_words[b + 2u]) + uintBitsToFloat(st_normal_words[b + 2u]) * off;
  rx = rx - st_light_word(lb, 0u);
  ry = ry - st_light_word(lb, 1u);
  rz = rz - st_light_word(lb, 2u);
  precise float pu = rx * st_light_word(lb, 3u) + ry * st_light_word(lb, 4u) + rz * st_light_word(lb, 5u);
  precise float pv = rx * st_light_word(lb, 6u) + ry * st_light_word(lb, 7u) + rz * st_light_word(lb, 8u);
  precise float pz = rx * st_light_word(lb, 9u) + ry * st_light_word(lb, 10u) + rz * st_light_word(lb, 11u);
  if (st_page_words[lb + kStLightProjection] != 0u) {  // perspective: the divide, rounded as the CPU's
    pu = st_fdiv(pu, pz) + st_light_word(lb, kStLightCentreU);
    pv = st_fdiv(pv, pz) + st_light_word(lb, kStLightCentreV);
  }
  precise float pd = pz - st_light_word(lb, 12u);
  u = pu;
  v = pv;
  d = pd;
  return true;
}

// Visibility of pixel p in slice w: outside the slice's light box lit, else the footprint
// (from the neighbours, in the slice's finest texels) and st_stack_lookup.
float st_slice_visibility(uint p, uint w, inout StProbe probe) {
  const uint width = st_pc.w[kPcCount], height = st_pc.w[kPcHeight];
  const uint blk = st_page_words[kPtStack];
  const uint lb = st_page_words[blk + kStLights] + w * kStLightWords;
  float u, v, d;
  if (!st_stack_light_point(p, lb, u, v, d) || !(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0 && d >= 0.0 && d <= 1.0))
    return 1.0;
  const uint finest = st_page_words[blk + kStXyLevel];
  const float side = uintBitsToFloat((127u + finest) << 23u);  // 2^finest, exact
  precise float fu = floor(u * side), fv = floor(v * side);
  const uint x = min(uint(fu), (1u << finest) - 1u), y = min(uint(fv), (1u << finest) - 1u);
  float footprint = uintBitsToFloat(st_pc.w[kPcFootprint]);
  if ((st_pc.w[kPcFlags] & kFlagNeighbourFootprint) != 0u) {
    precise float f = 0.0;
    float nu, nv, nd;
    const uint px = p % width, py = p / width;
    if (px + 1u < width && st_stack_light_point(p + 1u, lb, nu, nv, nd)) f = max(f, max(abs(nu - u), abs(nv - v)));
    if (py + 1u < height && st_stack_light_point(p + width, lb, nu, nv, nd)) f = max(f, max(abs(nu - u), abs(nv - v)));
    footprint = f * side;
  }
  // Each tap against the receiver's plane in the slice's light (a spot's slopes: 0); without
  // kFlagReceiverPlane zero slopes: one receiver depth (st_stack_lookup's answer).
  vec2 slope = vec2(0.0);
  if ((st_pc.w[kPcFlags] & kFlagReceiverPlane) != 0u) {
    const uint b = 4u * p;
    const vec3 n = vec3(uintBitsToFloat(st_normal_words[b]), uintBitsToFloat(st_normal_words[b + 1u]),
                        uintBitsToFloat(st_normal_words[b + 2u]));
    slope = st_plane_slope(lb, finest, n);
  }
  const vec3 plane = vec3(st_plane_corner(vec3(u, v, d), slope, side), slope.x, slope.y);
  return st_stack_lookup_plane(x, y, w, plane, footprint, st_pc.w[kPcKernel], probe);
}

void main() {
  const uint p = gl_GlobalInvocationID.x;
  if (p >= st_pc.w[kPcCount] * st_pc.w[kPcHeight]) return;
  StProbe probe = st_probe();
  st_oct_path_reset((st_pc.w[kPcFlags] & kFlagResumeWalks) != 0u);  // tile walks resume from the last one's path
  // One call site of st_slice_visibility (a compiler inlines the walk once): slices a and b
  // at a time (a == b at a sample's time; else va + f * (vb - va), each step rounded once),
  // or with kFlagSoft every slice in order, summed in float (one rounding per add), then
  // divided by N (rounded once): StackMap::soft_visibility_filtered's average.
  const bool soft = (st_pc.w[kPcFlags] & kFlagSoft) != 0u;
  const uint slices = st_page_words[st_page_words[kPtStack] + kStSlices];
  const uint wa = st_pc.w[kPcSliceA], wb = st_pc.w[kPcSliceB];
  const uint count = soft ? slices : (wa == wb ? 1u : 2u);
  precise float sum = 0.0;
  float va = 1.0, vb = 1.0;
  for (uint i = 0u; i < count; ++i) {
    const float v = st_slice_visibility(p, soft ? i : (i == 0u ? wa : wb), probe);
    sum = sum + v;
    if (i == 0u) va = v;
    else vb = v;
  }
  float answer = va;
  if (soft) {
    answer = st_fdiv(sum, float(slices));
  } else if (count == 2u) {
    const float f = uintBitsToFloat(st_pc.w[kPcTimeWeight]);
    precise float step = vb - va;
    precise float scaled = f * step;
    precise float blended = va + scaled;
    answer = blended;
  }
  st_output[p] = answer;
  if (probe.hole) atomicAdd(st_fb_words[kFbHoles], 1u);
}

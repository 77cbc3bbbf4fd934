#version 450
// A batch of stack queries (GpuMap::evaluate with GpuStackQuery): one invocation per query,
// kSqWords words each.
#include "st_buffers.glsl"

#include "st_stack.glsl"

void main() {
  const uint q = gl_GlobalInvocationID.x;
  if (q >= st_pc.w[kPcCount]) return;
  const uint b = q * kSqWords;
  const uint x = st_input_words[b + kSqX], y = st_input_words[b + kSqY], w = st_input_words[b + kSqSlice];
  const uint level = st_input_words[b + kSqLevel], r = st_input_words[b + kSqR];
  const float receiver = uintBitsToFloat(st_input_words[b + kSqReceiver]);
  const float footprint = uintBitsToFloat(st_input_words[b + kSqFootprint]);
  StProbe probe = st_probe();
  float answer;
  if (r == 0u) answer = st_stack_depth(x, y, w, level, probe);
  else if (level == kLevelFromFootprint) answer = st_stack_lookup(x, y, w, receiver, footprint, r, probe);
  else answer = st_stack_pcf(level, x, y, w, r, receiver, probe);
  st_output[q] = answer;
  if (probe.hole) atomicAdd(st_fb_words[kFbHoles], 1u);
}

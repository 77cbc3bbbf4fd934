#version 450
// A batch of queries (GpuMap::evaluate): one invocation per query, kQueryWords words each.
#include "st_buffers.glsl"

void main() {
  const uint q = gl_GlobalInvocationID.x;
  if (q >= st_pc.w[kPcCount]) return;
  const uint b = q * kQueryWords;
  const uint x = st_input_words[b + kQueryX], y = st_input_words[b + kQueryY];
  const float receiver = uintBitsToFloat(st_input_words[b + kQueryReceiver]);
  const float footprint = uintBitsToFloat(st_input_words[b + kQueryFootprint]);
  const uint r = st_input_words[b + kQueryR], level = st_input_words[b + kQueryLevel];
  StProbe probe = st_probe();
  float answer;
  if (r == 0u) answer = st_depth(level, x, y, probe);
  else if (level == kLevelFromFootprint) answer = st_lookup(x, y, receiver, footprint, r, probe);
  else answer = st_pcf(level, x, y, r, receiver, probe);
  st_output[q] = answer;
  if (probe.hole) atomicAdd(st_fb_words[kFbHoles], 1u);
}

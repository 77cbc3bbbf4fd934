#version 450
// A batch of queries (GpuMap::evaluate): one invocation per query, kQueryWords words each.
#include "st_buffers.glsl"

#include "st_deep.glsl"

void main() {
  const uint q = gl_GlobalInvocationID.x;
  if (q >= st_pc.w[kPcCount]) return;
  const uint b = q * kQueryWords;
  const uint x = st_input_words[b + kQueryX], y = st_input_words[b + kQueryY];
  const float receiver = uintBitsToFloat(st_input_words[b + kQueryReceiver]);
  const float footprint = uintBitsToFloat(st_input_words[b + kQueryFootprint]);
  const uint r = st_input_words[b + kQueryR], level = st_input_words[b + kQueryLevel];
  if (r == kDeepQuery) {  // GpuDeepQuery: (u, v) in x, y, depth, width in footprint; RGB after the answers
    const vec3 t = st_deep_transmittance(uintBitsToFloat(x), uintBitsToFloat(y), receiver, footprint);
    const uint n = st_pc.w[kPcCount];
    st_output[q] = 0.0;
    st_output[n + 3u * q] = t.x;
    st_output[n + 3u * q + 1u] = t.y;
    st_output[n + 3u * q + 2u] = t.z;
    return;
  }
  StProbe probe = st_probe();
  float answer;
  if (r == 0u) answer = st_depth(level, x, y, probe);
  else if (level == kLevelFromFootprint) answer = st_lookup(x, y, receiver, footprint, r, probe);
  else answer = st_pcf(level, x, y, r, receiver, probe);
  st_output[q] = answer;
  if (probe.hole) atomicAdd(st_fb_words[kFbHoles], 1u);
}

// A sun's light space in float32 for the shadow passes (shadow_pass.comp, r32f.comp): the
// operations gpu/shadow_reference.cpp repeats on the CPU. Needs st_buffers.glsl first.
#ifndef SHADOWTILE_GPU_ST_LIGHT_GLSL
#define SHADOWTILE_GPU_ST_LIGHT_GLSL
float st_pcf_word(uint i) { return uintBitsToFloat(st_pc.w[i]); }

// Light-space (u, v, d) of pixel p's surface point moved `off` along its normal; false
// when it holds no surface.
bool st_light_point_at(uint p, float off, out float u, out float v, out float d) {
  const uint b = 4u * p;
  u = 0.0;
  v = 0.0;
  d = 0.0;
  if (uintBitsToFloat(st_input_words[b + 3u]) == 0.0) return false;
  precise float rx = uintBitsToFloat(st_input_words[b]) + uintBitsToFloat(st_normal_words[b]) * off;
  precise float ry = uintBitsToFloat(st_input_words[b + 1u]) + uintBitsToFloat(st_normal_words[b + 1u]) * off;
  precise float rz = uintBitsToFloat(st_input_words[b + 2u]) + uintBitsToFloat(st_normal_words[b + 2u]) * off;
  rx = rx - st_pcf_word(kPcOrigin);
  ry = ry - st_pcf_word(kPcOrigin + 1u);
  rz = rz - st_pcf_word(kPcOrigin + 2u);
  precise float pu = rx * st_pcf_word(kPcAxisU) + ry * st_pcf_word(kPcAxisU + 1u) + rz * st_pcf_word(kPcAxisU + 2u);
  precise float pv = rx * st_pcf_word(kPcAxisV) + ry * st_pcf_word(kPcAxisV + 1u) + rz * st_pcf_word(kPcAxisV + 2u);
  precise float pd = rx * st_pcf_word(kPcForward) + ry * st_pcf_word(kPcForward + 1u) + rz * st_pcf_word(kPcForward + 2u);
  pd = pd - st_pcf_word(kPcNear);
  u = pu;
  v = pv;
  d = pd;
  return true;
}

// The receiver's: moved by the pass's normal offset.
bool st_light_point(uint p, out float u, out float v, out float d) {
  return st_light_point_at(p, st_pcf_word(kPcNormalOffset), u, v, d);
}

#endif

// st_fdiv(a, b): a / b rounded as the CPU's IEEE 754 binary32 division, for the shaders
// that divide (the stack passes, the deep lookups of st_deep.glsl). Needs nothing else.
#ifndef SHADOWTILE_GPU_ST_FDIV_GLSL
#define SHADOWTILE_GPU_ST_FDIV_GLSL

// ---- division rounded as IEEE 754 binary32 (the CPU's a / b) ----
// Vulkan lets OpFDiv be off by 2.5 ulp, so the passes that divide (a perspective light's
// x / z, the soft pass's sum / N) divide in integers: the 24-bit significands' quotient by
// long division (25 bits and the remainder), rounded to nearest even, subnormal operands
// read and subnormal quotients formed exactly; NaN, infinities and zeros as IEEE gives them
// (a NaN quotient is the default NaN 0x7FC00000; nothing compares or stores its payload).
uint st_fdiv_norm(uint bits, out int e) {  // significand in [2^23, 2^24), exponent unbiased
  uint m = bits & 0x7FFFFFu;
  e = int((bits >> 23u) & 0xFFu);
  if (e != 0) return m | 0x800000u;
  e = 1;
  while (m < 0x800000u) m <<= 1u, --e;  // subnormal (m != 0: zeros are handled before)
  return m;
}

float st_fdiv(float a, float b) {
  const uint ab = floatBitsToUint(a), bb = floatBitsToUint(b);
  const uint sign = (ab ^ bb) & 0x80000000u;
  const uint aa = ab & 0x7FFFFFFFu, ba = bb & 0x7FFFFFFFu;
  if (aa > 0x7F800000u || ba > 0x7F800000u) return uintBitsToFloat(0x7FC00000u);  // NaN operand
  if (aa == 0x7F800000u) return uintBitsToFloat(ba == 0x7F800000u ? 0x7FC00000u : sign | 0x7F800000u);
  if (ba == 0x7F800000u) return uintBitsToFloat(sign);                              // x / inf
  if (ba == 0u) return uintBitsToFloat(aa == 0u ? 0x7FC00000u : sign | 0x7F800000u);  // x / 0
  if (aa == 0u) return uintBitsToFloat(sign);
  int ea, eb;
  uint ma = st_fdiv_norm(aa, ea);
  const uint mb = st_fdiv_norm(ba, eb);
  int e = ea - eb + 127;  // biased exponent of a quotient in [1, 2)
  if (ma < mb) ma <<= 1u, --e;
  uint q = 1u, r = ma - mb;  // ma / mb in [1, 2): q = 25 bits of it, r the remainder (r < mb)
  for (int i = 0; i < 24; ++i) {
    r <<= 1u;
    q <<= 1u;
    if (r >= mb) r -= mb, q |= 1u;
  }
  // q / 2^24 in [1, 2) times 2^(e - 127): keep 24 bits (normal) or fewer (subnormal).
  const int drop = e >= 1 ? 1 : 2 - e;  // bits of q below the kept significand
  if (drop > 26) return uintBitsToFloat(sign);
  uint m = q >> uint(drop);
  const bool halfway = ((q >> uint(drop - 1)) & 1u) != 0u;
  const bool sticky = r != 0u || (q & ((1u << uint(drop - 1)) - 1u)) != 0u;
  if (halfway && (sticky || (m & 1u) != 0u)) ++m;  // a carry into the exponent is right
  const uint mag = e >= 1 ? (uint(e - 1) << 23u) + m : m;
  return uintBitsToFloat(sign | (e >= 255 || mag >= 0x7F800000u ? 0x7F800000u : mag));
}

#endif

// st_fdiv(a, b): a / b rounded as the CPU's IEEE 754 binary32 division, for the shaders
// that divide (the stack passes, the deep lookups of st_deep.glsl). Needs nothing else.
#ifndef SHADOWTILE_GPU_ST_FDIV_GLSL
#define SHADOWTILE_GPU_ST_FDIV_GLSL

// ---- division rounded as IEEE 754 binary32 (the CPU's a / b) ----
// Vulkan lets OpFDiv be off by 2.5 ulp (and flush subnormals), so the passes that divide (a
// perspective light's x / z, the soft pass's sum / N) take the device's division only as an
// estimate and make it exact in integers: the 24-bit significands ma, mb (subnormal operands
// normalised), ma doubled where ma < mb so that ma / mb is in [1, 2); the device divides
// float(ma) / float(mb) (both exact, normal, well inside OpFDiv's precise range), which
// gives Q0 ~ ma * 2^24 / mb; the remainder r = ma * 2^24 - Q0 * mb is exact in 32-bit
// integers (wrapping: |r| < 2^31 while |Q0 - Q| < 127); Q0 steps to the quotient Q with
// 0 <= r < mb (at most a few steps for a 2.5-ulp division, one on an exact one). Q (25 bits)
// and r are the long division's quotient and remainder: rounded to nearest even, subnormal
// quotients formed exactly; NaN, infinities and zeros as IEEE gives them (a NaN quotient is
// the default NaN 0x7FC00000; nothing compares or stores its payload). The steps are bounded
// for any estimate (|r| / mb < 2^8), so a wild device division gives a wrong quotient, never
// a hang. st_fdiv_est's `skew` moves the estimate by that many ulps (0 in every pass; the
// division test moves it by -3..3 ulps to check the steps on a device that divides exactly).
uint st_fdiv_norm(uint bits, out int e) {  // significand in [2^23, 2^24), exponent unbiased
  const uint m = bits & 0x7FFFFFu;
  e = int((bits >> 23u) & 0xFFu);
  if (e != 0) return m | 0x800000u;
  const int s = 23 - findMSB(m);  // subnormal (m != 0: zeros are handled before)
  e = 1 - s;
  return m << uint(s);
}

float st_fdiv_est(float a, float b, int skew) {
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
  // The estimate: float(ma) / float(mb) in [1, 2], times 2^24 (exact), as an integer.
  precise float est = float(ma) / float(mb);
  est = uintBitsToFloat(floatBitsToUint(est) + uint(skew));
  uint q = uint(est * 16777216.0);
  int r = int((ma << 24u) - q * mb);  // ma * 2^24 - q * mb, exact mod 2^32
  while (r < 0) --q, r += int(mb);
  while (r >= int(mb)) ++q, r -= int(mb);
  // q / 2^24 in [1, 2) times 2^(e - 127): keep 24 bits (normal) or fewer (subnormal).
  const int drop = e >= 1 ? 1 : 2 - e;  // bits of q below the kept significand
  if (drop > 26) return uintBitsToFloat(sign);
  uint m = q >> uint(drop);
  const bool halfway = ((q >> uint(drop - 1)) & 1u) != 0u;
  const bool sticky = r != 0 || (q & ((1u << uint(drop - 1)) - 1u)) != 0u;
  if (halfway && (sticky || (m & 1u) != 0u)) ++m;  // a carry into the exponent is right
  const uint mag = e >= 1 ? (uint(e - 1) << 23u) + m : m;
  return uintBitsToFloat(sign | (e >= 255 || mag >= 0x7F800000u ? 0x7F800000u : mag));
}

float st_fdiv(float a, float b) { return st_fdiv_est(a, b, 0); }

#endif

// Deep shadow maps on the GPU (Lokovic and Veach 2000; tiles/core/DEEP.md): the
// transmittance of a map's partial occluders (foliage cards, smoke, fog), per channel, bit
// for bit the CPU's lookups (DeepTileView::transmittance and ::filtered through
// DeepMap / the client's DeepPart, tiles/core/deep_tile.cpp) for the same tiles
// (GPU_LAYOUT.md "The deep block" and "Exactness").
//
// Include after st_layout.h and st_eval.glsl (StProbe, st_feedback) with ST_PAGE(i) defined
// (the page table: the block sits at word kPtDeep), or define ST_DEEP(i) as word i of
// another buffer holding a deep block.
// Feedback: a lookup whose deep tile the directory names (the block's presence bitmap) but
// the device does not hold records the tile in the frame's feedback (key kFbDeepKeyBit |
// ty << (D - b) | tx), as an absent opaque tile is, and marks the probe's hole; GpuMap
// asks the Map for it. The forms without a probe feed back too (a probe of their own).
// Functions (each also with a trailing `inout StProbe probe`):
//   st_deep_level()                          D, 0 when the map has no deep part (yet)
//   st_deep_transmittance(u, v, d, width)    at map coordinates (u, v) in [0, 1) and
//                                            light-space depth d, over a footprint `width`
//                                            map units wide (0: the texel under (u, v));
//                                            1 outside the map or where the device holds
//                                            no deep tile (none there, or not resident)
//   st_deep_shadow(uvd, footprint, kernel)   what a shadow lookup multiplies in: at the
//                                            surface point's (u, v, d) (no normal offset)
//                                            moved toward the light by the block's depth
//                                            bias, over kernel x max(1, footprint) finest
//                                            texels (bilinear at mip 0 while that is
//                                            a deep texel or less)
#ifndef SHADOWTILE_GPU_ST_DEEP_GLSL
#define SHADOWTILE_GPU_ST_DEEP_GLSL

#include "st_fdiv.glsl"

#ifndef ST_DEEP
#define ST_DEEP(i) ST_PAGE(i)
#endif

// Depths of magnitude below 2^-103 read as 0 (deep::kDepthFlushBelow): then every depth is
// 0 or a multiple of 2^-126, their differences are 0 or normal, and no step below forms a
// subnormal that a device without shaderDenormPreserveFloat32 would flush. Compared on the
// bits (no float compare of a subnormal).
float st_deep_flush(float d) { return (floatBitsToUint(d) & 0x7FFFFFFFu) < 0x0C000000u ? 0.0 : d; }

// Stored value k (unorm16) of a texel whose values start at word `values`, as a float:
// float(q) times the float nearest 1 / 65535 (deep::kUnormInverse), the CPU's product.
float st_deep_value(uint values, uint k) {
  const uint w = ST_DEEP(values + (k >> 1u));
  const uint q = (k & 1u) != 0u ? w >> 16u : w & 0xFFFFu;
  precise float v = float(q) * uintBitsToFloat(0x37800080u);
  return v;
}

vec3 st_deep_vertex(uint values, uint k, bool mono) {
  if (mono) {
    const float r = st_deep_value(values, k);
    return vec3(r, r, r);
  }
  return vec3(st_deep_value(values, 3u * k), st_deep_value(values, 3u * k + 1u), st_deep_value(values, 3u * k + 2u));
}

// DeepTileView::eval of texel `index` (directory order: mip 0 row-major, then each mip) of
// the deep tile at word `base`: the first vertex at depth >= z (a receiver at a step's
// depth sees the value before the step), then a + (b - a) * f per channel with f =
// clamp((z - za) / (zb - za), 0, 1), every operation rounded once (precise; st_fdiv),
// clamped to [min(a, b), max(a, b)].
// One call site per shader (the filters loop over their taps): st_fdiv stays one copy.
vec3 st_deep_texel(uint base, uint index, float z) {
  const uint texels = ST_DEEP(base + kDtTexelCount);
  const uint e = base + kDtHeaderWords + 2u * index;
  const uint info = ST_DEEP(e + 1u);
  const uint n = info & 0xFFFFu;
  if (n == 0u) return vec3(1.0);
  const bool mono = ((info >> 16u) & 1u) != 0u;
  const uint depths = base + kDtHeaderWords + 2u * texels + (ST_DEEP(e) >> 2u);
  const uint values = depths + n;  // u16 values from here, 2 a word
  const float zf = st_deep_flush(z);
  uint lo = 0u, hi = n;
  while (lo < hi) {
    const uint m = lo + (hi - lo) / 2u;
    if (st_deep_flush(uintBitsToFloat(ST_DEEP(depths + m))) < zf) lo = m + 1u;
    else hi = m;
  }
  if (lo == 0u || lo == n) return st_deep_vertex(values, lo == 0u ? 0u : n - 1u, mono);
  const float za = st_deep_flush(uintBitsToFloat(ST_DEEP(depths + lo - 1u)));
  const float zb = st_deep_flush(uintBitsToFloat(ST_DEEP(depths + lo)));
  precise float num = zf - za;
  precise float den = zb - za;
  const float f = clamp(st_fdiv(num, den), 0.0, 1.0);
  const vec3 a = st_deep_vertex(values, lo - 1u, mono), b = st_deep_vertex(values, lo, mono);
  precise vec3 r = a + (b - a) * f;
  return clamp(r, min(a, b), max(a, b));  // DeepTileView::eval's clamp: non-increasing in z
}

uint st_deep_level() {
  const uint blk = ST_PAGE(kPtDeep);
  return blk == 0u ? 0u : ST_DEEP(blk + kDpLevel);
}

// Tile (tx, ty) (grid index i) has no words on the device: when the directory names it,
// into the feedback (GpuMap fetches it), and the probe has a hole.
void st_deep_absent(uint blk, uint i, uint level, uint tx, uint ty, inout StProbe probe) {
  const uint pres = ST_DEEP(blk + kDpPresence);
  if (pres == 0u || (ST_DEEP(pres + (i >> 5u)) & (1u << (i & 31u))) == 0u) return;  // no partial occluder there
  st_feedback(kFbDeepKeyBit | i, level, tx, ty, 0u, 0u, probe);
}

// The word of the deep tile (tx, ty) on the device, or kNoSlot (no partial occluder over
// it, or not on the device): a binary search of the block's sorted keys.
uint st_deep_tile_base(uint blk, uint tx, uint ty) {
  const uint level = ST_DEEP(blk + kDpLevel), b = ST_DEEP(blk + kDpSideBits);
  const uint key = (ty << (level - b)) | tx;
  uint lo = 0u, hi = ST_DEEP(blk + kDpCount);
  while (lo < hi) {
    const uint m = lo + (hi - lo) / 2u;
    const uint k = ST_DEEP(blk + kDpHeaderWords + 2u * m);
    if (k == key) return ST_DEEP(blk + kDpHeaderWords + 2u * m + 1u);
    if (k < key) lo = m + 1u;
    else hi = m;
  }
  return kNoSlot;
}

// One axis of DeepTileView::bilinear_f at a mip `s` texels a side: p = w * s - 0.5
// clamped to [0, s - 1], the texel pair and the weight p - floor(p).
void st_deep_axis(float w, uint s, out uint i0, out uint i1, out float f) {
  const float last = float(s - 1u);
  precise float p = w * float(s) - 0.5;
  if (!(p > 0.0)) p = 0.0;
  if (p > last) p = last;
  i0 = uint(p);
  i1 = min(i0 + 1u, s - 1u);
  precise float frac = p - float(i0);
  f = frac;
}

// DeepTileView::bilinear_f's blend of four texels: a (1 - fx) + b fx per row, then the
// rows, each operation rounded once.
vec3 st_deep_blend4(vec3 a, vec3 b, vec3 c, vec3 d, float fx, float fy) {
  precise float gx = 1.0 - fx, gy = 1.0 - fy;
  precise vec3 top = a * gx + b * fx;
  precise vec3 bottom = c * gx + d * fx;
  precise vec3 r = top * gy + bottom * fy;
  return r;
}

vec3 st_deep_transmittance(float u, float v, float d, float width, inout StProbe probe) {
  const uint blk = ST_PAGE(kPtDeep);
  if (blk == 0u) return vec3(1.0);
  const uint level = ST_DEEP(blk + kDpLevel);
  if (level == 0u) return vec3(1.0);  // the directory is on its way
  if (!(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0)) return vec3(1.0);
  if ((floatBitsToUint(d) & 0x7F800000u) == 0x7F800000u) return vec3(1.0);  // not finite
  const uint b = ST_DEEP(blk + kDpSideBits);
  const uint t = 1u << (level - b);
  const float tf = uintBitsToFloat((127u + level - b) << 23u);  // tiles a side, exact
  precise float pu = u * tf, pv = v * tf;
  const uint tx = min(uint(pu), t - 1u), ty = min(uint(pv), t - 1u);
  const uint base = st_deep_tile_base(blk, tx, ty);
  if (base == kNoSlot) {
    st_deep_absent(blk, (ty << (level - b)) | tx, level, tx, ty, probe);
    return vec3(1.0);
  }
  precise float lu = pu - float(tx), lv = pv - float(ty);  // tile-local, exact
  const uint s = 1u << b;
  // The taps (directory indices): the texel under (u, v) (width 0), or four at mip m0 and,
  // when blended, four at m0 + 1; each evaluated at one call site, combined in the CPU's order.
  uint idx[8];
  uint taps = 1u, m0 = 0u;
  float fx0 = 0.0, fy0 = 0.0, fx1 = 0.0, fy1 = 0.0, f = 0.0;
  if (!(width > 0.0)) {
    precise float xs = lu * float(s), ys = lv * float(s);
    idx[0] = min(uint(ys), s - 1u) * s + min(uint(xs), s - 1u);
  } else {
    // DeepTileView::filtered: texels = width * 2^D (exact; an infinite width reads as 0);
    // lod = e + (m - 1) for texels = m * 2^e, from the bits.
    precise float texels = width * uintBitsToFloat((127u + level) << 23u);
    if ((floatBitsToUint(width) & 0x7FFFFFFFu) == 0x7F800000u) texels = 0.0;
    if (texels > 1.0) {
      const uint bits = floatBitsToUint(texels);
      const uint e = (bits >> 23u) - 127u;
      if (e >= b) m0 = b;
      else {
        m0 = e;
        f = float(bits & 0x7FFFFFu) * uintBitsToFloat(0x34000000u);  // * 2^-23, exact
      }
    }
    taps = f == 0.0 || m0 >= b ? 4u : 8u;
    uint mip_base = 0u;
    for (uint k = 0u; k < m0; ++k) mip_base += 1u << (2u * (b - k));
    for (uint j = 0u; j < taps; j += 4u) {
      const uint ms = s >> (m0 + j / 4u);
      uint x0, x1, y0, y1;
      float fx, fy;
      st_deep_axis(lu, ms, x0, x1, fx);
      st_deep_axis(lv, ms, y0, y1, fy);
      if (j == 0u) fx0 = fx, fy0 = fy;
      else fx1 = fx, fy1 = fy;
      idx[j] = mip_base + y0 * ms + x0;
      idx[j + 1u] = mip_base + y0 * ms + x1;
      idx[j + 2u] = mip_base + y1 * ms + x0;
      idx[j + 3u] = mip_base + y1 * ms + x1;
      mip_base += ms * ms;
    }
  }
  vec3 tv[8];
  for (uint i = 0u; i < taps; ++i) tv[i] = st_deep_texel(base, idx[i], d);
  if (taps == 1u) return tv[0];
  const vec3 a = st_deep_blend4(tv[0], tv[1], tv[2], tv[3], fx0, fy0);
  if (taps == 4u) return a;
  const vec3 c = st_deep_blend4(tv[4], tv[5], tv[6], tv[7], fx1, fy1);
  precise float g = 1.0 - f;
  precise vec3 r = a * g + c * f;
  return r;
}

vec3 st_deep_transmittance(float u, float v, float d, float width) {
  StProbe probe = st_probe();
  return st_deep_transmittance(u, v, d, width, probe);
}

vec3 st_deep_shadow(vec3 uvd, float footprint, uint kernel, inout StProbe probe) {
  const uint blk = ST_PAGE(kPtDeep);
  if (blk == 0u) return vec3(1.0);
  precise float d = uvd.z - uintBitsToFloat(ST_DEEP(blk + kDpDepthBias));
  // Never a point lookup: one texel's box-filtered coverage read as a step would put every
  // leaf edge on a deep texel's edge; bilinear between texel centres puts it where the
  // coverage crosses 1/2, between them (render.cpp measured the map against the rays).
  precise float texels = float(kernel) * (footprint > 1.0 ? footprint : 1.0);
  precise float width = texels * uintBitsToFloat((127u - ST_PAGE(kPtMapLevel)) << 23u);  // * 2^-L, exact
  return st_deep_transmittance(uvd.x, uvd.y, d, width, probe);
}

vec3 st_deep_shadow(vec3 uvd, float footprint, uint kernel) {
  StProbe probe = st_probe();
  return st_deep_shadow(uvd, footprint, kernel, probe);
}

#endif

// st_plane.glsl: a filtered lookup's receiver plane (tiles/core/receiver_plane.hpp) from
// the surface normal, for the shadow passes (shadow_pass.comp, engine_shadow_pass.comp,
// stack_shadow_pass.comp) and shadowtile.glsl (st_receiver_slope, st_visibility,
// st_shadow). Needs st_layout.h and ST_PAGE (the page table) first.
//
// The slopes (gx, gy): the plane's depth per finest texel along u and v, from the normal
// through the light's rows at `lb` (a, b, c: u, v, d of an affine light): the plane's normal
// in light space is (n . (b x c), n . (c x a), n . (a x b)) up to a factor, so
// d(depth)/du = -(n . (b x c)) / (n . (a x b)), likewise v, over 2^finest; each clamped to
// +-cap (the light's kStLightSlopeCap word: kMaxReceiverSlope times one finest texel's depth
// along the light ray, written by GpuMap), and a slope below 2^-60 (or NaN: a degenerate
// normal) is 0 (no subnormal products on devices that flush them). Every product, sum and
// the quotients (st_fdiv) rounded once, in the order written: gpu::receiver_slope_reference
// is the CPU twin. A perspective light (a stack's spot) answers (0, 0): one receiver depth.
#ifndef SHADOWTILE_GPU_ST_PLANE_GLSL
#define SHADOWTILE_GPU_ST_PLANE_GLSL
#include "st_fdiv.glsl"

const float kStMaxReceiverSlope = 4.0;  // kMaxReceiverSlope (tiles/core/receiver_plane.hpp)

float st_plane_word(uint lb, uint i) { return uintBitsToFloat(ST_PAGE(lb + i)); }

float st_slope_clamp(float g, float cap) {
  const float c = abs(g) <= cap ? g : g > 0.0 ? cap : g < 0.0 ? -cap : 0.0;
  return abs(c) < uintBitsToFloat(0x21800000u) ? 0.0 : c;  // 2^-60
}

// The slopes of the receiver plane with normal `normal` in the light at `lb`, clamped to cap.
vec2 st_plane_slope(uint lb, uint finest, vec3 normal, float cap) {
  if (lb == 0u || ST_PAGE(lb + kStLightProjection) != 0u) return vec2(0.0);
  const vec3 a = vec3(st_plane_word(lb, 3u), st_plane_word(lb, 4u), st_plane_word(lb, 5u));
  const vec3 b = vec3(st_plane_word(lb, 6u), st_plane_word(lb, 7u), st_plane_word(lb, 8u));
  const vec3 c = vec3(st_plane_word(lb, 9u), st_plane_word(lb, 10u), st_plane_word(lb, 11u));
  precise vec3 bc = vec3(b.y * c.z - b.z * c.y, b.z * c.x - b.x * c.z, b.x * c.y - b.y * c.x);
  precise vec3 ca = vec3(c.y * a.z - c.z * a.y, c.z * a.x - c.x * a.z, c.x * a.y - c.y * a.x);
  precise vec3 ab = vec3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
  precise float pu = normal.x * bc.x + normal.y * bc.y + normal.z * bc.z;
  precise float pv = normal.x * ca.x + normal.y * ca.y + normal.z * ca.z;
  precise float pw = normal.x * ab.x + normal.y * ab.y + normal.z * ab.z;
  const float side = uintBitsToFloat((127u + finest) << 23u);
  precise float den = pw * side;
  return vec2(st_slope_clamp(st_fdiv(-pu, den), cap), st_slope_clamp(st_fdiv(-pv, den), cap));
}
// The same with the light's own cap (kStLightSlopeCap): what the passes, st_visibility and
// st_shadow use, the CPU's Map::visibility_filtered with a normal likewise.
vec2 st_plane_slope(uint lb, uint finest, vec3 normal) {
  return st_plane_slope(lb, finest, normal, st_plane_word(lb, kStLightSlopeCap));
}

// The plane's depth at the low corner of the finest texel holding (u, v) (side = 2^finest):
// (d - gx * in_u) - gy * in_v with (in_u, in_v) the point's place in that texel; with the
// slopes, st_pcf_plane's / st_lookup_plane's plane (corner, gx, gy).
float st_plane_corner(vec3 uvd, vec2 slope, float side) {
  precise float su = uvd.x * side, sv = uvd.y * side;
  precise float fu = floor(su), fv = floor(sv);
  precise float in_u = su - fu, in_v = sv - fv;
  precise float du = slope.x * in_u, dv = slope.y * in_v;
  precise float corner_u = uvd.z - du;
  precise float corner = corner_u - dv;
  return corner;
}

#endif

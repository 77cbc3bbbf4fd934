#version 450
// The example renderer's fragment shader (examples/raster/raster.cpp): Lambert shading
// with streamed shadows as `shadowtile render` shades (ambient 0.15, albedo, sky, gamma
// 2.2 for its PNG), the visibility from the GPU tile cache through shadowtile.glsl (our
// buffers in set 0). Absent tiles answer coarsely and are fed back, so the next frames
// stream them. The level pair comes from the pixel's footprint (or the finest level).
// Stack maps: two slices blended at the frame's time, or every slice averaged (soft).
// mode.x picks the lookup: 0 none (the pass's cost without shadows), 1 shadowtile, 2 a
// plain R32F depth map of the finest level (set 1) with the same texel and PCF taps, the
// baseline the benchmark compares with. A 2D map's partial occluders (its deep part)
// multiply their transmittance per channel into the light. RASTER_TWIN: the receiver and the visibility are
// also written (a CPU twin answers the same lookups).
#define ST_MAP_KIND_ID 0  // specialization constant 0: 1 a 2D map, 2 a stack map (the other walk left out)
#define ST_SET 0
#define ST_BINDING_POOL 0
#define ST_BINDING_PAGE 1
#define ST_BINDING_FEEDBACK 2
#include "shadowtile.glsl"

// Early fragment tests: with the depth pre-pass and the EQUAL test only the visible
// surface runs this shader (its feedback writes would otherwise force the tests late).
layout(early_fragment_tests) in;

layout(set = 1, binding = 0) uniform sampler2D r32f_map;

layout(location = 0) in vec3 world_position;
layout(location = 1) in vec3 world_normal;
layout(push_constant) uniform Push {
  mat4 view_projection;
  vec4 light;  // xyz: toward a sun, or a point light's position (w == 1)
  vec4 eye;    // xyz: the camera; w: the pixel's angle (radians), 0: the finest level
  uvec4 mode;  // lookup, PCF kernel side, slice a | slice b << 16, soft
  vec4 misc;   // blend between slices a and b, one finest texel (world units), offset in texels,
               // the filtered lookups' offset in finest texels
} push;
layout(location = 0) out vec4 colour;
#ifdef RASTER_TWIN
layout(location = 1) out vec4 out_receiver;  // xyz the receiver; w the footprint (finest texels), -1: no lookup
layout(location = 2) out vec4 out_visibility;  // x the visibility, yz the receiver plane's slopes
#endif

// The baseline: r x r PCF on the R32F map at the finest level, the lit test and the
// taps clamped at the edges as st_pcf's (the fraction of lit taps).
float r32f_shadow(vec3 uvd, uint r) {
  if (!st_in_light_box(uvd)) return 1.0;
  const uint finest = st_finest_level();
  const float side = uintBitsToFloat((127u + finest) << 23u);
  const uint x = min(uint(floor(uvd.x * side)), (1u << finest) - 1u), y = min(uint(floor(uvd.y * side)), (1u << finest) - 1u);
  const uint n = 1u << finest;
  uint lit = 0u;
  for (uint j = 0u; j < r; ++j)
    for (uint i = 0u; i < r; ++i)
      lit += st_lit(uvd.z, texelFetch(r32f_map, ivec2(st_pcf_tap(x, i, r, n), st_pcf_tap(y, j, r, n)), 0).x) ? 1u : 0u;
  return float(lit) / float(r * r);
}

void main() {
  vec3 n = normalize(world_normal);
  if (dot(n, push.eye.xyz - world_position) < 0.0) n = -n;  // the side the camera sees
  const vec3 to_light = push.light.w != 0.0 ? normalize(push.light.xyz - world_position) : push.light.xyz;
  const float lambert = max(dot(n, to_light), 0.0);
  // The footprint in finest texels, as `shadowtile render --filter` measures it
  // (render/render.cpp): the pixel's size at the receiver (distance x pixel angle)
  // over one finest texel. The light-space derivatives (st_footprint_of with uvd +
  // dFdx(uvd)) overestimate it at grazing angles: coarser levels, speckled shadows.
  const float footprint = push.eye.w != 0.0 ? distance(push.eye.xyz, world_position) * push.eye.w / push.misc.y : 1.0;
  // The receiver's offset along the normal, as the CPU renderer's (render/render.hpp):
  // unfiltered, 1.5 texels plus the PCF radius; filtered, 1.5 finest texels and every PCF
  // tap against the receiver's plane (st_receiver_slope: its depth slopes from the normal;
  // render's filtered_lookup), so that kernels of coarse texels on sloped surfaces do not
  // shadow their own surface.
  const bool filtered = push.eye.w != 0.0;
  const float offset = filtered ? push.misc.w * push.misc.y : push.misc.z * push.misc.y;
  const uint kernel = push.mode.y;
  vec2 slope = vec2(0.0);
  float vis = 1.0;
  StProbe probe = st_probe();
  if (lambert <= 0.0) {
    vis = 0.0;  // facing away: unlit whatever the map says
  } else if (push.mode.x == 1u) {
    // One call site of the lookup (each inlines the page-table walk and the decoders):
    // a 2D map's one light, a stack's slices a and b (blended as st_shadow_stack), or
    // every slice (soft: summed in slice order, then divided, as the CPU's).
    const uint slices = st_slices();
    const bool soft = slices != 0u && push.mode.w != 0u;
    const uint a = push.mode.z & 0xFFFFu, b = push.mode.z >> 16;
    const uint count = slices == 0u ? 1u : soft ? slices : (a == b ? 1u : 2u);
    const vec3 r = st_receiver(world_position, n, offset);
    if (filtered && slices == 0u) slope = st_receiver_slope(st_light_block(0u), n, to_light, push.misc.y);
    precise float sum = 0.0;
    float va = 1.0, vb = 1.0;
    for (uint i = 0u; i < count; ++i) {
      const uint w = soft ? i : (i == 0u ? a : b);
      const uint lb = st_light_block(slices == 0u ? 0u : w);
      const float v = lb == 0u ? 1.0 : st_shadow_uvd_plane(w, st_light_uvd(lb, r), slope, footprint, kernel, probe);
      sum = sum + v;
      if (i == 0u) va = v;
      else vb = v;
    }
    if (soft) {
      vis = st_fdiv(sum, float(slices));  // rounded as the CPU divides (st_fdiv.glsl)
    } else if (count == 2u) {
      precise float step = vb - va;
      precise float scaled = push.misc.x * step;
      precise float blended = va + scaled;
      vis = blended;
    } else {
      vis = va;
    }
  } else if (push.mode.x == 2u) {
    const uint lb = st_light_block(0u);
    if (lb != 0u) vis = r32f_shadow(st_light_uvd(lb, st_receiver(world_position, n, offset)), kernel);
  }
#ifdef RASTER_TWIN
  out_receiver = vec4(st_receiver(world_position, n, offset), lambert > 0.0 && push.mode.x == 1u ? footprint : -1.0);
  out_visibility = vec4(vis, slope, 0.0);
#endif
  // The light per channel: on a 2D map with a deep part (foliage, smoke, fog) the
  // visibility times the partial occluders' transmittance (shadowtile.glsl).
  vec3 light = vec3(vis);
  if (lambert > 0.0 && push.mode.x == 1u && st_slices() == 0u) {
    precise vec3 lit = vis * st_transmittance(world_position, footprint, kernel, probe);  // feeds back deep tiles
    light = lit;
  }
  st_finish(probe);
  const vec3 albedo = vec3(0.8, 0.78, 0.72);
  const vec3 c = albedo * (0.15 + 0.85 * lambert * light);
  colour = vec4(pow(c, vec3(1.0 / 2.2)), 1.0);
}

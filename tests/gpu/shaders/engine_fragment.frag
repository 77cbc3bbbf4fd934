#version 450
// An engine's fragment shader over the GPU tile cache (the fragment-shader test): our
// buffers in set 0 at the bindings the engine chose, its G-buffer in set 1; per pixel the
// receiver's visibility with the footprint given, feedback on, or one channel of the light
// (st_shadow: times the deep part's transmittance; compiled with ST_TEST_DEEP for the deep
// tests, engine_fragment_deep.frag.spv.inc). The opaque build reads the pool and page table
// as uniform texel buffers (ST_TEXEL_BUFFERS: GpuOptions::texel_buffers' views), the deep build
// as storage buffers, so both of shadowtile.glsl's modes run. It must answer what the compute pass
// answers with neighbour_footprint off, bit for bit. One lookup per pipeline, as an engine
// calls it once: specialization constant 1 picks st_visibility (channel 0), st_shadow
// (1..3) or st_shadow_uvd_plane (4), constant 0 (ST_MAP_KIND_ID) says a 2D map; the others
// fold away (each call site would inline the tile walk again: minutes of pipeline compile
// on a software device from a cold shader cache).
#define ST_MAP_KIND_ID 0
#define ST_SET 0
#define ST_BINDING_POOL 3
#define ST_BINDING_PAGE 5
#define ST_BINDING_FEEDBACK 7
#ifndef ST_TEST_DEEP
#define ST_DEEP_SHADOWS 0  // the opaque tests' build: st_shadow = vec3(visibility), less to compile
#define ST_TEXEL_BUFFERS   // and the pool and page table as texel buffers (the deep build: storage buffers)
#endif
#include "shadowtile.glsl"

layout(set = 1, binding = 0) uniform sampler2D gbuffer_positions;
layout(set = 1, binding = 1) uniform sampler2D gbuffer_normals;
layout(push_constant) uniform Push {
  uint kernel;
  float normal_offset;
  float footprint;
  uint channel;  // 0: st_visibility; 1..3: st_shadow's r, g, b; 4: with the receiver plane
  vec4 to_light_texel;  // channel 4: xyz toward the light (unit), w one finest texel (world)
} push;
layout(location = 0) out float visibility;
layout(constant_id = 1) const uint kLookup = 0u;  // 0: st_visibility, 1: st_shadow, 2: st_shadow_uvd_plane

void main() {
  const ivec2 q = ivec2(gl_FragCoord.xy);
  const vec4 p = texelFetch(gbuffer_positions, q, 0);
  if (p.w == 0.0) {
    visibility = 1.0;
    return;
  }
  StProbe probe = st_probe();
  const vec3 n = texelFetch(gbuffer_normals, q, 0).xyz;
  if (kLookup == 2u) {
    // An engine's filtered lookup with the receiver plane (shadowtile.glsl).
    const uint lb = st_light_block(0u);
    const vec2 slope = st_receiver_slope(lb, n, push.to_light_texel.xyz, push.to_light_texel.w);
    const vec3 uvd = st_light_uvd(lb, st_receiver(p.xyz, n, push.normal_offset));
    visibility = st_shadow_uvd_plane(0u, uvd, slope, push.footprint, push.kernel, probe);
  } else if (kLookup == 0u) {
    visibility = st_visibility(p.xyz, n, push.normal_offset, push.footprint, push.kernel, probe);
  } else {
    const vec3 light = st_shadow(p.xyz, n, push.normal_offset, push.footprint, push.kernel, probe);
    visibility = light[push.channel - 1u];
  }
  st_finish(probe);
}

// shadowtile.glsl: the GPU tile cache for an engine's own shaders (fragment, compute, any
// stage that may read storage buffers). Installed with the client (share/shadowtile/shaders)
// beside st_layout.h, st_eval.glsl, st_stack.glsl, st_fdiv.glsl, st_deep.glsl and st_plane.glsl, which it
// includes: compile with glslc -I <that folder>. It declares GpuMap's three buffers at the
// set and bindings the engine chooses and answers the light reaching a world position,
// bit for bit as the CPU's Map::pcf / Evaluator::pcf_footprint (2D maps) and StackMap's filtered
// lookups (stack maps) answer with the same float light transform
// (gpu/shadow_reference.hpp), times the deep part's transmittance (partial occluders:
// foliage, smoke, fog) as the CPU's deep lookups answer it. The light comes from the page
// table (GPU-resident, uploaded once): nothing per frame but what the engine passes as
// arguments.
//
//   #define ST_SET 2                  // descriptor set of our buffers (default 0)
//   #define ST_BINDING_POOL 0         // GpuDescriptors::pool        (default 0)
//   #define ST_BINDING_PAGE 1         // GpuDescriptors::page_table  (default 1)
//   #define ST_BINDING_FEEDBACK 2     // GpuDescriptors::feedback    (default 2)
//   #define ST_FEEDBACK 0             // optional: no feedback buffer (read-only use)
//   #define ST_DEEP_SHADOWS 0         // optional: no partial occluders (st_shadow = vec3(visibility))
//   #define ST_MAP_KIND_ID 7          // optional: specialization constant 7 says which maps the
//                                     // pipeline serves: 0 either (default), 1 2D, 2 stack
//   #define ST_TEXEL_BUFFERS          // optional: the pool and page table read through texelFetch
//                                     // on uniform texel buffers (GpuOptions::texel_buffers)
//   #include "shadowtile.glsl"
//   ...
//   StProbe probe = st_probe();
//   vec3 light = st_shadow(world_pos, normal, normal_offset, footprint, 3u, probe);  // per channel
//   float vis = st_visibility(world_pos, normal, normal_offset, footprint, 3u, probe);  // opaque only
//   st_finish(probe);                 // counts the pixel in the feedback's holes
//
// footprint: the pixel's size in texels of the map's finest level (the level choice of
// MH §3.3 / Evaluator::pcf_footprint); st_footprint_of measures it from neighbouring receivers'
// light-space positions (the passes' definition: a compute pass's neighbours, or uvd +
// dFdx(uvd) in a fragment shader), which grows at grazing angles; distance x pixel angle /
// texel (render/render.cpp's) stays isotropic (examples/shaders/scene.frag). Filtered
// kernels on surfaces sloped to the light shadow their own surface (a coarse level's
// above all: rings around the camera) unless each tap compares the receiver's plane, so
// st_visibility and st_shadow compare each tap with the plane through the receiver with
// the surface's normal (st_receiver_slope, st_plane.glsl), as the CPU's
// Map::visibility_filtered with a normal and `shadowtile render --filter` do
// (tiles/core/receiver_plane.hpp); an offset of 1.5 finest texels suits open surfaces:
//   float vis = st_visibility(p, normal, 1.5 * finest_texel_world, footprint, 3u, probe);
// One receiver depth for every tap (the unfiltered rule) is st_shadow_uvd. The deep part is
// looked up at the surface point itself moved toward the light along the light ray by 1.5
// deep texels (no normal offset, which would shift leaf shadows sideways), filtered with
// its mips over kernel x max(1, footprint) finest texels (st_deep.glsl). Feedback: every
// absent tile a call needed lands in the frame's feedback buffer
// (GpuMap reads it back when the frame retires and queues the tiles on the Map); it needs
// a stage with storage-buffer writes (fragmentStoresAndAtomics for fragment shaders).
// Deep tiles are fed back likewise (the tiles of partial occluders a lookup needed; pass the
// probe to st_transmittance). No workgroup size is assumed: the engine declares its own local_size.
// Compile time: a shader compiler inlines every function, so each call of st_visibility,
// st_shadow, st_shadow_uvd[_plane] or st_shadow_stack in a shader is one more copy of the
// tile walk and its decoders (a pipeline compile of minutes on a software device from a cold
// shader cache): call one of them once per shader (loop over slices or taps around the call,
// as examples/shaders/scene.frag does), and with ST_MAP_KIND_ID set the specialization
// constant to GpuMap::is_stack() (1 for a 2D map, 2 for a stack map) at pipeline creation:
// the walk of the other kind of map is then left out.
// Texel buffers (ST_TEXEL_BUFFERS defined): the pool and the page table are read with
// texelFetch on usamplerBuffers (R32_UINT views) instead of storage buffers: the same words,
// so the same answers bit for bit. Create the GpuMap with GpuOptions::texel_buffers and bind
// GpuDescriptors::pool_view and page_table_view as VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER at
// ST_BINDING_POOL and ST_BINDING_PAGE (the feedback stays a storage buffer). On lavapipe it
// did not make the 5x5 lookup cheaper (bench/raster.cpp's header: the figures).
#ifndef SHADOWTILE_GLSL
#define SHADOWTILE_GLSL
#extension GL_GOOGLE_include_directive : require

#ifndef ST_SET
#define ST_SET 0
#endif
#ifndef ST_BINDING_POOL
#define ST_BINDING_POOL 0
#endif
#ifndef ST_BINDING_PAGE
#define ST_BINDING_PAGE 1
#endif
#ifndef ST_BINDING_FEEDBACK
#define ST_BINDING_FEEDBACK 2
#endif
#ifndef ST_FEEDBACK
#define ST_FEEDBACK 1
#endif
#ifndef ST_DEEP_SHADOWS
#define ST_DEEP_SHADOWS 1
#endif

#include "st_layout.h"

#ifdef ST_TEXEL_BUFFERS
// The pool and page table as uniform texel buffers (R32_UINT views: GpuDescriptors'
// pool_view and page_table_view, VK_DESCRIPTOR_TYPE_UNIFORM_TEXEL_BUFFER).
layout(set = ST_SET, binding = ST_BINDING_POOL) uniform usamplerBuffer st_pool_texels;
layout(set = ST_SET, binding = ST_BINDING_PAGE) uniform usamplerBuffer st_page_texels;
#define ST_POOL(i) texelFetch(st_pool_texels, int(i)).x
#define ST_PAGE(i) texelFetch(st_page_texels, int(i)).x
#else
layout(std430, set = ST_SET, binding = ST_BINDING_POOL) readonly buffer StPoolBuffer { uint st_pool[]; };
layout(std430, set = ST_SET, binding = ST_BINDING_POOL) readonly buffer StPoolQuads { uvec4 st_pool_quads[]; };  // the same pool
layout(std430, set = ST_SET, binding = ST_BINDING_PAGE) readonly buffer StPageBuffer { uint st_page[]; };
#define ST_POOL(i) st_pool[i]
#define ST_POOL4(q) st_pool_quads[q]
#define ST_PAGE(i) st_page[i]
#endif
#if ST_FEEDBACK
layout(std430, set = ST_SET, binding = ST_BINDING_FEEDBACK) coherent buffer StFeedbackBuffer { uint st_fb[]; };
#define ST_FB(i) st_fb[i]
#else
#define ST_NO_FEEDBACK 1
#endif

#include "st_eval.glsl"
#include "st_stack.glsl"
#include "st_plane.glsl"
#if ST_DEEP_SHADOWS
#include "st_deep.glsl"
#endif

// ---- the map and its lights (page table) ----
#ifdef ST_MAP_KIND_ID
layout(constant_id = ST_MAP_KIND_ID) const uint st_map_kind = 0u;
#else
const uint st_map_kind = 0u;
#endif
// A stack map (the page table's stack block), or what the pipeline's st_map_kind says.
bool st_stack_map() { return st_map_kind == 0u ? ST_PAGE(kPtStack) != 0u : st_map_kind == 2u; }
// Slices of a stack map (0: a 2D map).
uint st_slices() {
  const uint blk = ST_PAGE(kPtStack);
  return blk == 0u ? 0u : ST_PAGE(blk + kStSlices);
}
// The finest level of the light space's texels (2D: the map's; stack: a slice's).
uint st_finest_level() {
  const uint blk = ST_PAGE(kPtStack);
  return blk == 0u ? ST_PAGE(kPtMapLevel) : ST_PAGE(blk + kStXyLevel);
}
// Word offset of the light block (kStLightWords words) of slice w (stack maps) or of the
// map's light (2D maps: w unused); 0 when the map has none the GPU can use.
uint st_light_block(uint w) {
  const uint blk = ST_PAGE(kPtStack);
  return blk == 0u ? ST_PAGE(kPtLight) : ST_PAGE(blk + kStLights) + w * kStLightWords;
}
float st_light_word(uint lb, uint i) { return uintBitsToFloat(ST_PAGE(lb + i)); }

// The receiver: the surface point moved `offset` world units along the normal, each
// component p + n * offset (the product rounded, then the sum: never fused).
vec3 st_receiver(vec3 position, vec3 normal, float offset) {
  precise float rx = position.x + normal.x * offset;
  precise float ry = position.y + normal.y * offset;
  precise float rz = position.z + normal.z * offset;
  return vec3(rx, ry, rz);
}

// Light-space (u, v, d) of a receiver in the light at `lb`: (r - origin) against the
// scaled axes, a perspective light's divide rounded as the CPU's (st_fdiv), d from near.
vec3 st_light_uvd(uint lb, vec3 receiver) {
  precise float rx = receiver.x - st_light_word(lb, 0u);
  precise float ry = receiver.y - st_light_word(lb, 1u);
  precise float rz = receiver.z - st_light_word(lb, 2u);
  precise float pu = rx * st_light_word(lb, 3u) + ry * st_light_word(lb, 4u) + rz * st_light_word(lb, 5u);
  precise float pv = rx * st_light_word(lb, 6u) + ry * st_light_word(lb, 7u) + rz * st_light_word(lb, 8u);
  precise float pz = rx * st_light_word(lb, 9u) + ry * st_light_word(lb, 10u) + rz * st_light_word(lb, 11u);
  if (ST_PAGE(lb + kStLightProjection) != 0u) {
    pu = st_fdiv(pu, pz) + st_light_word(lb, kStLightCentreU);
    pv = st_fdiv(pv, pz) + st_light_word(lb, kStLightCentreV);
  }
  precise float pd = pz - st_light_word(lb, 12u);
  return vec3(pu, pv, pd);
}

bool st_in_light_box(vec3 uvd) {
  return uvd.x >= 0.0 && uvd.x < 1.0 && uvd.y >= 0.0 && uvd.y < 1.0 && uvd.z >= 0.0 && uvd.z <= 1.0;
}

// The footprint in finest texels from the light-space positions of the neighbours that
// hold a surface: max over them of max(|du|, |dv|), times 2^finest (0 with none).
float st_footprint_of(vec3 uvd, vec3 right, bool has_right, vec3 down, bool has_down) {
  precise float f = 0.0;
  if (has_right) f = max(f, max(abs(right.x - uvd.x), abs(right.y - uvd.y)));
  if (has_down) f = max(f, max(abs(down.x - uvd.x), abs(down.y - uvd.y)));
  const float side = uintBitsToFloat((127u + st_finest_level()) << 23u);  // 2^finest, exact
  return f * side;
}

// ---- receiver-plane depth bias (tiles/core/receiver_plane.hpp, st_plane.glsl) ----
// A filtered lookup compares each PCF tap with the receiver's plane over the tap's texel,
// not with one depth: on surfaces sloped to the light a kernel (a coarse level's above all)
// otherwise shadows its own surface (rings around the camera on sloped open ground).
// st_receiver_slope: the plane's depth slopes per finest texel, (gx, gy), from the surface
// normal through the light at `lb` (st_plane_slope), each clamped to kStMaxReceiverSlope
// times the depth of one texel along the light ray: the light's own cap (kStLightSlopeCap,
// what st_visibility, st_shadow and the shadow passes use), or one from `texel` (one finest
// texel in world units) and `to_light` (the unit direction toward the light),
// kStMaxReceiverSlope * (texel * |c . to_light|). gpu::receiver_slope_reference is the CPU
// twin. A perspective light (a stack's spot) answers (0, 0): one receiver depth, as before.
vec2 st_receiver_slope(uint lb, vec3 normal) {
  if (lb == 0u) return vec2(0.0);
  return st_plane_slope(lb, st_finest_level(), normal);
}
vec2 st_receiver_slope(uint lb, vec3 normal, vec3 to_light, float texel) {
  if (lb == 0u) return vec2(0.0);
  const vec3 c = vec3(st_light_word(lb, 9u), st_light_word(lb, 10u), st_light_word(lb, 11u));
  precise float cl = c.x * to_light.x + c.y * to_light.y + c.z * to_light.z;
  precise float cap = kStMaxReceiverSlope * (texel * abs(cl));
  return st_plane_slope(lb, st_finest_level(), normal, cap);
}

// st_shadow_uvd with the receiver plane: slope (gx, gy) from st_receiver_slope (slice w's
// light for a stack map), the plane through uvd: its depth at the low corner of uvd's
// finest texel (st_plane_corner).
float st_shadow_uvd_plane(uint w, vec3 uvd, vec2 slope, float footprint, uint kernel, inout StProbe probe) {
  if (kernel < 1u || kernel > 9u || (kernel & 1u) == 0u) return uintBitsToFloat(0x7FC00000u);
  if (!st_in_light_box(uvd)) return 1.0;
  const uint finest = st_finest_level();
  const float side = uintBitsToFloat((127u + finest) << 23u);
  precise float fu = floor(uvd.x * side), fv = floor(uvd.y * side);
  const uint x = min(uint(fu), (1u << finest) - 1u), y = min(uint(fv), (1u << finest) - 1u);
  const vec3 plane = vec3(st_plane_corner(uvd, slope, side), slope.x, slope.y);
  if (st_stack_map()) return st_stack_lookup_plane(x, y, w, plane, footprint, kernel, probe);
  return st_lookup_plane(x, y, plane, footprint, kernel, probe);
}

// Visibility of a light-space point in slice w (2D maps: w unused): outside the light's box
// lit (1); else the texel floor(uv * 2^finest), the level pair of the footprint and
// kernel x kernel PCF at each with one receiver depth (uvd.z) for every tap, blended.
// kernel: the PCF kernel side, odd 1..9 (the C++ API's unit); any other answers NaN, as
// Map::visibility does. Absent tiles answer coarsely and are fed back. The same walk as
// st_shadow_uvd_plane with zero slopes (its plane's corner is then uvd.z, bit for bit).
float st_shadow_uvd(uint w, vec3 uvd, float footprint, uint kernel, inout StProbe probe) {
  return st_shadow_uvd_plane(w, uvd, vec2(0.0), footprint, kernel, probe);
}

// Visibility at a world position (2D maps; on a stack map slice 0): the receiver offset
// along the normal, the map's light, the footprint given, each PCF tap against the
// receiver's plane (st_receiver_slope(lb, normal): Map::visibility_filtered with a normal,
// the shadow passes' rule). 1 where the map has no light. One receiver depth for every
// tap: st_shadow_uvd(0u, st_light_uvd(lb, st_receiver(...)), ...).
float st_visibility(vec3 world_position, vec3 normal, float normal_offset, float footprint, uint kernel,
                    inout StProbe probe) {
  const uint lb = st_light_block(0u);
  if (lb == 0u) return 1.0;
  return st_shadow_uvd_plane(0u, st_light_uvd(lb, st_receiver(world_position, normal, normal_offset)),
                             st_receiver_slope(lb, normal), footprint, kernel, probe);
}

// The deep part's transmittance per channel at a world position (the surface point, no
// normal offset: st_deep_shadow); 1 for a map without a deep part, a stack map, or with
// ST_DEEP_SHADOWS 0. An absent deep tile is fed back and marks the probe's hole.
vec3 st_transmittance(vec3 world_position, float footprint, uint kernel, inout StProbe probe) {
#if ST_DEEP_SHADOWS
  const uint lb = st_light_block(0u);
  if (lb == 0u || st_stack_map() || ST_PAGE(kPtDeep) == 0u) return vec3(1.0);
  return st_deep_shadow(st_light_uvd(lb, world_position), footprint, kernel, probe);
#else
  return vec3(1.0);
#endif
}
vec3 st_transmittance(vec3 world_position, float footprint, uint kernel) {
  StProbe probe = st_probe();
  return st_transmittance(world_position, footprint, kernel, probe);
}

// The light reaching a world position per channel (2D maps; on a stack map slice 0):
// st_visibility times st_transmittance, one rounding per channel.
vec3 st_shadow(vec3 world_position, vec3 normal, float normal_offset, float footprint, uint kernel,
               inout StProbe probe) {
  const float vis = st_visibility(world_position, normal, normal_offset, footprint, kernel, probe);
  precise vec3 light = vis * st_transmittance(world_position, footprint, kernel, probe);
  return light;
}

// A stack map at a time of the light set: slices a and b (GpuMap's stack_time: a == b at a
// sample's time) blended va + f * (vb - va), each in its own light with the same footprint
// and its own receiver plane (st_receiver_slope in that slice's light; a spot's: none).
float st_shadow_stack(vec3 world_position, vec3 normal, float normal_offset, float footprint, uint kernel, uint a,
                      uint b, float f, inout StProbe probe) {
  const vec3 r = st_receiver(world_position, normal, normal_offset);
  const uint la = st_light_block(a), lb = st_light_block(b);
  const float va = st_shadow_uvd_plane(a, st_light_uvd(la, r), st_receiver_slope(la, normal), footprint, kernel, probe);
  if (a == b) return va;
  const float vb = st_shadow_uvd_plane(b, st_light_uvd(lb, r), st_receiver_slope(lb, normal), footprint, kernel, probe);
  precise float step = vb - va;
  precise float scaled = f * step;
  precise float blended = va + scaled;
  return blended;
}

// Ends a pixel's lookups: counts it in the frame's holes when a tap answered coarsely.
void st_finish(StProbe probe) {
#if ST_FEEDBACK
  if (probe.hole) atomicAdd(ST_FB(kFbHoles), 1u);
#endif
}

#endif

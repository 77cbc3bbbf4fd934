// shadowtile.glsl: the GPU tile cache for an engine's own shaders (fragment, compute, any
// stage that may read storage buffers). Installed with the client (share/shadowtile/shaders)
// beside st_layout.h, st_eval.glsl, st_stack.glsl, st_fdiv.glsl and st_deep.glsl, which it
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
// above all: rings around the camera) unless each tap compares the receiver's plane:
//   vec2 slope = st_receiver_slope(st_light_block(0u), normal, to_light, finest_texel_world);
//   float vis = st_shadow_uvd_plane(0u, st_light_uvd(st_light_block(0u), st_receiver(p, normal, 1.5 * finest_texel_world)),
//                                   slope, footprint, 3u, probe);
// as `shadowtile render --filter` does (render/render.hpp filtered_lookup); st_visibility
// and st_shadow take one receiver depth (the unfiltered rule). The deep part is
// looked up at the surface point itself moved toward the light along the light ray by 1.5
// deep texels (no normal offset, which would shift leaf shadows sideways), filtered with
// its mips over kernel x max(1, footprint) finest texels (st_deep.glsl). Feedback: every
// absent tile a call needed lands in the frame's feedback buffer
// (GpuMap reads it back when the frame retires and queues the tiles on the Map); it needs
// a stage with storage-buffer writes (fragmentStoresAndAtomics for fragment shaders).
// Deep tiles are fed back likewise (the tiles of partial occluders a lookup needed; pass the
// probe to st_transmittance). No workgroup size is assumed: the engine declares its own local_size.
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

layout(std430, set = ST_SET, binding = ST_BINDING_POOL) readonly buffer StPoolBuffer { uint st_pool[]; };
layout(std430, set = ST_SET, binding = ST_BINDING_PAGE) readonly buffer StPageBuffer { uint st_page[]; };
#define ST_POOL(i) st_pool[i]
#define ST_PAGE(i) st_page[i]
#if ST_FEEDBACK
layout(std430, set = ST_SET, binding = ST_BINDING_FEEDBACK) coherent buffer StFeedbackBuffer { uint st_fb[]; };
#define ST_FB(i) st_fb[i]
#else
#define ST_NO_FEEDBACK 1
#endif

#include "st_eval.glsl"
#include "st_stack.glsl"
#if ST_DEEP_SHADOWS
#include "st_deep.glsl"
#endif

// ---- the map and its lights (page table) ----
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

// Visibility of a light-space point in slice w (2D maps: w unused): outside the light's box
// lit (1); else the texel floor(uv * 2^finest), the level pair of the footprint and
// kernel x kernel PCF at each, blended. kernel: the PCF kernel side, odd 1..9 (the C++
// API's unit); any other answers NaN, as Map::visibility does. Absent tiles answer
// coarsely and are fed back.
float st_shadow_uvd(uint w, vec3 uvd, float footprint, uint kernel, inout StProbe probe) {
  if (kernel < 1u || kernel > 9u || (kernel & 1u) == 0u) return uintBitsToFloat(0x7FC00000u);
  if (!st_in_light_box(uvd)) return 1.0;
  const uint finest = st_finest_level();
  const float side = uintBitsToFloat((127u + finest) << 23u);
  precise float fu = floor(uvd.x * side), fv = floor(uvd.y * side);
  const uint x = min(uint(fu), (1u << finest) - 1u), y = min(uint(fv), (1u << finest) - 1u);
  if (ST_PAGE(kPtStack) != 0u) return st_stack_lookup(x, y, w, uvd.z, footprint, kernel, probe);
  return st_lookup(x, y, uvd.z, footprint, kernel, probe);
}

// ---- receiver-plane depth bias (tiles/core/receiver_plane.hpp) ----
// A filtered lookup compares each PCF tap with the receiver's plane over the tap's texel,
// not with one depth: on surfaces sloped to the light a kernel (a coarse level's above all)
// otherwise shadows its own surface (rings around the camera on sloped open ground).
// st_receiver_slope: the plane's depth slopes per finest texel, (gx, gy), from the
// surface normal through the light's rows at `lb` (a, b, c: u, v, d of an affine light):
// the plane's normal in light space is (n . (b x c), n . (c x a), n . (a x b)) up to a
// factor, so d(depth)/du = -(n . (b x c)) / (n . (a x b)), likewise v, over 2^finest; each
// clamped to kStMaxReceiverSlope times the depth of one texel along the light ray (texel:
// one finest texel in world units, to_light: the unit direction toward the light), and a
// slope below 2^-60 (or NaN) is 0 (no subnormal products on devices that flush them).
// Every product, sum and the quotients (st_fdiv) rounded once, in the order written:
// gpu::receiver_slope_reference is the CPU twin. A perspective light (a stack's spot)
// answers (0, 0): one receiver depth, as before.
const float kStMaxReceiverSlope = 4.0;  // kMaxReceiverSlope (tiles/core/receiver_plane.hpp)
float st_slope_clamp(float g, float cap) {
  const float c = abs(g) <= cap ? g : g > 0.0 ? cap : g < 0.0 ? -cap : 0.0;
  return abs(c) < uintBitsToFloat(0x21800000u) ? 0.0 : c;  // 2^-60
}
vec2 st_receiver_slope(uint lb, vec3 normal, vec3 to_light, float texel) {
  if (lb == 0u || ST_PAGE(lb + kStLightProjection) != 0u) return vec2(0.0);
  const vec3 a = vec3(st_light_word(lb, 3u), st_light_word(lb, 4u), st_light_word(lb, 5u));
  const vec3 b = vec3(st_light_word(lb, 6u), st_light_word(lb, 7u), st_light_word(lb, 8u));
  const vec3 c = vec3(st_light_word(lb, 9u), st_light_word(lb, 10u), st_light_word(lb, 11u));
  precise vec3 bc = vec3(b.y * c.z - b.z * c.y, b.z * c.x - b.x * c.z, b.x * c.y - b.y * c.x);
  precise vec3 ca = vec3(c.y * a.z - c.z * a.y, c.z * a.x - c.x * a.z, c.x * a.y - c.y * a.x);
  precise vec3 ab = vec3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
  precise float pu = normal.x * bc.x + normal.y * bc.y + normal.z * bc.z;
  precise float pv = normal.x * ca.x + normal.y * ca.y + normal.z * ca.z;
  precise float pw = normal.x * ab.x + normal.y * ab.y + normal.z * ab.z;
  const float side = uintBitsToFloat((127u + st_finest_level()) << 23u);
  precise float den = pw * side;
  precise float cl = c.x * to_light.x + c.y * to_light.y + c.z * to_light.z;
  precise float cap = kStMaxReceiverSlope * (texel * abs(cl));
  return vec2(st_slope_clamp(st_fdiv(-pu, den), cap), st_slope_clamp(st_fdiv(-pv, den), cap));
}

// st_shadow_uvd with the receiver plane: slope (gx, gy) from st_receiver_slope, the plane
// through uvd: its depth at the low corner of uvd's finest texel, corner = (d - gx * fu) -
// gy * fv with (fu, fv) uvd's place in that texel. Stack maps take one receiver depth.
float st_shadow_uvd_plane(uint w, vec3 uvd, vec2 slope, float footprint, uint kernel, inout StProbe probe) {
  if (kernel < 1u || kernel > 9u || (kernel & 1u) == 0u) return uintBitsToFloat(0x7FC00000u);
  if (!st_in_light_box(uvd)) return 1.0;
  const uint finest = st_finest_level();
  const float side = uintBitsToFloat((127u + finest) << 23u);
  precise float su = uvd.x * side, sv = uvd.y * side;
  precise float fu = floor(su), fv = floor(sv);
  const uint x = min(uint(fu), (1u << finest) - 1u), y = min(uint(fv), (1u << finest) - 1u);
  if (ST_PAGE(kPtStack) != 0u) return st_stack_lookup(x, y, w, uvd.z, footprint, kernel, probe);
  precise float in_u = su - fu, in_v = sv - fv;
  precise float du = slope.x * in_u, dv = slope.y * in_v;
  precise float corner_u = uvd.z - du;
  precise float corner = corner_u - dv;
  return st_lookup_plane(x, y, vec3(corner, slope.x, slope.y), footprint, kernel, probe);
}

// Visibility at a world position (2D maps; on a stack map slice 0): the receiver offset
// along the normal, the map's light, the footprint given. 1 where the map has no light.
float st_visibility(vec3 world_position, vec3 normal, float normal_offset, float footprint, uint kernel,
                    inout StProbe probe) {
  const uint lb = st_light_block(0u);
  if (lb == 0u) return 1.0;
  return st_shadow_uvd(0u, st_light_uvd(lb, st_receiver(world_position, normal, normal_offset)), footprint, kernel,
                       probe);
}

// The deep part's transmittance per channel at a world position (the surface point, no
// normal offset: st_deep_shadow); 1 for a map without a deep part, a stack map, or with
// ST_DEEP_SHADOWS 0. An absent deep tile is fed back and marks the probe's hole.
vec3 st_transmittance(vec3 world_position, float footprint, uint kernel, inout StProbe probe) {
#if ST_DEEP_SHADOWS
  const uint lb = st_light_block(0u);
  if (lb == 0u || ST_PAGE(kPtStack) != 0u || ST_PAGE(kPtDeep) == 0u) return vec3(1.0);
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
// sample's time) blended va + f * (vb - va), each in its own light with the same footprint.
float st_shadow_stack(vec3 world_position, vec3 normal, float normal_offset, float footprint, uint kernel, uint a,
                      uint b, float f, inout StProbe probe) {
  const vec3 r = st_receiver(world_position, normal, normal_offset);
  const float va = st_shadow_uvd(a, st_light_uvd(st_light_block(a), r), footprint, kernel, probe);
  if (a == b) return va;
  const float vb = st_shadow_uvd(b, st_light_uvd(st_light_block(b), r), footprint, kernel, probe);
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

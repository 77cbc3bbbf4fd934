#version 450
// The example renderer's fragment shader: Lambert shading with streamed shadows, the
// light (visibility x the partial occluders' transmittance, per channel) from the GPU
// tile cache through shadowtile.glsl (our buffers in set 0), the level pair from the pixel's footprint (or the finest level), 3x3 PCF; absent tiles
// answer coarsely and are fed back, so the next frames stream them.
#define ST_SET 0
#define ST_BINDING_POOL 0
#define ST_BINDING_PAGE 1
#define ST_BINDING_FEEDBACK 2
#include "shadowtile.glsl"

layout(location = 0) in vec3 world_position;
layout(location = 1) in vec3 world_normal;
layout(push_constant) uniform Push {
  mat4 view_projection;
  vec4 to_sun;  // w: one finest texel in world units
  vec4 eye;  // xyz: the camera; w: the pixel angle (radians), 0: the finest level
} push;
layout(location = 0) out vec4 colour;

void main() {
  vec3 n = normalize(world_normal);
  if (dot(n, push.eye.xyz - world_position) < 0.0) n = -n;  // the side the camera sees
  const uint finest = st_finest_level();
  // eye.w > 0: the pixel's angle; the level pair from the footprint (MH §3.3, as
  // Map::pcf_footprint), measured as the CPU renderer does (tiles/bake/render.cpp): the
  // pixel's size at the receiver in finest texels. The light-space derivatives
  // (st_footprint_of with uvd + dFdx(uvd)) overestimate it at grazing angles: coarser
  // levels, speckled shadows. eye.w == 0: the finest level.
  const float footprint = push.eye.w != 0.0 ? distance(push.eye.xyz, world_position) * push.eye.w / push.to_sun.w : 1.0;
  // The receiver's offset along the normal, as the CPU renderer's (tiles/bake/render.hpp):
  // 1.5 texels plus the PCF radius, in texels of the finer level filtered (a kernel of
  // coarse texels needs a coarse texel's bias, or sloped surfaces shadow themselves).
  const StFilter level = st_filter_levels(footprint, finest);
  const float offset = 2.5 * push.to_sun.w * float(1u << (finest - level.fine));
  const float lambert = max(dot(n, push.to_sun.xyz), 0.0);
  StProbe probe = st_probe();
  // The light per channel: the visibility times the partial occluders' transmittance.
  const vec3 light = lambert > 0.0 ? st_shadow(world_position, n, offset, footprint, 3u, probe) : vec3(0.0);
  st_finish(probe);
  const vec3 albedo = vec3(0.78, 0.74, 0.68);
  const vec3 c = albedo * (0.22 + 0.78 * lambert * light);
  colour = vec4(pow(c, vec3(1.0 / 2.2)), 1.0);
}

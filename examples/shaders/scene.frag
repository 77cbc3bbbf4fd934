#version 450
// The example renderer's fragment shader: Lambert shading with streamed shadows, the
// visibility from the GPU tile cache through shadowtile.glsl (our buffers in set 0), the
// footprint from the light-space derivatives (or the finest level), 3x3 PCF; absent tiles
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
  vec4 eye;  // xyz: the camera; w: 1 = level from the footprint
} push;
layout(location = 0) out vec4 colour;

void main() {
  vec3 n = normalize(world_normal);
  if (dot(n, push.eye.xyz - world_position) < 0.0) n = -n;  // the side the camera sees
  const uint lb = st_light_block(0u);
  const uint finest = st_finest_level();
  const vec3 uvd = st_light_uvd(lb, world_position);
  const float side = float(1u << finest);
  // eye.w: 1 picks the level pair from the footprint (MH §3.3, as Map::pcf_footprint);
  // 0 filters the finest level.
  const float footprint = push.eye.w != 0.0
      ? max(max(abs(dFdx(uvd.x)), abs(dFdx(uvd.y))), max(abs(dFdy(uvd.x)), abs(dFdy(uvd.y)))) * side
      : 1.0;
  // The receiver's offset along the normal, as the CPU renderer's (tiles/bake/render.hpp):
  // 1.5 texels plus the PCF radius, in texels of the finer level filtered (a kernel of
  // coarse texels needs a coarse texel's bias, or sloped surfaces shadow themselves).
  const StFilter level = st_filter_levels(footprint, finest);
  const float offset = 2.5 * push.to_sun.w * float(1u << (finest - level.fine));
  const float lambert = max(dot(n, push.to_sun.xyz), 0.0);
  StProbe probe = st_probe();
  const float vis = lambert > 0.0 ? st_shadow(world_position, n, offset, footprint, 3u, probe) : 0.0;
  st_finish(probe);
  const vec3 albedo = vec3(0.78, 0.74, 0.68);
  const vec3 c = albedo * (0.22 + 0.78 * lambert * vis);
  colour = vec4(pow(c, vec3(1.0 / 2.2)), 1.0);
}

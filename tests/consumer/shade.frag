#version 450
// An engine's fragment shader over the installed GPU tile cache: its buffers in set 2,
// feedback on; visibility at the fragment's world position, 3x3 PCF.
#define ST_SET 2
#define ST_BINDING_POOL 0
#define ST_BINDING_PAGE 1
#define ST_BINDING_FEEDBACK 2
#include "shadowtile.glsl"

layout(location = 0) in vec3 world_position;
layout(location = 1) in vec3 world_normal;
layout(location = 0) out vec4 colour;

void main() {
  StProbe probe = st_probe();
  const vec3 uvd = st_light_uvd(st_light_block(0u), st_receiver(world_position, world_normal, 0.01));
  const float side = float(1u << st_finest_level());
  const float footprint = max(length(dFdx(uvd.xy)), length(dFdy(uvd.xy))) * side;
  const float v = st_visibility(world_position, world_normal, 0.01, footprint, 3u, probe);
  st_finish(probe);
  colour = vec4(vec3(0.2 + 0.8 * v), 1.0);
}

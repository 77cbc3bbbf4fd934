#version 450
// The example renderer's vertex shader: world-space triangles, one normal per corner.
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(push_constant) uniform Push {
  mat4 view_projection;
  vec4 to_sun;  // xyz: direction to the sun; w: normal offset (world units)
  vec4 eye;     // xyz: the camera
} push;
layout(location = 0) out vec3 world_position;
layout(location = 1) out vec3 world_normal;

void main() {
  world_position = position;
  world_normal = normal;
  gl_Position = push.view_projection * vec4(position, 1.0);
}

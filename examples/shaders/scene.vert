#version 450
// The example renderer's vertex shader: world-space triangles, one normal per corner. The
// position is invariant: the depth pre-pass and the shading pass (depth test EQUAL) must
// compute the same depths.
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(push_constant) uniform Push {
  mat4 view_projection;
  vec4 light;  // scene.frag's
  vec4 eye;
  uvec4 mode;
  vec4 misc;
} push;
layout(location = 0) out vec3 world_position;
layout(location = 1) out vec3 world_normal;
invariant gl_Position;

void main() {
  world_position = position;
  world_normal = normal;
  gl_Position = push.view_projection * vec4(position, 1.0);
}

#version 450
// The example renderer's vertex shader: world-space triangles, one normal per corner. The
// depth pre-pass and the shading pass (depth test EQUAL) run this same module and must
// compute the same depths: the product is `precise` (no contraction or reassociation).
// (`invariant gl_Position` says the same, but Mesa's SPIR-V reader warns on the decoration
// glslang puts on the gl_PerVertex member.)
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

void main() {
  world_position = position;
  world_normal = normal;
  precise vec4 clip = push.view_projection * vec4(position, 1.0);
  gl_Position = clip;
}

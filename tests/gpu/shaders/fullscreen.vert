#version 450
// One triangle over the whole viewport (the fragment-shader test's draw).
void main() {
  const vec2 p = vec2(float((gl_VertexIndex << 1) & 2), float(gl_VertexIndex & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}

// Analytic scenes of the render tests: closed boxes (outward winding) and the cube on a
// ground slab whose shadow edges are known.
#pragma once

#include <string>

#include "scene/scene.hpp"

namespace st::render_test {

// A closed axis-aligned box as one mesh named `mesh` (outward winding).
inline void add_box(Scene& s, const std::string& mesh, Vec3d lo, Vec3d hi) {
  const uint32_t base = uint32_t(s.vertices.size());
  for (int i = 0; i < 8; ++i)
    s.vertices.push_back({(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z});
  const uint32_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  Mesh m;
  m.name = mesh;
  m.first_triangle = uint32_t(s.triangles.size());
  for (const auto& q : quads) {
    s.triangles.push_back({base + q[0], base + q[1], base + q[2]});
    s.triangles.push_back({base + q[0], base + q[2], base + q[3]});
  }
  m.triangle_count = 12;
  m.closed = true;
  s.meshes.push_back(m);
}

// A 4 x 4 x 4 cube standing on a 20 x 20 slab one unit thick.
inline Scene cube_on_slab() {
  Scene s;
  s.name = "cube-on-slab";
  add_box(s, "slab", {-10, -1, -10}, {10, 0, 10});
  add_box(s, "cube", {-2, 0, -2}, {2, 4, 2});
  return s;
}

}  // namespace st::render_test

// Turning one raw triangle list (from assimp or a procedural generator) into an st::Mesh
// of a Scene: the single place where validity, welding, degenerate removal, closedness
// and orientation are decided, so file and procedural scenes obey the same rules.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "scene/scene.hpp"

namespace st {

using Triangle = std::array<uint32_t, 3>;

// One mesh as produced by a source: vertices in world space (double), triangles indexing
// them. Vertices may be duplicated (split by normals/UVs).
struct MeshSoup {
  std::string name;
  std::vector<Vec3d> vertices;
  std::vector<Triangle> triangles;
  // Partial occluders (partial.hpp), copied onto the st::Mesh: per-channel transmittance,
  // the alpha texture's index in the scene, and texture coordinates per triangle corner
  // (empty, or one entry per triangle; they follow the triangles through step 3).
  Rgb transmit{0, 0, 0};
  int32_t alpha_texture = -1;
  std::vector<std::array<Vec2f, 3>> uv{};
};

// Appends `mesh` to `scene` as one st::Mesh, in this order:
//   1. every index must be < vertices.size() and every vertex referenced by a triangle
//      finite, else st::Error naming the mesh and the scene (`scene.name`);
//   2. vertices are welded by exact position (-0.0 == +0.0), per mesh only;
//   3. triangles with repeated indices or a zero cross product (computed in double) are
//      dropped and counted in scene.stats.degenerate_dropped;
//   4. closed = is_closed_surface(...) on the welded triangles;
//   5. a closed mesh with negative signed_volume has all triangles reversed
//      (scene.stats.meshes_flipped).
// Scene::triangle_uv is kept one entry per triangle once any mesh brings UVs (meshes
// without UVs get zeros). Only referenced vertices are kept. Throws st::Error if the scene would exceed 2^32-1
// vertices or triangles. A mesh left with no triangle is still appended (count 0).
void append_mesh(Scene& scene, MeshSoup mesh);

// True iff every undirected edge is used by exactly two triangles, once in each
// direction (a consistently wound 2-manifold-at-edges surface, possibly of several
// components). An empty list is not closed. Triangles must have distinct indices.
bool is_closed_surface(const std::vector<Triangle>& triangles);

// Signed volume enclosed by the triangles (divergence theorem, sum of tetrahedra against
// the mean vertex, so huge offsets do not cancel the result); positive when a closed
// surface faces outwards.
double signed_volume(const std::vector<Vec3d>& vertices, const std::vector<Triangle>& triangles);

// Signed volume of scene.meshes[mesh_index] inside a whole scene.
double mesh_signed_volume(const Scene& scene, size_t mesh_index);

}  // namespace st

// Scenes: one triangle soup with per-mesh flags, loaded from any format assimp reads or
// built procedurally ("procedural:NAME[,key=value...]"). World is right-handed, +Y up.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "tiles/core/vec.hpp"

namespace st {

struct Mesh {
  std::string name;
  uint32_t first_triangle = 0;  // triangles [first_triangle, first_triangle + triangle_count)
  uint32_t triangle_count = 0;
  // Closed: every edge is shared by exactly two faces with opposite winding, detected
  // from the mesh itself (never trusted from the file). Closed meshes are oriented
  // outwards (flipped at load if their signed volume is negative).
  bool closed = false;
};

struct SceneStats {
  uint64_t degenerate_dropped = 0;  // zero-area / repeated-index triangles removed at load
  uint64_t meshes_flipped = 0;      // closed meshes whose winding was turned outwards
};

struct Scene {
  std::string name;                            // the spec or file name it came from
  std::vector<Vec3d> vertices;                 // world space, double
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<Mesh> meshes;                    // partition the triangles, in order
  SceneStats stats;

  Aabb bounds() const;
  size_t closed_triangle_count() const;
  bool any_closed() const;
  // Stable 64-bit hash of the geometry (for pack headers).
  uint64_t content_hash() const;
};

enum class UpAxis { y, z };

struct SceneOptions {
  UpAxis up = UpAxis::y;  // Z-up sources are turned to Y-up on load
};

// Loads "procedural:NAME[,k=v...]" or a file path. Throws st::Error with a one-line
// message naming the file / mesh / parameter at fault: missing file, unknown format,
// NaN or Inf vertices, assimp validation failures, unknown procedural name or key.
Scene load_scene(const std::string& spec, const SceneOptions& options = {});

// Procedural scenes (deterministic): cube, sphere, city, terrain, hairball. `params`
// are the key=value pairs after the name.
Scene make_procedural(const std::string& spec);

}  // namespace st

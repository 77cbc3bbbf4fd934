// Scenes: one triangle soup with per-mesh flags, loaded from any format assimp reads or
// built procedurally ("procedural:NAME[,key=value...]"). World is right-handed, +Y up.
#pragma once
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "scene/partial.hpp"
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
  // Partial occluders (partial.hpp): the fraction of light let through at each crossing,
  // per channel; {0, 0, 0} is opaque (the default).
  Rgb transmit{0, 0, 0};
  int32_t alpha_texture = -1;  // index into Scene::alpha_textures; -1: none
  // A partial mesh is left out of the opaque map and carried by deep tiles.
  bool partial() const { return alpha_texture >= 0 || transmit != Rgb{0, 0, 0}; }
};

struct SceneStats {
  uint64_t degenerate_dropped = 0;  // zero-area / repeated-index triangles removed at load
  uint64_t meshes_flipped = 0;      // closed meshes whose winding was turned outwards
};

enum class UpAxis { y, z };

struct Scene {
  std::string name;                            // the spec or file name it came from
  std::vector<Vec3d> vertices;                 // world space, double
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<Mesh> meshes;                    // partition the triangles, in order
  // Texture coordinates per triangle corner: empty, or one entry per triangle when some
  // mesh is alpha-tested.
  std::vector<std::array<Vec2f, 3>> triangle_uv;
  std::vector<AlphaTexture> alpha_textures;
  std::vector<Volume> volumes;
  SceneStats stats;
  // Files: the source axis that was turned to +Y (up_axis_text() says which and why);
  // up_reason empty for procedural scenes, which are generated +Y up.
  UpAxis up = UpAxis::y;
  std::string up_reason;
  // Files whose unit was applied (FBX's UnitScaleFactor): the scale and where it came
  // from; empty where the coordinates are the file's as they are.
  std::string unit_reason;

  Aabb bounds() const;
  size_t closed_triangle_count() const;
  bool any_closed() const;
  // Whether any mesh is partial or any volume is present (a deep map is needed).
  bool any_partial() const;
  // Stable 64-bit hash of the geometry (for pack headers).
  uint64_t content_hash() const;
};

struct SceneOptions {
  // The source's up axis, turned to +Y on load. Unset: the file's own, where it is fixed
  // or recorded (Quake 3 maps: Z; FBX: the UpAxis / UpAxisSign metadata assimp exposes;
  // COLLADA: <up_axis>, applied by assimp), else Y. Set: overrides what the file says
  // (COLLADA's <up_axis> is then ignored too).
  std::optional<UpAxis> up;
};

// "z (from the file's metadata)", "y (given)", ...: the axis a file scene was read with
// and why; "y" for procedural scenes.
std::string up_axis_text(const Scene& scene);

// The CLIs' --up: "" (unset: the file's own axis), "y" or "z"; anything else throws
// st::Error naming the option.
std::optional<UpAxis> parse_up_axis(const std::string& text);

// Loads "procedural:NAME[,k=v...]" or a file path. Throws st::Error with a one-line
// message naming the file / mesh / parameter at fault: missing file, unknown format,
// NaN or Inf vertices, assimp validation failures, unknown procedural name or key.
// Files: one st::Mesh per mesh instance (node transforms applied in double, named after
// the mesh, else the node), triangulated, points and lines dropped, vertices welded by
// exact position per mesh, degenerate triangles dropped (counted), closed meshes turned
// outwards (counted). options.up applies to files only (procedural scenes are +Y up);
// Scene::up and up_reason record the axis used. Quake 3 maps (.bsp, .pk3,
// "ARCHIVE.pk3:maps/NAME.bsp") are read by our own checked parser, not assimp
// (scene_quake3.hpp); they are Z-up, so they load upright without options.up.
Scene load_scene(const std::string& spec, const SceneOptions& options = {});

// Procedural scenes (deterministic: splitmix64, same spec -> same content_hash()).
// Spec: "procedural:NAME[,key=value...]" (the prefix is optional here). Common keys:
// scale (default 1) then ox, oy, oz (default 0): v' = v * scale + (ox, oy, oz), in double.
//   cube     size=1             axis-aligned [-size/2, size/2]^3, 12 triangles, closed
//   sphere   radius=1 segments=32
//            closed UV sphere: stacks = max(2, segments / 2); vertices are the poles
//            (0, +-radius, 0) and, for j = 1..stacks-1, i = 0..segments-1,
//            radius * (sin t cos p, cos t, sin t sin p) with t = pi j / stacks,
//            p = 2 pi i / segments; quads between neighbouring rings split along the
//            diagonal from (j+1, i) to (j, i+1); 2 segments (stacks - 1) triangles
//   plane    size=10            open quad at y = 0 facing +Y, 2 triangles
//   boxes    (none)             box_a and box_b intersect; inner is nested in outer
//   city     seed=1 size=14 block=60   closed buildings on a closed ground slab
//   terrain  seed=1 size=256 extent=1000 height=150   closed solid heightfield
//   hairball seed=1 count=256 segments=96 sides=6 transmit=0
//            closed thin tubes, one mesh each; transmit > 0: semi-transparent hair
//   forest   seed=1 trees=9 leaves=300 size=30 translucency=0
//            trunks (closed boxes) on a ground quad, and per tree one mesh of leaf cards
//            alpha-tested through a procedural leaf texture; translucency > 0 lets
//            (0.3, 1, 0.2) x translucency of the light through a solid leaf (coloured)
//   smoke    seed=1 res=32 size=10 density=1 sigma=1
//            a ground quad under a density-grid plume of res^3 voxels (Volume)
//   soup     seed=1 count=2500 size=400  one open mesh, dup/sliver/overlap faces; bad names/keys throw
Scene make_procedural(const std::string& spec);

// The scene without its partial meshes and volumes (what the opaque map is built from);
// the scene itself when it has none.
Scene opaque_part(const Scene& scene);

// One paragraph for CLIs: triangles, vertices, meshes, closed meshes and triangles,
// dropped degenerates, flipped meshes and the bounds.
std::string summary(const Scene& scene);

}  // namespace st

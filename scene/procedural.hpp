// Building blocks of the procedural scenes (internal to scene/): a portable PRNG, the
// key=value parameter reader and closed-solid generators. Every generator writes
// outward-facing, consistently wound solids whose shared edges use shared vertex indices,
// so append_mesh() finds them closed without relying on welding.
//
// Orientation convention: polygons are given in the (x, z) plane, counter-clockwise in the
// (x, z) plane (positive shoelace area with x first, z second); seen from +Y that is
// clockwise because the world is right-handed with +Y up.
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "common/hash.hpp"
#include "scene/scene_mesh.hpp"

namespace st::procedural {

// The seeded generator of procedural scenes: common/hash.hpp (same output everywhere).
using st::Rng;

// The key=value pairs of one spec. Each generator asks for every key it knows (with a
// default and a valid range) and then calls finish(), which rejects keys nobody asked for.
class Params {
 public:
  // `spec` is "procedural:NAME,k=v,..." or "NAME,k=v,..."; throws st::Error on syntax
  // errors or duplicated keys.
  explicit Params(const std::string& spec);
  const std::string& scene_name() const { return name_; }
  double real(const std::string& key, double fallback, double lo, double hi);
  int64_t integer(const std::string& key, int64_t fallback, int64_t lo, int64_t hi);
  void finish() const;

 private:
  [[noreturn]] void fail(const std::string& what) const;
  std::string spec_, name_;
  std::map<std::string, std::string> values_;
  std::vector<std::string> asked_;
};

struct Vec2 {
  double x = 0, z = 0;
};

// Appends a vertex and returns its index.
uint32_t add_vertex(MeshSoup& m, const Vec3d& p);
// Quad a-b-c-d (counter-clockwise when seen from its front) as two triangles.
void add_quad(MeshSoup& m, uint32_t a, uint32_t b, uint32_t c, uint32_t d);

// Axis-aligned box [lo, hi], 8 vertices, 12 triangles, outwards.
void add_box(MeshSoup& m, const Vec3d& lo, const Vec3d& hi);

// Axis-aligned box whose faces are regular grids of n[0] x n[1] x n[2] cells (shared
// vertices along the box edges, so it stays closed): 4 (n0 n1 + n1 n2 + n0 n2) triangles.
void add_grid_box(MeshSoup& m, const Vec3d& lo, const Vec3d& hi, int nx, int ny, int nz);

// One horizontal ring of a loft: a polygon (counter-clockwise in (x, z)) at height y.
struct Ring {
  std::vector<Vec2> points;
  double y = 0;
};

// A solid swept through `rings` (all with the same vertex count, vertex i of one ring
// joined to vertex i of the next; heights non-decreasing; two rings at the same height
// make a horizontal step: a setback roof). Bottom and top caps are fans from `centre`,
// which must see the whole polygon (star-shaped) and lie on no edge line. Closed.
void add_loft(MeshSoup& m, const std::vector<Ring>& rings, Vec2 centre);

// A ring building with a courtyard: outer polygon minus inner polygon (same vertex count,
// inner vertex i "facing" outer vertex i, both counter-clockwise), from y0 to y1, walls
// split into `floors` bands. Closed surface of genus 1.
void add_courtyard(MeshSoup& m, const std::vector<Vec2>& outer, const std::vector<Vec2>& inner,
                   double y0, double y1, int floors);

// Subdivides edge i of a polygon (from point i to point i+1) into counts[i] equal parts
// (collinear points added). Rings subdivided with the same counts stay loftable.
std::vector<Vec2> subdivide(const std::vector<Vec2>& polygon, const std::vector<int>& counts);
// Per-edge counts giving parts of about `spacing` (at least 1 per edge).
std::vector<int> edge_counts(const std::vector<Vec2>& polygon, double spacing);

// A closed tube of `sides`-gon cross-section along `path` (>= 2 points), with flat caps
// (fans from the end points). Rotation-minimising frames (parallel transport).
void add_tube(MeshSoup& m, const std::vector<Vec3d>& path, double radius, int sides);

// UV sphere (see make_procedural's comment for the exact vertex formula).
void add_uv_sphere(MeshSoup& m, const Vec3d& centre, double radius, int segments);

// Scene generators: each reads its own keys from `p`, calls p.finish(), then generates
// (the caller applies the common scale/offset keys before append_mesh).
std::vector<MeshSoup> make_city(Params& p);
std::vector<MeshSoup> make_terrain(Params& p);
std::vector<MeshSoup> make_hairball(Params& p);
// Open geometry with duplicate, sliver and overlapping faces (procedural_soup.cpp).
std::vector<MeshSoup> make_soup(Params& p);

// What a scene of partial occluders holds besides meshes (procedural_partial.cpp); the
// caller applies scale and offset to volume bounds too.
struct PartialExtras {
  std::vector<AlphaTexture> textures;
  std::vector<Volume> volumes;
};
std::vector<MeshSoup> make_forest(Params& p, PartialExtras& extras);
std::vector<MeshSoup> make_smoke(Params& p, PartialExtras& extras);

}  // namespace st::procedural

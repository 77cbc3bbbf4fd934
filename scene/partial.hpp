// Partial occluders (deep shadow maps, Lokovic and Veach 2000): what a scene holds besides
// opaque triangles. A mesh may let part of the light through at each crossing (coloured
// transmittance), be alpha-tested through a texture, and the scene may hold volumes of
// participating media (density grids) whose extinction is ray-marched.
//
// The opaque depth map never sees any of this: partial meshes are left out of the
// opaque part of a scene (opaque_part()), and their effect on light is carried by deep
// tiles. A scene without partial meshes and volumes is exactly what it was before.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "tiles/core/vec.hpp"

namespace st {

using Rgb = std::array<float, 3>;

struct Vec2f {
  float u = 0, v = 0;
  constexpr bool operator==(const Vec2f&) const = default;
};

// An alpha map, 8 bits per texel, row 0 at v = 0. A surface point whose alpha is at least
// `cutoff` blocks the light (its mesh's transmit applies); below it the light passes.
struct AlphaTexture {
  std::string name;  // the file it came from, or a procedural name
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> alpha;  // width * height, row-major
  float cutoff = 0.5f;

  // Nearest texel, coordinates wrapped (repeat) into [0, 1). Non-finite -> not solid.
  // Requires validate() to have passed.
  bool solid(float u, float v) const;
  // Throws st::Error naming the texture when it is empty, its size disagrees with
  // width * height, or the cutoff is not in [0, 1].
  void validate() const;
};

// A participating medium on a regular grid over `bounds` (world space): the density at
// voxel centres, trilinear in between, zero outside. Extinction per unit length is
// density * sigma (per channel).
struct Volume {
  std::string name;
  Aabb bounds;
  uint32_t nx = 0, ny = 0, nz = 0;
  std::vector<float> density;  // nx * ny * nz, x fastest; finite, >= 0
  Rgb sigma{1, 1, 1};

  float density_at(const Vec3d& world) const;  // trilinear, 0 outside the bounds
  // The optical depth tau = integral of extinction from `origin + t0 dir` to
  // `origin + t1 dir`, per channel, marched in steps of at most half a voxel (midpoint
  // rule); `dir` need not be unit length (tau is per unit of t along it).
  Rgb optical_depth(const Vec3d& origin, const Vec3d& dir, double t0, double t1) const;
  // The ray's steps through the grid: (t, tau accumulated from t0 up to t), from t0 to
  // t1, at most half a voxel apart and at least one entry at each end of the part of
  // [t0, t1] inside the bounds; empty when the ray misses the bounds. Ray-marching a
  // visibility function reads these.
  struct Step {
    double t;
    Rgb tau;
  };
  void march(const Vec3d& origin, const Vec3d& dir, double t0, double t1,
             std::vector<Step>& out) const;
  // Throws st::Error naming the volume when sizes disagree or a density is not finite
  // or negative, or the bounds are empty.
  void validate() const;
};

}  // namespace st

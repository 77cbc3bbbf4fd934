// The canonical depth of a texel: one definition that every producer of depth bounds
// follows, so that (lo, hi) of a texel is a function of (scene, light, level, x, y) alone
// and never of how the texel was batched (packet width, region shape or alignment,
// single rays, `verify`, a later rasterizer or GPU builder). The lossless invariant has
// no epsilon, and on open geometry (hi = lo) one ulp of disagreement between the build
// and a re-trace is a violation, so the depths cannot be a ray tracer's float t, whose
// last bits depend on the SIMD kernel that happened to run.
//
// Definition (ARCHITECTURE.md "Definitions" points here):
//   1. Primitives. Which triangles a texel ray hits is the canonical coverage of
//      canonical_coverage.hpp (signed Plücker edge tests in double); every builder (the
//      Embree tracer, the light-space rasterizer) evaluates it, so none depends on a
//      float triangle test.
//   2. Plane. Each triangle's plane is computed in double from its three scene
//      vertices, recentred on the scene AABB centre (p - centre, double), taken in
//      lexicographic (x, y, z) order: n = (b - a) x (c - a), d = n . a. A duplicate,
//      a flipped or a re-indexed copy of a triangle therefore has the bit-identical
//      plane.
//   3. Parameter. t = (d - n . o) / (n . dir) in double, with o = ray origin - centre
//      and dir the texel ray's direction (LightSpace::texel_ray, double). A ray in the
//      plane (n . dir == 0) or a non-finite quotient is no hit.
//   4. Selection. lo takes the smallest t of the hit list, hi the t where the exit
//      counting of canonical_interval() ends (canonical_coverage.hpp).
//   5. Depth. Sun: d = t; spot (and windowed spot): d = (t - near) / (far - near), in double, clamped to
//      [0, 1], rounded to float once. hi = max(lo, hi).
// Tests pin bit-identity across batchings on open soups, terrain, coplanar overlaps,
// grazing and steep suns and spot lights, and between the two builders.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>

#include "tiles/core/light.hpp"
#include "tiles/core/vec.hpp"

namespace st {

struct CanonicalPlane {
  Vec3d n;       // (b - a) x (c - a) of the lexicographically ordered vertices
  double d = 0;  // n . a

  // From the three vertices of a triangle, already recentred (p - centre, in double).
  static CanonicalPlane of(Vec3d a, Vec3d b, Vec3d c) {
    auto less = [](const Vec3d& p, const Vec3d& q) {
      if (p.x != q.x) return p.x < q.x;
      if (p.y != q.y) return p.y < q.y;
      return p.z < q.z;
    };
    if (less(b, a)) std::swap(a, b);
    if (less(c, b)) std::swap(b, c);
    if (less(b, a)) std::swap(a, b);
    CanonicalPlane p;
    p.n = cross(b - a, c - a);
    p.d = dot(p.n, a);
    return p;
  }

  // The ray parameter of the plane; `fallback` (NaN for the definition: no hit) when the
  // ray lies in the plane or the quotient is not finite.
  double t(const Vec3d& origin, const Vec3d& dir, double fallback) const {
    const double den = dot(n, dir);
    const double t = (d - dot(n, origin)) / den;
    return den != 0 && std::isfinite(t) ? t : fallback;
  }
};

// Step 5 of the definition.
inline float canonical_depth(const LightSpace& light, double t) {
  const double d = light.parallel()
                       ? t
                       : (t - light.near_plane()) / (light.far_plane() - light.near_plane());
  return float(std::clamp(d, 0.0, 1.0));
}

}  // namespace st

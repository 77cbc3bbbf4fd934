// Scenes with the hazards real assets have, built in code: open triangle soups, duplicate
// triangles (also re-indexed and flipped), T-junctions, slivers, flipped faces, meshes
// that intersect each other, a mesh closed except for one missing triangle, nearly
// coplanar overlapping faces, open terrain, a rotated and scaled mesh far from the origin,
// and the procedural city with every building open (what a merged real town is).
#pragma once
#include <cmath>
#include <string>
#include <vector>

#include "common/hash.hpp"
#include "scene/scene.hpp"
#include "tiles/core/vec.hpp"

namespace st::test {

class HazardBuilder {
 public:
  explicit HazardBuilder(std::string name) { s_.name = std::move(name); }

  // Starts a new mesh; triangles added until the next call belong to it.
  void mesh(const std::string& name, bool closed = false) {
    Mesh m;
    m.name = name;
    m.first_triangle = uint32_t(s_.triangles.size());
    m.closed = closed;
    s_.meshes.push_back(m);
  }
  uint32_t v(const Vec3d& p) {
    s_.vertices.push_back(xf(p));
    return uint32_t(s_.vertices.size() - 1);
  }
  void tri(uint32_t a, uint32_t b, uint32_t c) {
    s_.triangles.push_back({a, b, c});
    ++s_.meshes.back().triangle_count;
  }
  void tri(const Vec3d& a, const Vec3d& b, const Vec3d& c) { tri(v(a), v(b), v(c)); }
  void quad(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& d) {
    const uint32_t ia = v(a), ib = v(b), ic = v(c), id = v(d);
    tri(ia, ib, ic), tri(ia, ic, id);
  }
  // A transform applied to every later vertex: rotation about Y then X, scale, offset.
  void transform(double yaw, double pitch, double scale, Vec3d offset) {
    yaw_ = yaw, pitch_ = pitch, scale_ = scale, offset_ = offset;
  }
  Scene take() { return std::move(s_); }

 private:
  Vec3d xf(Vec3d p) const {
    const double cy = std::cos(yaw_), sy = std::sin(yaw_), cp = std::cos(pitch_),
                 sp = std::sin(pitch_);
    p = {cy * p.x + sy * p.z, p.y, -sy * p.x + cy * p.z};
    p = {p.x, cp * p.y - sp * p.z, sp * p.y + cp * p.z};
    return p * scale_ + offset_;
  }
  Scene s_;
  double yaw_ = 0, pitch_ = 0, scale_ = 1;
  Vec3d offset_{};
};

// `n` random triangles in [0, 1]^3, sizes from slivers to a third of the box, random
// winding.
inline void add_soup(HazardBuilder& b, uint64_t seed, uint32_t n, Vec3d at, double size) {
  uint64_t rng = seed;
  b.mesh("soup");
  for (uint32_t k = 0; k < n; ++k) {
    const Vec3d c{unit_random(rng), unit_random(rng), unit_random(rng)};
    const double r = 0.02 + 0.3 * unit_random(rng) * unit_random(rng);
    auto p = [&] { return at + (c + Vec3d{unit_random(rng) - 0.5, unit_random(rng) - 0.5, unit_random(rng) - 0.5} * r) * size; };
    const Vec3d a = p(), bb = p(), cc = p();
    b.tri(a, bb, cc);
  }
}

// An open height field of n x n quads over [x0, x0 + size]^2 (y up).
inline void add_heightfield(HazardBuilder& b, const std::string& name, uint32_t n, Vec3d at,
                            double size, double amplitude, uint64_t seed) {
  b.mesh(name);
  std::vector<uint32_t> id((n + 1) * (n + 1));
  uint64_t rng = seed;
  const double f1 = 3 + 4 * unit_random(rng), f2 = 2 + 5 * unit_random(rng);
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) {
      const double x = double(i) / n, z = double(j) / n;
      const double h = amplitude * (std::sin(f1 * x + 1.3 * z) * std::cos(f2 * z - 0.7 * x));
      id[j * (n + 1) + i] = b.v(at + Vec3d{x * size, h * size, z * size});
    }
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) {
      const uint32_t a = id[j * (n + 1) + i], c = id[(j + 1) * (n + 1) + i + 1];
      const uint32_t bq = id[j * (n + 1) + i + 1], d = id[(j + 1) * (n + 1) + i];
      b.tri(a, d, c), b.tri(a, c, bq);
    }
}

// One scene holding every hazard side by side on an open ground slab of [0, 8] x [0, 8].
inline Scene hazard_town(uint64_t seed = 7) {
  HazardBuilder b("hazards");
  // The open ground: two big triangles.
  b.mesh("ground");
  b.quad({0, 0, 0}, {0, 0, 8}, {8, 0, 8}, {8, 0, 0});
  // Duplicate triangles: a roof made twice, the copy re-indexed, rotated and flipped.
  b.mesh("duplicates");
  for (int k = 0; k < 2; ++k) {
    const Vec3d p0{0.5, 1.0, 0.5}, p1{2.0, 1.6, 0.5}, p2{2.0, 1.6, 2.0}, p3{0.5, 1.0, 2.0};
    if (k == 0) b.quad(p0, p1, p2, p3);
    else b.tri(p2, p1, p0), b.tri(p3, p2, p0);
  }
  // T-junctions: a row of small quads meets one long edge of a big triangle strip.
  b.mesh("t_junctions");
  for (int i = 0; i < 6; ++i)
    b.quad({3.0 + 0.25 * i, 0.8, 0.5}, {3.0 + 0.25 * i, 0.8, 1.0}, {3.25 + 0.25 * i, 0.8, 1.0},
           {3.25 + 0.25 * i, 0.8, 0.5});
  b.quad({3.0, 0.8, 1.0}, {3.0, 1.1, 2.0}, {4.5, 1.1, 2.0}, {4.5, 0.8, 1.0});
  // Slivers: a fan of long needle triangles.
  b.mesh("slivers");
  for (int i = 0; i < 40; ++i) {
    const double a = 0.01 * i;
    b.tri({5.5, 0.5, 0.5}, {7.5, 0.5 + 0.8 * a, 0.5 + a}, {7.5, 0.5 + 0.8 * a, 0.5 + a + 1e-4});
  }
  // Flipped faces: an open box whose faces alternate winding.
  b.mesh("flipped");
  {
    const Vec3d lo{0.5, 0, 3}, hi{1.8, 1.4, 4.3};
    const Vec3d c[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {lo.x, hi.y, lo.z}, {hi.x, hi.y, lo.z},
                        {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {lo.x, hi.y, hi.z}, {hi.x, hi.y, hi.z}};
    const int f[5][4] = {{2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (int k = 0; k < 5; ++k) {
      if (k % 2) b.quad(c[f[k][3]], c[f[k][2]], c[f[k][1]], c[f[k][0]]);
      else b.quad(c[f[k][0]], c[f[k][1]], c[f[k][2]], c[f[k][3]]);
    }
  }
  // Meshes that intersect each other: two tilted plates crossing, and a plate through
  // the flipped box.
  b.mesh("cross_a");
  b.quad({2.5, 0.2, 3.0}, {2.5, 1.5, 4.5}, {4.5, 1.5, 4.5}, {4.5, 0.2, 3.0});
  b.mesh("cross_b");
  b.quad({2.5, 1.5, 3.0}, {2.5, 0.2, 4.5}, {4.5, 0.2, 4.5}, {4.5, 1.5, 3.0});
  b.mesh("through_box");
  b.quad({0.2, 0.7, 2.8}, {0.2, 0.9, 4.6}, {2.1, 0.9, 4.6}, {2.1, 0.7, 2.8});
  // Closed except for one missing triangle: a UV sphere minus one facet (open, as the
  // loader's edge check would mark it).
  b.mesh("sphere_missing_one");
  {
    constexpr double kPi = 3.14159265358979323846;
    const Vec3d c{6.0, 1.0, 3.7};
    const double r = 0.9;
    const int slices = 20, stacks = 10;
    std::vector<uint32_t> id;
    const uint32_t top = b.v(c + Vec3d{0, r, 0}), bottom = b.v(c - Vec3d{0, r, 0});
    for (int i = 1; i < stacks; ++i)
      for (int j = 0; j < slices; ++j) {
        const double th = kPi * i / stacks, ph = 2 * kPi * j / slices;
        id.push_back(b.v(c + Vec3d{r * std::sin(th) * std::cos(ph), r * std::cos(th),
                                   r * std::sin(th) * std::sin(ph)}));
      }
    auto ring = [&](int i, int j) { return id[(i - 1) * slices + j % slices]; };
    int k = 0;
    for (int j = 0; j < slices; ++j) {
      b.tri(top, ring(1, j + 1), ring(1, j));
      b.tri(bottom, ring(stacks - 1, j), ring(stacks - 1, j + 1));
      for (int i = 1; i + 1 < stacks; ++i) {
        if (k++ != 37) b.tri(ring(i, j), ring(i, j + 1), ring(i + 1, j + 1));
        b.tri(ring(i, j), ring(i + 1, j + 1), ring(i + 1, j));
      }
    }
  }
  // Nearly coplanar overlapping faces: decals a hair above, at and tilted through a plate.
  b.mesh("coplanar");
  b.quad({0.5, 0.3, 5.5}, {0.5, 0.3, 7.5}, {2.5, 0.3, 7.5}, {2.5, 0.3, 5.5});
  b.quad({1.0, 0.3 + 1e-7, 6.0}, {1.0, 0.3 + 1e-7, 7.0}, {2.0, 0.3 + 1e-7, 7.0}, {2.0, 0.3 + 1e-7, 6.0});
  b.quad({0.7, 0.3, 5.7}, {0.7, 0.3, 6.6}, {2.2, 0.3, 6.6}, {2.2, 0.3, 5.7});
  b.quad({0.6, 0.3 - 1e-6, 5.6}, {0.6, 0.3 + 1e-6, 7.4}, {2.4, 0.3 + 1e-6, 7.4}, {2.4, 0.3 - 1e-6, 5.6});
  // A random open soup, and open terrain, rotated and scaled.
  add_soup(b, seed, 300, {3.0, 0.1, 5.3}, 2.2);
  add_heightfield(b, "terrain", 24, {5.3, 0.05, 5.3}, 2.4, 0.08, seed + 1);
  return b.take();
}

// An open rotated and scaled terrain, far from the origin.
inline Scene rotated_terrain(uint64_t seed = 11) {
  HazardBuilder b("rotated_terrain");
  b.transform(0.7, 0.15, 1375.0, {1.0e5, -3.0e4, 2.5e5});
  add_heightfield(b, "terrain", 48, {0, 0, 0}, 1.0, 0.12, seed);
  add_soup(b, seed + 2, 200, {0.1, 0.05, 0.1}, 0.8);
  return b.take();
}

// A scene's meshes all marked open (what a merged real-asset mesh is).
inline Scene all_open(Scene s) {
  for (Mesh& m : s.meshes) m.closed = false;
  return s;
}

}  // namespace st::test

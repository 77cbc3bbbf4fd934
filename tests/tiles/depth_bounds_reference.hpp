// Test helpers for the depth-bounds tracer: hand-built scenes (boxes, spheres, planes)
// and an independent double-precision reference tracer (every triangle, every texel).
#pragma once
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "scene/scene.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"

namespace st::test {

inline bool small_scale() {
  const char* s = std::getenv("SHADOWTILE_TEST_SCALE");
  return s && std::strcmp(s, "small") == 0;
}

// Appends a mesh; triangles of convex shapes are oriented away from `inside` so that
// closed meshes face outwards like the scene loader guarantees.
inline void add_mesh(Scene& s, const std::string& name, const std::vector<Vec3d>& verts,
                     std::vector<std::array<uint32_t, 3>> tris, bool closed,
                     const Vec3d* inside = nullptr, bool invert = false) {
  const uint32_t base = uint32_t(s.vertices.size());
  s.vertices.insert(s.vertices.end(), verts.begin(), verts.end());
  Mesh m;
  m.name = name;
  m.first_triangle = uint32_t(s.triangles.size());
  m.triangle_count = uint32_t(tris.size());
  m.closed = closed;
  for (auto t : tris) {
    if (inside) {
      Vec3d a = verts[t[0]], b = verts[t[1]], c = verts[t[2]];
      Vec3d centroid = (a + b + c) / 3.0;
      bool outward = dot(cross(b - a, c - a), centroid - *inside) > 0;
      if (outward == invert) std::swap(t[1], t[2]);
    }
    s.triangles.push_back({base + t[0], base + t[1], base + t[2]});
  }
  s.meshes.push_back(m);
}

inline void add_box(Scene& s, Vec3d lo, Vec3d hi, bool closed = true, bool invert = false) {
  std::vector<Vec3d> v;
  for (int i = 0; i < 8; ++i)
    v.push_back({(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z});
  std::vector<std::array<uint32_t, 3>> t = {
      {0, 1, 3}, {0, 3, 2}, {4, 7, 5}, {4, 6, 7},  // z = lo, z = hi
      {0, 4, 5}, {0, 5, 1}, {2, 3, 7}, {2, 7, 6},  // y = lo, y = hi
      {0, 2, 6}, {0, 6, 4}, {1, 5, 7}, {1, 7, 3}};  // x = lo, x = hi
  Vec3d c = (lo + hi) * 0.5;
  add_mesh(s, "box", v, t, closed, &c, invert);
}

// UV sphere with shared poles and seam: a watertight closed mesh.
inline void add_sphere(Scene& s, Vec3d c, double r, uint32_t slices = 24, uint32_t stacks = 12) {
  constexpr double kPi = 3.14159265358979323846;
  std::vector<Vec3d> v{c + Vec3d{0, r, 0}, c - Vec3d{0, r, 0}};
  for (uint32_t i = 1; i < stacks; ++i) {
    double th = kPi * i / stacks;
    for (uint32_t j = 0; j < slices; ++j) {
      double ph = 2 * kPi * j / slices;
      v.push_back(c + Vec3d{r * std::sin(th) * std::cos(ph), r * std::cos(th),
                            r * std::sin(th) * std::sin(ph)});
    }
  }
  auto ring = [&](uint32_t i, uint32_t j) { return 2 + (i - 1) * slices + j % slices; };
  std::vector<std::array<uint32_t, 3>> t;
  for (uint32_t j = 0; j < slices; ++j) {
    t.push_back({0, ring(1, j), ring(1, j + 1)});
    t.push_back({1, ring(stacks - 1, j + 1), ring(stacks - 1, j)});
    for (uint32_t i = 1; i + 1 < stacks; ++i) {
      t.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      t.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  }
  add_mesh(s, "sphere", v, t, true, &c);
}

// A horizontal open quad at height y (one-sided geometry: hi = lo).
inline void add_plane(Scene& s, double y, double half) {
  std::vector<Vec3d> v{{-half, y, -half}, {half, y, -half}, {half, y, half}, {-half, y, half}};
  add_mesh(s, "plane", v, {{0, 2, 1}, {0, 3, 2}}, false);
}

inline Scene transformed(const Scene& s, double scale, Vec3d offset) {
  Scene out = s;
  for (auto& v : out.vertices) v = v * scale + offset;
  return out;
}

// Reference interval of one ray in double: all hits with barycentric slack `eps` (> 0
// fattens triangles, < 0 shrinks them), grouped by equal t (within 1e-12), counted per
// closed mesh like the tracer. Depth is the ray parameter mapped by the light.
struct RefResult {
  bool hit = false;
  double lo = 1, hi = 1;
  double lo_cos = 1, hi_cos = 1;  // |cos| between ray and surface at lo / hi
};

inline RefResult reference_ray(const Scene& s, const LightSpace& light, const LightRay& ray,
                               double eps) {
  struct Hit {
    double t;
    uint32_t mesh;
    int facing;
    bool closed;
    double cos;
  };
  std::vector<uint32_t> tri_mesh(s.triangles.size());
  for (uint32_t m = 0; m < s.meshes.size(); ++m)
    for (uint32_t i = 0; i < s.meshes[m].triangle_count; ++i)
      tri_mesh[s.meshes[m].first_triangle + i] = m;
  const bool sun = light.kind() == LightKind::sun;
  const double t0 = sun ? 0 : light.near_plane(), t1 = sun ? 1 : light.far_plane();
  std::vector<Hit> hits;
  for (size_t k = 0; k < s.triangles.size(); ++k) {
    const auto& tr = s.triangles[k];
    Vec3d a = s.vertices[tr[0]], b = s.vertices[tr[1]], c = s.vertices[tr[2]];
    Vec3d e1 = b - a, e2 = c - a, p = cross(ray.dir, e2);
    double det = dot(e1, p);
    if (det == 0) continue;
    Vec3d q = ray.origin - a;
    double u = dot(q, p) / det;
    Vec3d qq = cross(q, e1);
    double v = dot(ray.dir, qq) / det;
    double t = dot(e2, qq) / det;
    if (u < -eps || v < -eps || u + v > 1 + eps || t < t0 || t > t1) continue;
    Vec3d n = cross(e1, e2);
    double f = dot(n, ray.dir);
    double cs = std::fabs(f) / (length(n) * length(ray.dir));
    hits.push_back({t, tri_mesh[k], f < 0 ? 1 : (f > 0 ? -1 : 0),
                    s.meshes[tri_mesh[k]].closed, cs});
  }
  RefResult r;
  if (hits.empty()) return r;
  std::sort(hits.begin(), hits.end(), [](auto& x, auto& y) { return x.t < y.t; });
  auto depth = [&](double t) { return sun ? t : (t - light.near_plane()) /
                                                     (light.far_plane() - light.near_plane()); };
  r.hit = true;
  r.lo = r.hi = depth(hits[0].t);
  r.lo_cos = r.hi_cos = hits[0].cos;
  std::vector<int> count(s.meshes.size(), 0);
  int total = 0;
  bool first = true;
  for (size_t i = 0; i < hits.size();) {
    size_t j = i;
    std::vector<int> sum(s.meshes.size(), 0);
    bool any_closed = false;
    while (j < hits.size() && hits[j].t - hits[i].t <= 1e-12 * (1 + std::fabs(hits[i].t))) {
      if (hits[j].closed) sum[hits[j].mesh] += hits[j].facing, any_closed = true;
      ++j;
    }
    if (first && !any_closed) return r;  // open first hit
    for (size_t m = 0; m < sum.size(); ++m) {
      int net = std::clamp(sum[m], -1, 1);
      count[m] += net, total += net;
      if (count[m] < 0) return r;  // untrusted: hi = lo
    }
    if (total == 0) {
      if (!first) r.hi = depth(hits[i].t), r.hi_cos = hits[i].cos;
      return r;
    }
    first = false;
    i = j;
  }
  return r;  // left the scene inside: hi = lo
}

inline constexpr double kUlp = 1.0 / (1 << 24);  // the float grid just below 1.0

struct CompareResult {
  uint64_t compared = 0, skipped = 0, closed = 0, failures = 0;
};

// Compares every texel with the reference: texels whose reference changes when the
// triangles are fattened or shrunk by 1e-7 (rays through silhouettes) are skipped.
// Tolerance: `ulps` float steps of [0,1), divided by |cos| of the incidence.
// `stride` > 1 checks a pseudo-random subset of about 1/stride of the texels (big scenes).
inline CompareResult compare_with_reference(const Scene& s, const LightSpace& light,
                                            const IntervalTile& tile, double ulps = 16,
                                            uint32_t stride = 1) {
  CompareResult c;
  uint64_t pick = 0x9e3779b97f4a7c15ull;
  for (uint32_t j = 0; j < tile.height; ++j)
    for (uint32_t i = 0; i < tile.width; ++i) {
      if (stride > 1) {
        pick = pick * 6364136223846793005ull + 1442695040888963407ull;
        if ((pick >> 33) % stride != 0) continue;
      }
      const Interval iv = tile.at(i, j);
      EXPECT_LE(iv.lo, iv.hi) << "texel " << i << "," << j;
      LightRay ray = light.texel_ray(tile.level, tile.x0 + i, tile.y0 + j);
      auto fat = reference_ray(s, light, ray, 1e-7), thin = reference_ray(s, light, ray, -1e-7);
      if (fat.hit != thin.hit || std::fabs(fat.lo - thin.lo) > 1e-9 ||
          std::fabs(fat.hi - thin.hi) > 1e-9) {
        ++c.skipped;
        continue;
      }
      auto ref = reference_ray(s, light, ray, 0);
      ++c.compared;
      bool ok;
      if (!ref.hit) {
        ok = iv.lo == kLitDepth && iv.hi == kLitDepth;
      } else {
        double tol_lo = ulps * kUlp / std::max(ref.lo_cos, 1e-3);
        double tol_hi = ulps * kUlp / std::max(ref.hi_cos, 1e-3);
        ok = std::fabs(iv.lo - ref.lo) <= tol_lo && std::fabs(iv.hi - ref.hi) <= tol_hi;
        c.closed += ref.hi > ref.lo;
      }
      if (!ok && ++c.failures <= 5)
        ADD_FAILURE() << "texel " << tile.x0 + i << "," << tile.y0 + j << " level "
                      << tile.level << ": traced [" << iv.lo << ", " << iv.hi
                      << "] reference [" << ref.lo << ", " << ref.hi << "] hit " << ref.hit;
    }
  EXPECT_EQ(c.failures, 0u);
  // Ambiguous texels lie along silhouettes: a small share unless the map is tiny.
  EXPECT_LT(c.skipped, c.compared / 4 + 4) << "too many ambiguous texels";
  return c;
}

}  // namespace st::test

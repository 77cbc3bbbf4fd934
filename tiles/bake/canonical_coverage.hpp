// Canonical coverage and the canonical hit list of a texel ray: which triangles a texel
// ray hits, decided in double by a function of (recentred triangle vertices, ray) alone,
// so that a tracer and a light-space rasterizer that evaluate it on the same texels agree
// bit for bit (MH §3.1: the bounds a builder must reproduce).
//
// Coverage (signed Plücker edge tests):
//   For an edge between p and q, taken in lexicographic (x, y, z) order (p < q), its value
//   on the ray (o, d) is e = d . ((p - o) x (q - o)) in double. A triangle that walks the
//   edge q -> p uses -e; the shared edge of two triangles therefore gives exactly negated
//   values. A zero value is resolved by symbolic perturbation of the ray origin along
//   g1 then g2 (two fixed directions derived from d alone: g1 = d x axis of d's smallest
//   component, g2 = d x g1): the sign of de/dg = d . (g x (p - q)). An edge whose three
//   signs are all zero (it projects to a point) rejects the triangle. The triangle is hit
//   when its three oriented signs are equal; that common sign is the facing: negative
//   (d . n < 0 with n the triangle's own winding normal) is entering. A point on a shared
//   edge or vertex of a consistently wound closed mesh is covered by exactly one of the
//   triangles facing the ray (watertight, never twice).
//
// Hit list: every covered triangle with its canonical t (canonical_depth.hpp, plane t in
// double; a ray in the plane is never covered) and facing, sorted by (t, triangle index).
// canonical_interval() is the pure function of that list that gives (lo, hi): lo = first
// t; hi by exit counting per closed mesh on groups of exactly equal t (exit_depth.hpp's
// rules): front +1, back -1, a mesh contributes the sign of its group sum; open hits
// while inside are ignored; the counters at 0 end the run unless the next group lies
// within kTouchDouble of the t range and enters a closed mesh (touching faces). Fallbacks
// to hi = lo: a counter goes negative, or the list ends with a counter > 0. A first hit
// that is open gives hi = lo.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include "tiles/bake/canonical_depth.hpp"
#include "tiles/bake/exit_depth.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/vec.hpp"

namespace st {

namespace canonical_detail {
inline bool lex_less(const Vec3d& p, const Vec3d& q) {
  if (p.x != q.x) return p.x < q.x;
  if (p.y != q.y) return p.y < q.y;
  return p.z < q.z;
}
inline int sgn(double v) { return (v > 0) - (v < 0); }
}  // namespace canonical_detail

namespace canonical_detail {
inline Vec3d abs3(const Vec3d& v) { return {std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)}; }
// |x| x |y| with every product's magnitude added: bounds each component of x' x y' for
// |x'| <= |x|, |y'| <= |y| componentwise.
inline Vec3d cross_abs(const Vec3d& x, const Vec3d& y) {
  return {x.y * y.z + x.z * y.y, x.z * y.x + x.x * y.z, x.x * y.y + x.y * y.x};
}
}  // namespace canonical_detail

// The directed edge a -> b of a triangle on a ray of origin o and a fixed direction d (a
// sun): d . ((a - o) x (b - o)) = d . (a x b) + o . ((a - b) x d) = c + o . n exactly.
// `bound` covers both the rounding of this fast form (value()) and that of the
// definition's own double evaluation (canonical_edge_sign) for every origin with
// |o| <= o_max componentwise, so a fast value beyond +-bound has the definition's sign;
// within it the definition decides.
struct CanonicalEdgeFast {
  double c, nx, ny, nz, bound;

  static CanonicalEdgeFast of(const Vec3d& a, const Vec3d& b, const Vec3d& d, const Vec3d& o_max) {
    using canonical_detail::abs3;
    using canonical_detail::cross_abs;
    CanonicalEdgeFast e;
    e.c = dot(d, cross(a, b));
    const Vec3d n = cross(a - b, d);
    e.nx = n.x, e.ny = n.y, e.nz = n.z;
    const Vec3d A = abs3(a), B = abs3(b), D = abs3(d);
    const double m_c = dot(D, cross_abs(A, B));                    // terms of c
    const double m_n = dot(o_max, cross_abs(A + B, D));            // terms of o . n
    const double m_def = dot(D, cross_abs(A + o_max, B + o_max));  // terms of the definition
    // Each form is a sum of triple products after at most 8 roundings (about 8u and 7u
    // of its terms); 64u leaves room for the rounding of the bound itself. The absolute
    // term covers underflow; an overflowing bound is +inf (the definition always decides).
    e.bound = 0x1p-47 * (m_c + m_n + m_def) + 0x1p-1000;
    return e;
  }
  double value(const Vec3d& o) const { return c + (o.x * nx + o.y * ny + o.z * nz); }
  // +1 or -1: the definition's sign; 0: within the bound (the definition decides).
  int sure_sign(const Vec3d& o) const {
    const double v = value(o);
    return v > bound ? 1 : (v < -bound ? -1 : 0);
  }
};

// The perturbation directions of a ray: a function of d alone.
struct CoverageRay {
  Vec3d o, d, g1, g2;
  static CoverageRay of(const Vec3d& origin, const Vec3d& dir) {
    CoverageRay r;
    r.o = origin;
    r.d = dir;
    const double ax = std::fabs(dir.x), ay = std::fabs(dir.y), az = std::fabs(dir.z);
    Vec3d axis{0, 0, 0};
    if (ax <= ay && ax <= az) axis.x = 1;
    else if (ay <= az) axis.y = 1;
    else axis.z = 1;
    r.g1 = cross(dir, axis);
    r.g2 = cross(dir, r.g1);
    return r;
  }
};

// Sign of the edge (a -> b) on the ray, resolved to +-1, or 0 when it projects to a point.
inline int canonical_edge_sign(const CoverageRay& r, const Vec3d& a, const Vec3d& b) {
  using namespace canonical_detail;
  const bool fwd = lex_less(a, b);
  const Vec3d& p = fwd ? a : b;
  const Vec3d& q = fwd ? b : a;
  int s = sgn(dot(r.d, cross(p - r.o, q - r.o)));
  if (s == 0) s = sgn(dot(r.d, cross(r.g1, p - q)));
  if (s == 0) s = sgn(dot(r.d, cross(r.g2, p - q)));
  return fwd ? s : -s;
}

// 0: not covered; -1: covered, entering (front face); +1: covered, leaving (back face).
inline int canonical_cover(const CoverageRay& r, const Vec3d& a, const Vec3d& b,
                           const Vec3d& c) {
  const int s0 = canonical_edge_sign(r, a, b);
  if (s0 == 0) return 0;
  const int s1 = canonical_edge_sign(r, b, c);
  if (s1 != s0) return 0;
  const int s2 = canonical_edge_sign(r, c, a);
  return s2 == s0 ? s0 : 0;
}

struct CanonicalHit {
  double t;
  uint32_t tri;   // triangle index in the scene
  uint32_t mesh;  // mesh index
  int8_t facing;  // -1 entering, +1 leaving (winding of the triangle)
  bool closed;
  bool operator<(const CanonicalHit& o) const { return t != o.t ? t < o.t : tri < o.tri; }
};

struct CanonicalResult {
  double lo_t = INFINITY, hi_t = INFINITY;  // INFINITY: no hit
  bool fell_back = false;
};

namespace canonical_detail {
// (mesh, count) pairs in insertion order, inline up to kInline entries and on the heap
// beyond: canonical_interval() allocates nothing for the common handful of meshes per ray.
// Past kInline, a hash index finds a mesh in O(1): a ray through m coincident or stacked
// closed meshes then costs O(m), not O(m^2) (5,000 coincident closed meshes took 187 s
// for a 128^2 map with a linear search).
class MeshCounts {
 public:
  struct Entry {
    uint32_t first;  // mesh
    int32_t second;  // count
  };
  static constexpr size_t kInline = 16;
  void clear() {
    if (n_ > kInline) heap_.clear(), index_.clear();
    n_ = 0;
  }
  Entry* begin() { return n_ <= kInline ? inline_ : heap_.data(); }
  Entry* end() { return begin() + n_; }
  Entry* find(uint32_t mesh) {
    if (n_ > kInline) {
      const auto it = index_.find(mesh);
      return it == index_.end() ? nullptr : heap_.data() + it->second;
    }
    Entry* e = std::find_if(begin(), end(), [&](const Entry& c) { return c.first == mesh; });
    return e == end() ? nullptr : e;
  }
  Entry* add(uint32_t mesh, int32_t count) {
    if (n_ < kInline) {
      inline_[n_] = Entry{mesh, count};
    } else {
      if (n_ == kInline) {
        heap_.assign(inline_, inline_ + kInline);
        for (size_t k = 0; k < kInline; ++k) index_.emplace(inline_[k].first, uint32_t(k));
      }
      index_.emplace(mesh, uint32_t(heap_.size()));
      heap_.push_back(Entry{mesh, count});
    }
    ++n_;
    return end() - 1;
  }

 private:
  Entry inline_[kInline];  // the first n_ are set (not initialised beyond: no per-call cost)
  std::vector<Entry> heap_;
  std::unordered_map<uint32_t, uint32_t> index_;  // mesh -> position in heap_, past kInline
  size_t n_ = 0;
};
}  // namespace canonical_detail

// (lo, hi) of a hit list sorted by (t, tri); `range` is the ray's t range (t_max - t_min).
inline CanonicalResult canonical_interval(const CanonicalHit* hits, size_t n, double range) {
  CanonicalResult r;
  if (n == 0) return r;
  r.lo_t = r.hi_t = hits[0].t;
  if (!hits[0].closed) return r;
  const double touch = ExitDepthRay::kTouchDouble * range;
  canonical_detail::MeshCounts counters, group;  // counters: mesh -> count
  int32_t total = 0;
  size_t i = 0;
  bool entered = false;
  while (i < n) {
    size_t j = i;
    while (j < n && hits[j].t == hits[i].t) ++j;
    // Per mesh: the sign of the sum of its closed facings in this group (entering +1).
    group.clear();
    for (size_t k = i; k < j; ++k) {
      if (!hits[k].closed) continue;
      if (auto* g = group.find(hits[k].mesh)) g->second -= hits[k].facing;
      else group.add(hits[k].mesh, -hits[k].facing);
    }
    if (entered && total == 0) {
      // Counters at 0 after group ending at hits[i-1]: go on only through a touching face.
      bool enters = false;
      for (const auto& g : group) enters |= g.second > 0;
      if (!(enters && hits[i].t - r.hi_t <= touch)) return r;
    }
    for (const auto& g : group) {
      const int32_t s = (g.second > 0) - (g.second < 0);
      if (s == 0) continue;
      auto* c = counters.find(g.first);
      if (!c) c = counters.add(g.first, 0);
      c->second += s;
      total += s;
      if (c->second < 0) {
        r.hi_t = r.lo_t;
        r.fell_back = true;
        return r;
      }
    }
    if (!entered) {
      if (total == 0) return r;  // a grazing touch or a silhouette: hi = lo
      entered = true;
    }
    if (total == 0) r.hi_t = hits[i].t;
    i = j;
  }
  if (total != 0) {
    r.hi_t = r.lo_t;
    r.fell_back = true;
  }
  return r;
}

inline CanonicalResult canonical_interval(const std::vector<CanonicalHit>& hits, double range) {
  return canonical_interval(hits.data(), hits.size(), range);
}

inline Interval canonical_depths(const LightSpace& light, const CanonicalResult& r) {
  if (!(r.lo_t < INFINITY)) return Interval{kLitDepth, kLitDepth};
  Interval iv;
  iv.lo = canonical_depth(light, r.lo_t);
  iv.hi = std::max(iv.lo, canonical_depth(light, r.hi_t));
  return iv;
}

}  // namespace st

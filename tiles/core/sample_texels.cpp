// Batched light-space transforms (sample_texels.hpp). Every lane repeats, operation for
// operation, LightSpace::to_light (light.cpp) and LightSpace::texel_of: dot(r, a) is
// (r.x a.x + r.y a.y) + r.z a.z, divisions are divisions (no reciprocals), and the floor
// and clamp of texel_of become two compares and a truncation. Built with
// -ffp-contract=off like light.cpp (tiles/CMakeLists.txt), so neither side fuses.
#include "tiles/core/sample_texels.hpp"

#include <algorithm>
#include <cassert>
#include <cstring>

namespace st {
namespace {

// Two lanes: one SSE2 or NEON register.
typedef double V2d __attribute__((vector_size(16)));
typedef int64_t V2l __attribute__((vector_size(16)));
typedef int32_t V2i __attribute__((vector_size(8)));
typedef float V2f __attribute__((vector_size(8)));

inline V2d load2(const double* p) {
  V2d v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

// Lane-wise m ? a : b for a compare's mask m (all ones or zero).
inline V2d select2(V2l m, V2d a, V2d b) { return (V2d)(((V2l)a & m) | ((V2l)b & ~m)); }

// texel_of's cell for two coordinates: floor(c * R) clamped to [0, R - 1], NaN to 0
// (R = 2^level is exact, c * R too; truncation is the floor on [0, R)).
inline V2i cells2(V2d c, V2d r, V2d r_last) {
  const V2d x = c * r;
  V2d t = select2(x >= r, r_last, x);
  t = select2(x >= 0.0, t, V2d{0.0, 0.0});
  return __builtin_convertvector(t, V2i);
}

inline void store2(uint32_t* dst, V2i v) { std::memcpy(dst, &v, sizeof v); }
inline void store2(float* dst, V2f v) { std::memcpy(dst, &v, sizeof v); }

}  // namespace

SampleTexels::SampleTexels(const std::vector<LightSpace>& samples, uint32_t level)
    : samples_(samples), count_(uint32_t(samples.size())), level_(level) {
  assert(level <= kMaxLevel);
  if (samples.empty()) return;
  const LightSpace& a = samples[0];
  bool one_kind = true, shared_ground = a.kind() == LightKind::sun_ground;
  for (const LightSpace& s : samples) {
    one_kind = one_kind && s.kind() == a.kind();
    shared_ground = shared_ground && s.kind() == LightKind::sun_ground && s.origin() == a.origin() &&
                    s.axis_u() == a.axis_u() && s.axis_v() == a.axis_v() && s.depth_axis() == a.depth_axis() &&
                    s.extent_uv() == a.extent_uv() && s.near_plane() == a.near_plane() &&
                    s.far_plane() == a.far_plane();
  }
  if (shared_ground) {
    path_ = Path::ground_shared;
  } else if (one_kind && a.kind() == LightKind::sun) {
    path_ = Path::sun;
  } else if (one_kind && a.kind() == LightKind::spot) {
    path_ = Path::spot;
  } else if (one_kind && a.kind() == LightKind::spot_window) {
    path_ = Path::spot_window;
  } else {
    return;  // scalar
  }
  // One pad sample (a copy of the last): an odd run's second lane reads it.
  for (uint32_t w = 0; w <= count_; ++w) {
    const LightSpace& s = samples[std::min(w, count_ - 1)];
    const Vec3d o = s.origin(), u = s.axis_u(), v = s.axis_v(), f = s.depth_axis();
    ox_.push_back(o.x), oy_.push_back(o.y), oz_.push_back(o.z);
    ux_.push_back(u.x), uy_.push_back(u.y), uz_.push_back(u.z);
    vx_.push_back(v.x), vy_.push_back(v.y), vz_.push_back(v.z);
    fx_.push_back(f.x), fy_.push_back(f.y), fz_.push_back(f.z);
    ext_.push_back(s.extent_uv()), near_.push_back(s.near_plane());
    span_.push_back(s.far_plane() - s.near_plane());
    if (s.kind() == LightKind::sun_ground) {
      // As LightSpace::derive_ground's k_u, k_v (ray_axis() is its ray_axis_).
      c0_.push_back(dot(s.ray_axis(), u)), c1_.push_back(dot(s.ray_axis(), v));
    } else {
      const auto c = s.window_shift();
      c0_.push_back(c[0]), c1_.push_back(c[1]);
    }
  }
}

void SampleTexels::texel(const Vec3d& p, uint32_t w, uint32_t& x, uint32_t& y, float& d) const noexcept {
  const LightPoint lp = samples_[w].to_light(p);
  const auto t = LightSpace::texel_of(level_, lp.u, lp.v);
  x = uint32_t(t[0]), y = uint32_t(t[1]), d = float(lp.d);
}

void SampleTexels::run(const Vec3d& p, uint32_t w0, uint32_t n, Run& out) const noexcept {
  assert(n <= kRun && w0 + n <= count_);
  if (path_ == Path::scalar) {
    for (uint32_t i = 0; i < n; ++i) texel(p, w0 + i, out.x[i], out.y[i], out.d[i]);
    return;
  }
  const double rr = double(uint64_t(1) << level_);
  const V2d r{rr, rr}, r_last{rr - 1, rr - 1};
  if (path_ == Path::ground_shared) {
    // to_light_ground with the frame's one origin and axes: r, z and the offsets along the
    // axes once; per sample (ru - k_u z) / extent.
    const Vec3d rv = p - Vec3d{ox_[0], oy_[0], oz_[0]};
    const double z = dot(rv, Vec3d{fx_[0], fy_[0], fz_[0]});
    const double ru = dot(rv, Vec3d{ux_[0], uy_[0], uz_[0]}), rw = dot(rv, Vec3d{vx_[0], vy_[0], vz_[0]});
    const float d = float((z - near_[0]) / span_[0]);
    const V2d z2{z, z}, ru2{ru, ru}, rw2{rw, rw};
    for (uint32_t i = 0; i < n; i += 2) {
      const uint32_t w = w0 + i;
      const V2d e = load2(&ext_[w]);
      store2(out.x + i, cells2((ru2 - load2(&c0_[w]) * z2) / e, r, r_last));
      store2(out.y + i, cells2((rw2 - load2(&c1_[w]) * z2) / e, r, r_last));
      out.d[i] = out.d[i + 1] = d;
    }
    return;
  }
  const V2d px{p.x, p.x}, py{p.y, p.y}, pz{p.z, p.z}, half{0.5, 0.5};
  for (uint32_t i = 0; i < n; i += 2) {
    const uint32_t w = w0 + i;
    const V2d rx = px - load2(&ox_[w]), ry = py - load2(&oy_[w]), rz = pz - load2(&oz_[w]);
    const V2d du = rx * load2(&ux_[w]) + ry * load2(&uy_[w]) + rz * load2(&uz_[w]);
    const V2d dv = rx * load2(&vx_[w]) + ry * load2(&vy_[w]) + rz * load2(&vz_[w]);
    const V2d z = rx * load2(&fx_[w]) + ry * load2(&fy_[w]) + rz * load2(&fz_[w]);
    const V2d e = load2(&ext_[w]);
    V2d u, v;
    if (path_ == Path::sun) {
      u = du / e, v = dv / e;
    } else if (path_ == Path::spot) {
      const V2d ze = z * e;
      u = du / ze + half, v = dv / ze + half;
    } else {  // spot_window: the sheared image plane
      u = (du / z - load2(&c0_[w])) / e + half, v = (dv / z - load2(&c1_[w])) / e + half;
    }
    store2(out.x + i, cells2(u, r, r_last));
    store2(out.y + i, cells2(v, r, r_last));
    store2(out.d + i, __builtin_convertvector((z - load2(&near_[w])) / load2(&span_[w]), V2f));
  }
}

}  // namespace st

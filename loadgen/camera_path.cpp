#include "loadgen/camera_path.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st::loadgen {


namespace {

double percentile(std::vector<double>& v, double p) {
  size_t i = std::min(v.size() - 1, size_t(p * double(v.size())));
  std::nth_element(v.begin(), v.begin() + long(i), v.end());
  return v[i];
}

}  // namespace

WorldFrame world_frame(const PackHeader& header, const CutGrid& grid) {
  WorldFrame w;
  w.light = LightSpace::from_array(header.light_kind, header.light);
  const uint32_t k = grid.levels;
  const uint64_t side = uint64_t(1) << k;
  std::vector<double> xs, ys, zs;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const float v = grid.entry(x, y).value;
      if (!(v < kLitDepth) || !(v >= 0)) continue;  // no hit: nothing there
      const LightRay r = w.light.texel_ray(k, x, y);
      // Inverse of LightSpace::depth_of_t (sun: d = t; spot: linear between near/far).
      const double t = w.light.parallel()
                           ? double(v)
                           : w.light.near_plane() + double(v) * (w.light.far_plane() - w.light.near_plane());
      const Vec3d p = r.origin + r.dir * t;
      xs.push_back(p.x);
      ys.push_back(p.y);
      zs.push_back(p.z);
    }
  if (xs.size() < 4) {
    // Nothing hit at level K: the light box itself (its lowest corner is the ground).
    const Vec3d o = w.light.origin(), a = w.light.axis_u() * w.light.extent_uv(),
                b = w.light.axis_v() * w.light.extent_uv();
    Aabb box;
    for (int i = 0; i < 4; ++i) box.extend(o + a * double(i & 1) + b * double(i >> 1));
    w.ground = box.lo.y;
    w.top = box.lo.y + 0.1 * std::max(box.extent().x, box.extent().z);
    w.x0 = box.lo.x, w.x1 = box.hi.x, w.z0 = box.lo.z, w.z1 = box.hi.z;
    return w;
  }
  w.x0 = percentile(xs, 0.01), w.x1 = percentile(xs, 0.99);
  w.z0 = percentile(zs, 0.01), w.z1 = percentile(zs, 0.99);
  w.ground = percentile(ys, 0.05);
  w.top = std::max(percentile(ys, 0.98), w.ground + 1e-3 * std::max(w.span(), 1e-9));
  if (!(w.x1 > w.x0)) w.x1 = w.x0 + 1;
  if (!(w.z1 > w.z0)) w.z1 = w.z0 + 1;
  return w;
}

PathKind parse_path(const std::string& name) {
  if (name == "flyover") return PathKind::flyover;
  if (name == "orbit") return PathKind::orbit;
  if (name == "walk") return PathKind::walk;
  if (name == "teleport") return PathKind::teleport;
  throw Error("--path: expected flyover, orbit, walk or teleport, got '" + name + "'");
}

std::string to_string(PathKind k) {
  switch (k) {
    case PathKind::flyover: return "flyover";
    case PathKind::orbit: return "orbit";
    case PathKind::walk: return "walk";
    case PathKind::teleport: return "teleport";
  }
  return "?";
}

CameraPath::CameraPath(PathKind kind, const WorldFrame& world, uint64_t seed, uint32_t camera_index)
    : kind_(kind), w_(world), seed_(seed * 0x100000001B3ull + camera_index) {
  uint64_t s = seed_;
  for (double& p : phase_) p = unit_random(s) * 2 * M_PI;
}

uint64_t CameraPath::segment(double t) const {
  return kind_ == PathKind::teleport ? uint64_t(std::max(0.0, t) / kTeleportSeconds) : 0;
}

Camera CameraPath::at(double t) const {
  const double span = w_.span(), height = w_.top - w_.ground;
  const double cx = (w_.x0 + w_.x1) / 2, cz = (w_.z0 + w_.z1) / 2;
  const double ax = 0.42 * (w_.x1 - w_.x0), az = 0.42 * (w_.z1 - w_.z0);
  Camera c;
  // A Lissajous sweep with periods chosen so the camera crosses the footprint in about
  // `cross` seconds; its heading follows the velocity.
  auto lissajous = [&](double cross, double tt, double alt, double pitch_deg) {
    const double w1 = M_PI / cross, w2 = w1 * 0.77;
    Vec3d p{cx + ax * std::sin(w1 * tt + phase_[0]), alt, cz + az * std::sin(w2 * tt + phase_[1])};
    Vec3d v{ax * w1 * std::cos(w1 * tt + phase_[0]), 0, az * w2 * std::cos(w2 * tt + phase_[1])};
    if (length(v) < 1e-12) v = {1, 0, 0};
    v = normalize(v);
    const double pitch = pitch_deg * M_PI / 180;
    c.pos = p;
    c.target = p + Vec3d{v.x * std::cos(pitch), -std::sin(pitch), v.z * std::cos(pitch)} * (0.1 * span);
  };
  switch (kind_) {
    case PathKind::flyover:
      lissajous(40, t, w_.top + std::max(0.5 * height, 0.02 * span), 30);
      break;
    case PathKind::walk:
      lissajous(400, t, w_.ground + std::max(0.004 * span, 0.05 * height), 4);
      break;
    case PathKind::orbit: {
      const double r = 0.3 * span, a = phase_[2] + 2 * M_PI * t / 30.0;
      const Vec3d centre{cx + 0.1 * ax * std::sin(phase_[3]), w_.ground, cz + 0.1 * az * std::cos(phase_[3])};
      c.pos = centre + Vec3d{r * std::cos(a), w_.top - w_.ground + 0.15 * span, r * std::sin(a)};
      c.target = centre;
      break;
    }
    case PathKind::teleport: {
      const uint64_t seg = segment(t);
      uint64_t s = seed_ ^ (0xD1B54A32D192ED03ull * (seg + 1));
      const double px = w_.x0 + unit_random(s) * (w_.x1 - w_.x0);
      const double pz = w_.z0 + unit_random(s) * (w_.z1 - w_.z0);
      const double heading = unit_random(s) * 2 * M_PI, pitch = (15 + 30 * unit_random(s)) * M_PI / 180;
      const double alt = w_.top + (0.2 + unit_random(s)) * std::max(0.5 * height, 0.02 * span);
      const double dt = t - double(seg) * kTeleportSeconds;
      const Vec3d dir{std::cos(heading), 0, std::sin(heading)};
      c.pos = Vec3d{px, alt, pz} + dir * (0.01 * span * dt);
      c.target = c.pos + Vec3d{dir.x * std::cos(pitch), -std::sin(pitch), dir.z * std::cos(pitch)} * (0.1 * span);
      break;
    }
  }
  return c;
}

}  // namespace st::loadgen

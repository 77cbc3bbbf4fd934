#include "loadgen/camera_path.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st::loadgen {


WorldFrame world_frame(const PackHeader& header, const CutGrid& grid) {
  const LightSpace light = LightSpace::from_array(header.light_kind, header.light);
  return world_frame(light, surface_extent(light, grid));
}

WorldFrame world_frame(const LightSpace& light, const SurfaceExtent& s) {
  WorldFrame w;
  w.light = light;
  w.ground = s.ground, w.top = s.top;
  w.x0 = s.x0, w.x1 = s.x1, w.z0 = s.z0, w.z1 = s.z1;
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

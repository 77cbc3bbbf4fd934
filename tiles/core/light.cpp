#include "tiles/core/light.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "common/error.hpp"

namespace st {
namespace {

constexpr double kPi = 3.14159265358979323846;
double rad(double deg) { return deg * kPi / 180.0; }

double parse_number(const std::string& key, const std::string& s) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (...) {
    used = 0;
  }
  if (used != s.size() || s.empty() || !std::isfinite(v))
    throw Error("--light: '" + key + "' needs a finite number, got '" + s + "'");
  return v;
}

Vec3d parse_vec(const std::string& key, const std::vector<std::string>& parts) {
  if (parts.size() != 3) throw Error("--light: '" + key + "' needs X,Y,Z");
  return {parse_number(key, parts[0]), parse_number(key, parts[1]), parse_number(key, parts[2])};
}

// Orthonormal (u, v) perpendicular to forward; stable choice of helper axis.
void make_basis(const Vec3d& f, Vec3d& u, Vec3d& v) {
  Vec3d helper = std::fabs(f.y) > 0.9 ? Vec3d{0, 0, 1} : Vec3d{0, 1, 0};
  u = normalize(cross(helper, f));
  v = cross(f, u);
}

}  // namespace

bool light_kind_known(uint8_t kind) {
  return kind == uint8_t(LightKind::sun) || kind == uint8_t(LightKind::spot) || kind == uint8_t(LightKind::sun_ground) ||
         kind == uint8_t(LightKind::spot_window);
}

const char* light_kind_name(LightKind kind) {
  switch (kind) {
    case LightKind::sun: return "sun";
    case LightKind::spot: return "spot";
    case LightKind::sun_ground: return "sun-ground";
    case LightKind::spot_window: return "spot-window";
  }
  return "unknown";
}

LightSpec LightSpec::parse(const std::string& text) {
  LightSpec s;
  auto colon = text.find(':');
  std::string kind = text.substr(0, colon);
  std::string rest = colon == std::string::npos ? "" : text.substr(colon + 1);
  if (kind == "sun") {
    s.kind = LightKind::sun;
  } else if (kind == "spot") {
    s.kind = LightKind::spot;
  } else {
    if (kind == "spot-window")
      throw Error("--light: 'spot-window:' is the frame of an area light set's samples (area:...), not a light of its own");
    if (kind == "sun-path" || kind == "area")
      throw Error("--light: '" + kind + ":' is a light set for shadow-map stacks (tiles/core/light_set.hpp); this command "
                  "builds one light's map (sun:... or spot:...)");
    throw Error("--light: unknown light kind '" + kind + "' (expected sun:... or spot:...)");
  }
  // Split on commas; a key=value starts a new field, bare numbers continue a vector.
  std::vector<std::pair<std::string, std::vector<std::string>>> fields;
  std::stringstream ss(rest);
  std::string tok;
  while (std::getline(ss, tok, ',')) {
    auto eq = tok.find('=');
    if (eq != std::string::npos) {
      fields.push_back({tok.substr(0, eq), {tok.substr(eq + 1)}});
    } else if (!fields.empty()) {
      fields.back().second.push_back(tok);
    } else {
      throw Error("--light: expected key=value, got '" + tok + "'");
    }
  }
  bool have_az = false, have_el = false, have_pos = false, have_target = false;
  for (auto& field : fields) {
    // Named references, not a structured binding: clang < 16 cannot capture bindings in
    // a lambda (the fuzz preset builds with clang 14).
    const std::string& key = field.first;
    auto& vals = field.second;
    auto one = [&]() {
      if (vals.size() != 1) throw Error("--light: '" + key + "' takes one number");
      return parse_number(key, vals[0]);
    };
    if (s.kind == LightKind::sun && key == "azimuth") {
      s.azimuth_deg = one(), have_az = true;
    } else if (s.kind == LightKind::sun && key == "elevation") {
      s.elevation_deg = one(), have_el = true;
    } else if (s.kind == LightKind::sun && key == "margin") {
      s.margin = one();
    } else if (s.kind == LightKind::spot && key == "pos") {
      s.pos = parse_vec(key, vals), have_pos = true;
    } else if (s.kind == LightKind::spot && key == "target") {
      s.target = parse_vec(key, vals), have_target = true;
    } else if (s.kind == LightKind::spot && key == "fov") {
      s.fov_deg = one();
    } else {
      throw Error("--light: unknown field '" + key + "' for a " + kind + " light");
    }
  }
  if (s.kind == LightKind::sun) {
    if (!have_az || !have_el) throw Error("--light sun: needs azimuth=DEG,elevation=DEG");
    if (!(s.elevation_deg > 0 && s.elevation_deg <= 90))
      throw Error("--light sun: elevation must be in (0, 90] degrees");
    if (!(s.margin >= 0 && s.margin < 10)) throw Error("--light sun: margin must be in [0, 10)");
  } else {
    if (!have_pos || !have_target) throw Error("--light spot: needs pos=X,Y,Z,target=X,Y,Z");
    if (length(s.target - s.pos) == 0) throw Error("--light spot: pos and target coincide");
    if (!(s.fov_deg > 0 && s.fov_deg < 170)) throw Error("--light spot: fov must be in (0, 170)");
  }
  return s;
}

std::string LightSpec::to_string() const {
  std::ostringstream os;
  os.precision(17);
  if (kind == LightKind::sun) {
    os << "sun:azimuth=" << azimuth_deg << ",elevation=" << elevation_deg << ",margin=" << margin;
  } else {
    os << (kind == LightKind::spot_window ? "spot-window:pos=" : "spot:pos=") << pos.x << ',' << pos.y << ','
       << pos.z << ",target=" << target.x << ',' << target.y << ',' << target.z << ",fov=" << fov_deg;
    if (kind == LightKind::spot_window) os << ",shift=" << shift_u << ',' << shift_v;
  }
  return os.str();
}

LightSpace LightSpace::fit(const LightSpec& spec, const Aabb& b) {
  if (b.empty()) throw Error("light: the scene has no geometry to fit the light to");
  if (spec.kind == LightKind::sun_ground)
    throw Error("light: a ground-frame sun is fitted per light set (LightSet::fit), not alone");
  LightSpace ls;
  ls.kind_ = spec.kind;
  ls.spec_ = spec;
  std::array<Vec3d, 8> corners;
  for (int i = 0; i < 8; ++i)
    corners[i] = {(i & 1) ? b.hi.x : b.lo.x, (i & 2) ? b.hi.y : b.lo.y, (i & 4) ? b.hi.z : b.lo.z};
  if (spec.kind == LightKind::sun) {
    double az = rad(spec.azimuth_deg), el = rad(spec.elevation_deg);
    // Direction towards the sun; +Y up, azimuth measured from +Z towards +X.
    Vec3d to_sun{std::cos(el) * std::sin(az), std::sin(el), std::cos(el) * std::cos(az)};
    ls.forward_ = normalize(-to_sun);
    make_basis(ls.forward_, ls.axis_u_, ls.axis_v_);
    double umin = INFINITY, umax = -INFINITY, vmin = INFINITY, vmax = -INFINITY;
    double fmin = INFINITY, fmax = -INFINITY;
    for (auto& c : corners) {
      double u = dot(c, ls.axis_u_), v = dot(c, ls.axis_v_), f = dot(c, ls.forward_);
      umin = std::min(umin, u), umax = std::max(umax, u);
      vmin = std::min(vmin, v), vmax = std::max(vmax, v);
      fmin = std::min(fmin, f), fmax = std::max(fmax, f);
    }
    double side = std::max(umax - umin, vmax - vmin);
    double depth = fmax - fmin;
    if (!(side > 0) || !(depth > 0) || !std::isfinite(side) || !std::isfinite(depth))
      throw Error("light: zero-extent light box (the scene is flat or a point seen from the sun)");
    double m = spec.margin;
    side *= 1 + 2 * m;
    depth *= 1 + 2 * m;
    double uc = 0.5 * (umin + umax), vc = 0.5 * (vmin + vmax), fc = 0.5 * (fmin + fmax);
    ls.extent_uv_ = side;
    ls.near_ = 0;
    ls.far_ = depth;
    ls.origin_ = ls.axis_u_ * (uc - side / 2) + ls.axis_v_ * (vc - side / 2) +
                 ls.forward_ * (fc - depth / 2);
  } else {
    ls.origin_ = spec.pos;
    ls.forward_ = normalize(spec.target - spec.pos);
    make_basis(ls.forward_, ls.axis_u_, ls.axis_v_);
    double zmin = INFINITY, zmax = -INFINITY;
    for (auto& c : corners) {
      double z = dot(c - spec.pos, ls.forward_);
      zmin = std::min(zmin, z), zmax = std::max(zmax, z);
    }
    if (!(zmax > 0)) throw Error("light spot: the scene lies entirely behind the light");
    ls.far_ = zmax * 1.01;
    ls.near_ = std::max(zmin * 0.99, ls.far_ * 1e-4);
    ls.extent_uv_ = 2 * std::tan(rad(spec.fov_deg) / 2);
  }
  return ls;
}

LightPoint LightSpace::to_light(const Vec3d& p) const {
  Vec3d r = p - origin_;
  if (kind_ == LightKind::sun_ground) return to_light_ground(r);
  if (kind_ == LightKind::sun) {
    return {dot(r, axis_u_) / extent_uv_, dot(r, axis_v_) / extent_uv_,
            (dot(r, forward_) - near_) / (far_ - near_)};
  }
  double z = dot(r, forward_);
  if (kind_ == LightKind::spot_window) {  // the sheared image plane (light.hpp)
    const double u = (dot(r, axis_u_) / z - spec_.shift_u) / extent_uv_ + 0.5;
    const double v = (dot(r, axis_v_) / z - spec_.shift_v) / extent_uv_ + 0.5;
    return {u, v, (z - near_) / (far_ - near_)};
  }
  double u = dot(r, axis_u_) / (z * extent_uv_) + 0.5;
  double v = dot(r, axis_v_) / (z * extent_uv_) + 0.5;
  return {u, v, (z - near_) / (far_ - near_)};
}

LightRay LightSpace::texel_ray(uint32_t level, uint64_t x, uint64_t y) const {
  const double inv = std::ldexp(1.0, -int(level));
  const double u = (double(x) + 0.5) * inv, v = (double(y) + 0.5) * inv;
  if (kind_ == LightKind::sun || kind_ == LightKind::sun_ground) {
    // sun_ground: the same operations with ray_axis() for forward (light.hpp).
    const Vec3d ax = ray_axis();
    Vec3d o = origin_ + axis_u_ * (u * extent_uv_) + axis_v_ * (v * extent_uv_) + ax * near_;
    return {o, ax * (far_ - near_)};
  }
  // Spot: direction with unit forward component, so t is the distance along the axis.
  return {origin_, perspective_dir(u, v)};
}

Vec3d LightSpace::perspective_dir(double u, double v) const {
  if (kind_ == LightKind::spot_window)
    return forward_ + axis_u_ * ((u - 0.5) * extent_uv_ + spec_.shift_u) +
           axis_v_ * ((v - 0.5) * extent_uv_ + spec_.shift_v);
  return forward_ + axis_u_ * ((u - 0.5) * extent_uv_) + axis_v_ * ((v - 0.5) * extent_uv_);
}

Vec3d LightSpace::to_world(double u, double v, double d) const {
  if (parallel()) {  // texel_ray's arithmetic at (u, v), t == d
    const Vec3d ax = ray_axis();
    return origin_ + axis_u_ * (u * extent_uv_) + axis_v_ * (v * extent_uv_) + ax * near_ + ax * ((far_ - near_) * d);
  }
  return origin_ + perspective_dir(u, v) * (near_ + d * (far_ - near_));
}

double LightSpace::depth_of_t(const LightRay&, double t) const {
  if (parallel()) return t;
  return (t - near_) / (far_ - near_);
}

std::array<uint64_t, 2> LightSpace::texel_of(uint32_t level, double u, double v) {
  // floor(w * r) clamped to [0, r - 1] (w * r is exact: r is a power of two), without the
  // floor call (every soft-shadow sample takes this path): r is an integer, so
  // floor(x) >= r iff x >= r and floor(x) >= 0 iff x >= 0 (NaN: 0), and for 0 <= x < r
  // the conversion's truncation is the floor.
  const double r = level < 64 ? double(uint64_t(1) << level) : std::ldexp(1.0, int(level));
  auto cell = [&](double w) -> uint64_t {
    const double x = w * r;
    if (!(x >= 0)) return 0;
    if (x >= r) return uint64_t(r) - 1;
    return uint64_t(x);
  };
  return {cell(u), cell(v)};
}

std::array<double, 18> LightSpace::to_array() const {
  return {origin_.x, origin_.y, origin_.z, axis_u_.x, axis_u_.y, axis_u_.z,
          axis_v_.x, axis_v_.y, axis_v_.z, forward_.x, forward_.y, forward_.z,
          extent_uv_, near_, far_,
          kind_ == LightKind::spot_window ? spec_.shift_u : spec_.azimuth_deg,
          kind_ == LightKind::spot_window ? spec_.shift_v : spec_.elevation_deg,
          parallel() ? spec_.margin : spec_.fov_deg};
}

std::string LightSpace::check_array(LightKind kind, const std::array<double, 18>& a) {
  static const char* const kNames[18] = {"origin.x", "origin.y", "origin.z", "axis_u.x", "axis_u.y", "axis_u.z",
                                         "axis_v.x", "axis_v.y", "axis_v.z", "forward.x", "forward.y", "forward.z",
                                         "extent", "near", "far", "azimuth/c_u", "elevation/c_v", "margin/fov"};
  auto num = [](double v) {
    std::ostringstream os;
    os.precision(17);
    os << v;
    return os.str();
  };
  if (!light_kind_known(uint8_t(kind)))
    return "unknown light kind " + std::to_string(int(kind)) +
           " (this build reads 0 sun, 1 spot, 2 sun-ground, 3 spot-window)";
  for (size_t i = 0; i < a.size(); ++i) {
    if (!std::isfinite(a[i])) return std::string(kNames[i]) + " is " + num(a[i]) + ", not a finite number";
    if (std::fabs(a[i]) > kMaxLightCoordinate)
      return std::string(kNames[i]) + " = " + num(a[i]) + " exceeds " + num(kMaxLightCoordinate);
  }
  if (kind == LightKind::sun_ground) return check_ground_array(a);
  const Vec3d u{a[3], a[4], a[5]}, v{a[6], a[7], a[8]}, f{a[9], a[10], a[11]};
  constexpr double kTol = 1e-6;
  const std::pair<const char*, Vec3d> axes[3] = {{"axis_u", u}, {"axis_v", v}, {"forward", f}};
  for (const auto& [name, axis] : axes)
    if (std::fabs(length(axis) - 1) > kTol) return std::string(name) + " has length " + num(length(axis)) + ", not 1";
  if (std::fabs(dot(u, v)) > kTol || std::fabs(dot(u, f)) > kTol || std::fabs(dot(v, f)) > kTol)
    return "axes are not orthogonal";
  const double extent = a[12], near = a[13], far = a[14];
  if (!(extent > 0)) return "extent " + num(extent) + " is not positive";
  if (!(near >= 0) || !(far > near) || !(far - near > 0))
    return "near " + num(near) + " and far " + num(far) + " do not make 0 <= near < far";
  if (kind == LightKind::sun) {
    if (!(a[16] > 0 && a[16] <= 90)) return "sun elevation " + num(a[16]) + " is outside (0, 90]";
    if (!(a[17] >= 0 && a[17] < 10)) return "sun margin " + num(a[17]) + " is outside [0, 10)";
  } else if (!(a[17] > 0 && a[17] < 170)) {
    return "spot fov " + num(a[17]) + " is outside (0, 170)";
  }
  if (kind == LightKind::spot_window)
    for (int i : {15, 16})
      if (!(std::fabs(a[i]) <= kMaxWindowShift))
        return std::string("window shift ") + (i == 15 ? "c_u" : "c_v") + " = " + num(a[i]) + " exceeds " +
               num(kMaxWindowShift);
  return "";
}

LightSpace LightSpace::from_array(LightKind kind, const std::array<double, 18>& a) {
  LightSpace ls;
  ls.kind_ = kind;
  ls.origin_ = {a[0], a[1], a[2]};
  ls.axis_u_ = {a[3], a[4], a[5]};
  ls.axis_v_ = {a[6], a[7], a[8]};
  ls.forward_ = {a[9], a[10], a[11]};
  ls.extent_uv_ = a[12];
  ls.near_ = a[13];
  ls.far_ = a[14];
  ls.spec_.kind = kind == LightKind::sun_ground ? LightKind::sun : kind;
  if (kind == LightKind::spot_window) {
    ls.spec_.shift_u = a[15];
    ls.spec_.shift_v = a[16];
  } else {
    ls.spec_.azimuth_deg = a[15];
    ls.spec_.elevation_deg = a[16];
  }
  if (kind == LightKind::sun_ground) ls.derive_ground();
  if (kind == LightKind::sun || kind == LightKind::sun_ground) {
    ls.spec_.margin = a[17];
  } else {
    ls.spec_.fov_deg = a[17];
    ls.spec_.pos = ls.origin_;
    ls.spec_.target = ls.origin_ + ls.forward_;
  }
  return ls;
}

// ---- The ground frame (LightKind::sun_ground) ----
//
// With n = axis_u x axis_v (unit, pointing away from the sun: forward . n > 0) and
// g = forward / (forward . n) (the ray step per unit of depth distance, g . n = 1), a
// world point p, r = p - origin, z = r . n, lies on the ray through the reference-plane
// point q = p - g z, so
//   u = (r . axis_u - (g . axis_u) z) / E,  v = (r . axis_v - (g . axis_v) z) / E,
//   d = (z - near) / (far - near),
// affine in p (rows axis_u - ku n, axis_v - kv n, n: the dual basis of axis_u, axis_v, g).
// texel_ray inverts it: origin + axis_u (u E) + axis_v (v E) + g near, direction
// g (far - near), so t == d.

void LightSpace::derive_ground() {
  depth_axis_ = cross(axis_u_, axis_v_);
  ray_axis_ = forward_ * (1.0 / dot(forward_, depth_axis_));
  ku_ = dot(ray_axis_, axis_u_);
  kv_ = dot(ray_axis_, axis_v_);
}

LightPoint LightSpace::to_light_ground(const Vec3d& r) const {
  const double z = dot(r, depth_axis_);
  return {(dot(r, axis_u_) - ku_ * z) / extent_uv_, (dot(r, axis_v_) - kv_ * z) / extent_uv_,
          (z - near_) / (far_ - near_)};
}

std::string LightSpace::check_ground_array(const std::array<double, 18>& a) {
  auto num = [](double v) {
    std::ostringstream os;
    os.precision(17);
    os << v;
    return os.str();
  };
  const Vec3d u{a[3], a[4], a[5]}, v{a[6], a[7], a[8]}, f{a[9], a[10], a[11]};
  constexpr double kTol = 1e-6;
  const std::pair<const char*, Vec3d> axes[3] = {{"axis_u", u}, {"axis_v", v}, {"forward", f}};
  for (const auto& [name, axis] : axes)
    if (std::fabs(length(axis) - 1) > kTol)
      return std::string("ground frame: ") + name + " has length " + num(length(axis)) + ", not 1";
  if (std::fabs(dot(u, v)) > kTol) return "ground frame: axis_u and axis_v are not orthogonal";
  const double sine = dot(f, cross(u, v));
  if (!(sine >= kMinGroundSine))
    return "ground frame: the sun's ray meets the reference plane at sine " + num(sine) + ", below " +
           num(kMinGroundSine) + " (about 1 degree) or from the wrong side";
  const double extent = a[12], near = a[13], far = a[14];
  if (!(extent > 0)) return "ground frame: extent " + num(extent) + " is not positive";
  if (!(far > near) || !(far - near > 0)) return "ground frame: near " + num(near) + " is not below far " + num(far);
  if (!((far - near) / sine <= kMaxLightCoordinate) || !(std::fabs(near) / sine <= kMaxLightCoordinate))
    return "ground frame: the rays' reach exceeds " + num(kMaxLightCoordinate);
  if (!(a[16] > 0 && a[16] <= 90)) return "sun elevation " + num(a[16]) + " is outside (0, 90]";
  if (!(a[17] >= 0 && a[17] < 10)) return "sun margin " + num(a[17]) + " is outside [0, 10)";
  return "";
}

}  // namespace st

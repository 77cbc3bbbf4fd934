#include "tiles/core/light_set.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <tuple>
#include <utility>
#include <vector>

#include "common/error.hpp"
#include "common/hash.hpp"

namespace st {
namespace {

[[noreturn]] void fail(const std::string& kind, const std::string& what) {
  throw Error("--light " + kind + ": " + what);
}

double number(const std::string& kind, const std::string& key, const std::string& s) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (...) {
    used = 0;
  }
  if (s.empty() || used != s.size() || !std::isfinite(v))
    fail(kind, "'" + key + "' needs a finite number, got '" + s + "'");
  if (std::fabs(v) > kMaxLightCoordinate) fail(kind, "'" + key + "' = " + s + " is out of range");
  return v;
}

// "A0..A1" or "A" (then A..A).
std::pair<double, double> range(const std::string& kind, const std::string& key, const std::string& s) {
  const size_t dots = s.find("..");
  if (dots == std::string::npos) {
    const double v = number(kind, key, s);
    return {v, v};
  }
  return {number(kind, key, s.substr(0, dots)), number(kind, key, s.substr(dots + 2))};
}

using Fields = std::vector<std::pair<std::string, std::vector<std::string>>>;

// Comma-separated key=value fields; bare numbers continue the previous field (vectors).
Fields split_fields(const std::string& kind, const std::string& rest) {
  Fields fields;
  std::stringstream ss(rest);
  std::string tok;
  while (std::getline(ss, tok, ',')) {
    const auto eq = tok.find('=');
    if (eq != std::string::npos) {
      const std::string key = tok.substr(0, eq);
      for (const auto& f : fields)
        if (f.first == key) fail(kind, "field '" + key + "' given twice");
      fields.push_back({key, {tok.substr(eq + 1)}});
    } else if (!fields.empty()) {
      fields.back().second.push_back(tok);
    } else {
      fail(kind, "expected key=value, got '" + tok + "'");
    }
  }
  return fields;
}

uint32_t sample_count(const std::string& kind, const std::string& s) {
  const double v = number(kind, "samples", s);
  if (v != std::floor(v) || v < 1 || v > kMaxLightSamples)
    fail(kind, "samples must be an integer in 1.." + std::to_string(kMaxLightSamples) + ", got '" + s + "'");
  return uint32_t(v);
}

}  // namespace

bool LightSetSpec::names_light_set(const std::string& text) {
  return text.rfind("sun-path:", 0) == 0 || text.rfind("area:", 0) == 0;
}

LightSetSpec LightSetSpec::parse(const std::string& text) {
  LightSetSpec s;
  const auto colon = text.find(':');
  const std::string kind = text.substr(0, colon);
  const std::string rest = colon == std::string::npos ? "" : text.substr(colon + 1);
  if (kind == "sun-path") {
    s.kind = LightSetKind::sun_path;
  } else if (kind == "area") {
    s.kind = LightSetKind::area;
  } else {
    throw Error("--light: unknown light set '" + kind + "' (expected sun-path:... or area:...)");
  }
  bool have_samples = false, have_az = false, have_el = false, have_pos = false, have_target = false,
       have_size = false;
  for (const auto& field : split_fields(kind, rest)) {
    const std::string& key = field.first;
    const auto& vals = field.second;
    auto one = [&]() -> const std::string& {
      if (vals.size() != 1) fail(kind, "'" + key + "' takes one value");
      return vals[0];
    };
    auto vec = [&]() {
      if (vals.size() != 3) fail(kind, "'" + key + "' needs X,Y,Z");
      return Vec3d{number(kind, key, vals[0]), number(kind, key, vals[1]), number(kind, key, vals[2])};
    };
    if (key == "samples") {
      s.samples = sample_count(kind, one()), have_samples = true;
    } else if (s.kind == LightSetKind::sun_path && key == "azimuth") {
      std::tie(s.azimuth0_deg, s.azimuth1_deg) = range(kind, key, one()), have_az = true;
    } else if (s.kind == LightSetKind::sun_path && key == "elevation") {
      std::tie(s.elevation0_deg, s.elevation1_deg) = range(kind, key, one()), have_el = true;
    } else if (s.kind == LightSetKind::sun_path && key == "margin") {
      s.margin = number(kind, key, one());
    } else if (s.kind == LightSetKind::sun_path && key == "ground") {
      s.ground = number(kind, key, one());
    } else if (s.kind == LightSetKind::sun_path && key == "frame") {
      if (one() == "ground") s.sun_frame = SunFrame::ground;
      else if (one() == "ortho") s.sun_frame = SunFrame::ortho;
      else fail(kind, "frame must be ground or ortho, got '" + one() + "'");
    } else if (s.kind == LightSetKind::area && key == "pos") {
      s.pos = vec(), have_pos = true;
    } else if (s.kind == LightSetKind::area && key == "target") {
      s.target = vec(), have_target = true;
    } else if (s.kind == LightSetKind::area && key == "size") {
      if (vals.size() != 2) fail(kind, "'size' needs W,H");
      s.width = number(kind, key, vals[0]), s.height = number(kind, key, vals[1]), have_size = true;
    } else if (s.kind == LightSetKind::area && key == "fov") {
      s.fov_deg = number(kind, key, one());
    } else if (s.kind == LightSetKind::area && key == "jitter") {
      s.jitter = number(kind, key, one());
    } else if (s.kind == LightSetKind::area && key == "frame") {
      const std::string& f = one();
      if (f == "window") s.area_frame = AreaFrame::window;
      else if (f == "translate") s.area_frame = AreaFrame::translate;
      else fail(kind, "frame must be window or translate, got '" + f + "'");
    } else if (s.kind == LightSetKind::area && key == "seed") {
      const double v = number(kind, key, one());
      if (v != std::floor(v) || v < 0 || v > 9007199254740992.0) fail(kind, "seed must be an integer >= 0");
      s.seed = uint64_t(v);
    } else {
      fail(kind, "unknown field '" + key + "'");
    }
  }
  if (!have_samples) fail(kind, "needs samples=N");
  if (s.kind == LightSetKind::sun_path) {
    if (!have_az || !have_el) fail(kind, "needs azimuth=A0..A1,elevation=E0..E1");
    if (std::fabs(s.azimuth1_deg - s.azimuth0_deg) > 360) fail(kind, "azimuth range spans more than 360 degrees");
    for (double e : {s.elevation0_deg, s.elevation1_deg})
      if (!(e > 0 && e <= 90)) fail(kind, "elevation " + std::to_string(e) + " is outside (0, 90] degrees");
    if (!(s.margin >= 0 && s.margin < 10)) fail(kind, "margin must be in [0, 10)");
    if (!std::isnan(s.ground) && s.sun_frame != SunFrame::ground) fail(kind, "ground=Y needs frame=ground");
  } else {
    if (!have_pos || !have_target || !have_size) fail(kind, "needs pos=X,Y,Z,target=X,Y,Z,size=W,H");
    if (length(s.target - s.pos) == 0) fail(kind, "pos and target coincide");
    if (!(s.width > 0 && s.height > 0)) fail(kind, "size W,H must both be > 0");
    if (!(s.fov_deg > 0 && s.fov_deg < 170)) fail(kind, "fov must be in (0, 170)");
    if (!(s.jitter >= 0 && s.jitter <= 1)) fail(kind, "jitter must be in [0, 1]");
  }
  return s;
}

std::string LightSetSpec::to_string() const {
  std::ostringstream os;
  os.precision(17);
  if (kind == LightSetKind::sun_path) {
    os << "sun-path:azimuth=" << azimuth0_deg << ".." << azimuth1_deg << ",elevation=" << elevation0_deg << ".."
       << elevation1_deg << ",samples=" << samples << ",margin=" << margin
       << ",frame=" << (sun_frame == SunFrame::ground ? "ground" : "ortho");
    if (!std::isnan(ground)) os << ",ground=" << ground;
  } else {
    os << "area:pos=" << pos.x << ',' << pos.y << ',' << pos.z << ",target=" << target.x << ',' << target.y << ','
       << target.z << ",size=" << width << ',' << height << ",samples=" << samples << ",fov=" << fov_deg
       << ",jitter=" << jitter << ",seed=" << seed << ",frame=" << (area_frame == AreaFrame::window ? "window" : "translate");
  }
  return os.str();
}

void hilbert_cell(uint32_t order, uint64_t d, uint32_t& x, uint32_t& y) {
  // The classic iterative mapping: two bits of d per level, rotating the quadrant.
  uint64_t rx = 0, ry = 0, t = d, cx = 0, cy = 0;
  for (uint64_t s = 1; s < (uint64_t(1) << order); s *= 2) {
    rx = 1 & (t / 2);
    ry = 1 & (t ^ rx);
    if (ry == 0) {
      if (rx == 1) cx = s - 1 - cx, cy = s - 1 - cy;
      std::swap(cx, cy);
    }
    cx += s * rx;
    cy += s * ry;
    t /= 4;
  }
  x = uint32_t(cx), y = uint32_t(cy);
}

std::vector<LightSpec> LightSetSpec::sample_specs() const {
  std::vector<LightSpec> out;
  out.reserve(samples);
  if (kind == LightSetKind::sun_path) {
    for (uint32_t w = 0; w < samples; ++w) {
      const double t = samples == 1 ? 0.0 : double(w) / double(samples - 1);
      LightSpec s;
      s.kind = LightKind::sun;
      s.azimuth_deg = azimuth0_deg + t * (azimuth1_deg - azimuth0_deg);
      s.elevation_deg = elevation0_deg + t * (elevation1_deg - elevation0_deg);
      s.margin = margin;
      out.push_back(s);
    }
    return out;
  }
  // The rectangle's axes: those of the spot light pos -> target (LightSpace's basis).
  LightSpec centre;
  centre.kind = LightKind::spot;
  centre.pos = pos, centre.target = target, centre.fov_deg = fov_deg;
  Aabb probe;
  probe.extend(target);  // any box in front of the light fits
  const LightSpace axes = LightSpace::fit(centre, probe);
  uint32_t order = 0;
  while ((uint64_t(1) << (2 * order)) < samples) ++order;
  const uint64_t cells = uint64_t(1) << (2 * order), side = uint64_t(1) << order;
  Rng rng(seed);
  for (uint32_t w = 0; w < samples; ++w) {
    // N points evenly along the curve of 4^order >= N cells: gaps of fewer than 4 cells.
    const uint64_t d = (2 * uint64_t(w) + 1) * cells / (2 * uint64_t(samples));
    uint32_t hx = 0, hy = 0;
    hilbert_cell(order, d, hx, hy);
    const double jx = jitter > 0 ? jitter * (rng.uniform() - 0.5) : 0.0;
    const double jy = jitter > 0 ? jitter * (rng.uniform() - 0.5) : 0.0;
    const double fx = (double(hx) + 0.5 + jx) / double(side) - 0.5;
    const double fy = (double(hy) + 0.5 + jy) / double(side) - 0.5;
    const Vec3d offset = axes.axis_u() * (fx * width) + axes.axis_v() * (fy * height);
    LightSpec s = centre;
    s.pos = pos + offset;
    s.target = target + offset;
    out.push_back(s);
  }
  return out;
}

namespace {

constexpr double kPi = 3.14159265358979323846;

// A sun path's samples share one frame rule and one box size (see light_set.hpp "Frames").
std::vector<LightSpace> fit_sun_path(const std::vector<LightSpec>& specs, const Aabb& b) {
  struct Frame {
    Vec3d u, v, f;
    double uc, vc, fc;
  };
  std::vector<Frame> frames;
  double side = 0, depth = 0;
  for (const LightSpec& s : specs) {
    const double az = s.azimuth_deg * kPi / 180, el = s.elevation_deg * kPi / 180;
    Frame fr;
    fr.f = normalize(Vec3d{-std::cos(el) * std::sin(az), -std::sin(el), -std::cos(el) * std::cos(az)});
    fr.u = Vec3d{-std::cos(az), 0, std::sin(az)};  // LightSpace::fit's u below ~64 degrees
    fr.v = cross(fr.f, fr.u);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < 8; ++i) {
      const Vec3d c{(i & 1) ? b.hi.x : b.lo.x, (i & 2) ? b.hi.y : b.lo.y, (i & 4) ? b.hi.z : b.lo.z};
      const double p[3] = {dot(c, fr.u), dot(c, fr.v), dot(c, fr.f)};
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
    }
    side = std::max({side, hi[0] - lo[0], hi[1] - lo[1]});
    depth = std::max(depth, hi[2] - lo[2]);
    fr.uc = 0.5 * (lo[0] + hi[0]), fr.vc = 0.5 * (lo[1] + hi[1]), fr.fc = 0.5 * (lo[2] + hi[2]);
    frames.push_back(fr);
  }
  const double m = specs.empty() ? 0 : specs[0].margin;
  side *= 1 + 2 * m, depth *= 1 + 2 * m;
  if (!(side > 0) || !(depth > 0) || !std::isfinite(side) || !std::isfinite(depth))
    throw Error("light set: zero-extent light box (the scene is flat or a point seen from the sun)");
  std::vector<LightSpace> out;
  for (size_t w = 0; w < frames.size(); ++w) {
    const Frame& fr = frames[w];
    const Vec3d o = fr.u * (fr.uc - side / 2) + fr.v * (fr.vc - side / 2) + fr.f * (fr.fc - depth / 2);
    const std::array<double, 18> a = {o.x, o.y, o.z, fr.u.x, fr.u.y, fr.u.z, fr.v.x, fr.v.y, fr.v.z,
                                      fr.f.x, fr.f.y, fr.f.z, side, 0, depth, specs[w].azimuth_deg,
                                      specs[w].elevation_deg, m};
    const std::string bad = LightSpace::check_array(LightKind::sun, a);
    if (!bad.empty()) throw Error("light set sample " + std::to_string(w) + " (" + specs[w].to_string() + "): " + bad);
    out.push_back(LightSpace::from_array(LightKind::sun, a));
  }
  return out;
}

// frame=ground (light_set.hpp "Frames"): one square on the ground plane for every sample.
std::vector<LightSpace> fit_sun_ground(const std::vector<LightSpec>& specs, const Aabb& b, double ground_y,
                                       const std::vector<Vec3d>& extent) {
  const double m = specs.empty() ? 0 : specs[0].margin;
  const Vec3d ext = b.extent();
  const double H = ext.y, width = std::max(ext.x, ext.z);
  const double pad = m * std::max(H, 1e-3 * width);
  const double ground = std::isnan(ground_y) ? b.lo.y : ground_y;
  if (!(ground >= b.lo.y && ground <= b.hi.y))
    throw Error("--light sun-path: ground=" + std::to_string(ground) + " lies outside the scene's heights " +
                std::to_string(b.lo.y) + ".." + std::to_string(b.hi.y));
  const Vec3d axis_u{1, 0, 0}, axis_v{0, 0, 1};  // n = u x v = (0, -1, 0): down
  // Signed distances below the reference plane: the box's top (and margin) to its bottom.
  const double near = -(b.hi.y - ground) - pad, far = (ground - b.lo.y) + pad;
  if (!(far > near) || !std::isfinite(H) || !std::isfinite(width) || !(std::max(width, H) > 0))
    throw Error("light set: zero-extent light slab (the scene is a point, or flat with margin=0)");
  double lo_x = INFINITY, hi_x = -INFINITY, lo_z = INFINITY, hi_z = -INFINITY;
  for (const LightSpec& s : specs) {
    const double az = s.azimuth_deg * kPi / 180, el = s.elevation_deg * kPi / 180;
    const Vec3d f = normalize(Vec3d{-std::cos(el) * std::sin(az), -std::sin(el), -std::cos(el) * std::cos(az)});
    const double gx = f.x / -f.y, gz = f.z / -f.y;  // the ray's step per unit of descent
    const size_t count = extent.empty() ? 8 : extent.size();
    for (size_t i = 0; i < count; ++i) {
      const Vec3d c = extent.empty() ? Vec3d{(i & 1) ? b.hi.x : b.lo.x, (i & 2) ? b.hi.y : b.lo.y,
                                             (i & 4) ? b.hi.z : b.lo.z}
                                     : extent[i];
      const double h = c.y - ground;  // height above the reference plane (negative below)
      const double x = c.x + gx * h, z = c.z + gz * h;
      lo_x = std::min(lo_x, x), hi_x = std::max(hi_x, x), lo_z = std::min(lo_z, z), hi_z = std::max(hi_z, z);
    }
  }
  const double side = std::max({hi_x - lo_x, hi_z - lo_z, 1e-3 * std::max(width, H)}) * (1 + 2 * m);
  const double scene = std::max(width, H) * (1 + 2 * m);
  if (!std::isfinite(side) || side > kMaxGroundStretch * scene) {
    std::ostringstream os;
    os.precision(3);
    os << "--light sun-path: frame=ground: the lowest sun stretches the ground square to " << side / scene
       << " times the scene (limit " << kMaxGroundStretch
       << "); raise the lowest elevation or use frame=ortho";
    throw Error(os.str());
  }
  const Vec3d o{0.5 * (lo_x + hi_x) - side / 2, ground, 0.5 * (lo_z + hi_z) - side / 2};
  std::vector<LightSpace> out;
  for (size_t w = 0; w < specs.size(); ++w) {
    const double az = specs[w].azimuth_deg * kPi / 180, el = specs[w].elevation_deg * kPi / 180;
    const Vec3d f = normalize(Vec3d{-std::cos(el) * std::sin(az), -std::sin(el), -std::cos(el) * std::cos(az)});
    const std::array<double, 18> a = {o.x,      o.y,      o.z,  axis_u.x, axis_u.y, axis_u.z, axis_v.x, axis_v.y,
                                      axis_v.z, f.x,      f.y,  f.z,      side,     near,     far,
                                      specs[w].azimuth_deg, specs[w].elevation_deg, m};
    const std::string bad = LightSpace::check_array(LightKind::sun_ground, a);
    if (!bad.empty()) throw Error("light set sample " + std::to_string(w) + " (" + specs[w].to_string() + "): " + bad);
    out.push_back(LightSpace::from_array(LightKind::sun_ground, a));
  }
  return out;
}

// An area light's samples in the window frame (light_set.hpp "Frames"): the translate
// frame's fits give near/far (z along the shared axis is the same from every point of
// the rectangle); each sample then takes the shift that centres the window on target and
// the one grown extent.
std::vector<LightSpace> fit_area_window(const LightSetSpec& set, const std::vector<LightSpec>& specs, const Aabb& b) {
  std::vector<LightSpace> fits;
  fits.reserve(specs.size());
  double near = INFINITY, far = 0;
  for (size_t w = 0; w < specs.size(); ++w) {
    try {
      fits.push_back(LightSpace::fit(specs[w], b));
    } catch (const Error& e) {
      throw Error("light set sample " + std::to_string(w) + " (" + specs[w].to_string() + "): " + e.what());
    }
    near = std::min(near, fits.back().near_plane()), far = std::max(far, fits.back().far_plane());
  }
  // One basis for every sample, bit for bit: the centred spot's (each translated spot's
  // normalize(target - pos) may differ from it in the last bit).
  LightSpec centre = specs[0];
  centre.pos = set.pos, centre.target = set.target;
  const LightSpace first = LightSpace::fit(centre, b);
  const Vec3d U = first.axis_u(), V = first.axis_v(), F = first.forward();
  const double D = dot(set.target - set.pos, F);
  std::vector<std::array<double, 2>> shift(specs.size());
  for (size_t w = 0; w < specs.size(); ++w) {
    const Vec3d r = set.target - specs[w].pos;  // the window's centre seen from the sample
    const double z = dot(r, F);
    shift[w] = {dot(r, U) / z, dot(r, V) / z};
  }
  // The part of the scene the centred spot sees: the scene box clipped to its frustum
  // between near and far, two convex polytopes. Each sample's image coordinate minus its
  // shift is linear-fractional in the point (positive denominator z), so its largest
  // magnitude over that intersection is at one of its vertices; every vertex lies on a
  // face of one polytope inside the other, so clipping each one's six faces by the other's
  // six half-spaces finds them all.
  using Poly = std::vector<Vec3d>;
  struct Half {
    Vec3d n;
    double c;  // inside: dot(n, p) + c >= 0
  };
  auto clip = [](Poly poly, const std::vector<Half>& hs) {
    for (const Half& h : hs) {  // Sutherland-Hodgman
      Poly next;
      for (size_t j = 0; j < poly.size(); ++j) {
        const Vec3d& p = poly[j];
        const Vec3d& q = poly[(j + 1) % poly.size()];
        const double fp = dot(h.n, p) + h.c, fq = dot(h.n, q) + h.c;
        if (fp >= 0) next.push_back(p);
        if ((fp >= 0) != (fq >= 0)) next.push_back(p + (q - p) * (fp / (fp - fq)));
      }
      poly = std::move(next);
    }
    return poly;
  };
  // The box's faces and half-spaces.
  std::vector<Poly> faces;
  std::vector<Half> box_h;
  const double lo[3] = {b.lo.x, b.lo.y, b.lo.z}, hi[3] = {b.hi.x, b.hi.y, b.hi.z};
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2, a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    Poly poly;
    for (int i : {0, 1, 3, 2}) {  // around the face
      double q[3];
      q[axis] = face % 2 ? hi[axis] : lo[axis];
      q[a1] = i & 1 ? hi[a1] : lo[a1];
      q[a2] = i & 2 ? hi[a2] : lo[a2];
      poly.push_back({q[0], q[1], q[2]});
    }
    faces.push_back(poly);
    double e[3] = {0, 0, 0};
    e[axis] = face % 2 ? -1 : 1;
    box_h.push_back({{e[0], e[1], e[2]}, face % 2 ? hi[axis] : -lo[axis]});
  }
  // The centred spot's frustum between near and far: corners and half-spaces.
  const double h0 = first.extent_uv() / 2;
  Vec3d corner[8];
  for (int i = 0; i < 8; ++i) {
    const double z = i & 4 ? far : near;
    corner[i] = set.pos + (F + U * (i & 1 ? h0 : -h0) + V * (i & 2 ? h0 : -h0)) * z;
  }
  const int quads[6][4] = {{0, 1, 3, 2}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 3, 7, 5}};
  std::vector<Half> frustum_h;
  for (const Vec3d& n : {F * h0 - U, F * h0 + U, F * h0 - V, F * h0 + V}) frustum_h.push_back({n, -dot(n, set.pos)});
  frustum_h.push_back({F, -dot(F, set.pos) - near});
  frustum_h.push_back({-F, dot(F, set.pos) + far});
  std::vector<Vec3d> vertices;
  for (const Poly& f : faces)
    for (const Vec3d& p : clip(f, frustum_h)) vertices.push_back(p);
  for (const auto& q : quads)
    for (const Vec3d& p : clip({corner[q[0]], corner[q[1]], corner[q[2]], corner[q[3]]}, box_h)) vertices.push_back(p);
  double need = h0;
  for (const Vec3d& p : vertices)
    for (size_t w = 0; w < specs.size(); ++w) {
      const Vec3d r = p - specs[w].pos;
      const double z = dot(r, F);
      need = std::max({need, std::fabs(dot(r, U) / z - shift[w][0]), std::fabs(dot(r, V) / z - shift[w][1])});
    }
  // A margin far above the rounding of these quotients.
  const double extent = std::max(first.extent_uv(), 2 * need * (1 + 1e-9));
  const double fov = 2 * std::atan(extent / 2) * 180 / kPi;
  if (!(D > 0) || !std::isfinite(extent) || !(fov < 170))
    throw Error("light set " + set.to_string() + ": the window frame needs a field of view of " + std::to_string(fov) +
                " degrees (above 170: the scene reaches too close to the light for the rectangle's size); use "
                "frame=translate");
  std::vector<LightSpace> out;
  out.reserve(specs.size());
  for (size_t w = 0; w < specs.size(); ++w) {
    std::array<double, 18> a = fits[w].to_array();
    const double basis[9] = {U.x, U.y, U.z, V.x, V.y, V.z, F.x, F.y, F.z};
    for (int i = 0; i < 9; ++i) a[3 + i] = basis[i];
    a[12] = extent, a[13] = near, a[14] = far;
    a[15] = shift[w][0], a[16] = shift[w][1], a[17] = fov;
    const std::string bad = LightSpace::check_array(LightKind::spot_window, a);
    if (!bad.empty()) throw Error("light set sample " + std::to_string(w) + " (" + specs[w].to_string() + "): " + bad);
    out.push_back(LightSpace::from_array(LightKind::spot_window, a));
  }
  return out;
}

}  // namespace

LightSet LightSet::fit(const LightSetSpec& spec, const Aabb& bounds) { return fit(spec, bounds, {}); }

LightSet LightSet::fit(const LightSetSpec& spec, const Aabb& bounds, const std::vector<Vec3d>& extent) {
  for (const Vec3d& p : extent)
    if (!(p.x >= bounds.lo.x && p.x <= bounds.hi.x && p.y >= bounds.lo.y && p.y <= bounds.hi.y &&
          p.z >= bounds.lo.z && p.z <= bounds.hi.z))
      throw Error("light set: an extent point lies outside the scene's box");
  if (bounds.empty()) throw Error("light: the scene has no geometry to fit the light to");
  LightSet set;
  set.spec = spec;
  const std::vector<LightSpec> specs = spec.sample_specs();
  if (spec.kind == LightSetKind::sun_path) {
    set.samples =
        spec.sun_frame == SunFrame::ground ? fit_sun_ground(specs, bounds, spec.ground, extent) : fit_sun_path(specs, bounds);
    return set;
  }
  if (spec.area_frame == AreaFrame::window) {
    set.samples = fit_area_window(spec, specs, bounds);
    return set;
  }
  set.samples.reserve(specs.size());
  double near = INFINITY, far = 0;
  for (size_t w = 0; w < specs.size(); ++w) {
    try {
      set.samples.push_back(LightSpace::fit(specs[w], bounds));
    } catch (const Error& e) {
      throw Error("light set sample " + std::to_string(w) + " (" + specs[w].to_string() + "): " + e.what());
    }
    near = std::min(near, set.samples.back().near_plane()), far = std::max(far, set.samples.back().far_plane());
  }
  // One depth range for every sample, so a surface keeps nearly the same depth from slice
  // to slice.
  for (LightSpace& ls : set.samples) {
    std::array<double, 18> a = ls.to_array();
    a[13] = near, a[14] = far;
    ls = LightSpace::from_array(LightKind::spot, a);
  }
  return set;
}

double LightSet::time_of(uint32_t w) const {
  return samples.size() <= 1 ? 0.0 : double(w) / double(samples.size() - 1);
}

}  // namespace st

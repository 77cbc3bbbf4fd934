// Light space (ARCHITECTURE.md "Definitions"). A directional light ("sun") uses an orthographic
// box fitted to the scene; a spot light a perspective frustum. A world point maps to
// (u, v, d): u, v in [0,1) across the map, d in [0,1] linear between near and far
// (for a spot light: linear in distance along the light axis). All math in double.
//
// A windowed spot (LightKind::spot_window, the frame of an area light's samples,
// light_set.hpp "Frames") is a spot whose image plane is sheared: its principal point is
// shifted by (c_u, c_v) in image-plane units (the plane at distance 1 along forward), so
//   u = (dot(p - o, axis_u) / dot(p - o, forward) - c_u) / extent + 0.5   (likewise v)
// and texel (x, y)'s ray has direction forward + axis_u ((u - 0.5) extent + c_u) +
// axis_v ((v - 0.5) extent + c_v): still one origin and a unit forward component, so depth
// is the spot's (linear in distance along the axis between near and far).
//
// Texel (x, y) of a map of level L (R = 2^L) covers [x/R, (x+1)/R) x [y/R, (y+1)/R); its
// ray goes through the texel centre. Lookups use integer texel coordinates computed in
// double, so maps up to 2^20 a side are addressed exactly.
#pragma once
#include <array>
#include <cmath>
#include <cstdint>
#include <string>

#include "tiles/core/vec.hpp"

namespace st {

// sun_ground (a sun-path sample's ground-aligned frame, light_set.hpp "Frames"): texel
// (u, v) indexes a fixed square on a reference plane spanned by axis_u and axis_v (the
// scene's ground), the texel ray runs along the sun's direction `forward` through that
// point, and depth is linear along the ray, measured along n = axis_u x axis_v (down):
// d = ((p - origin) . n - near) / (far - near), the same in every slice for a world
// point. The world -> light map is affine (an oblique projection); rays share one
// direction and t == d, as for an orthographic sun.
// spot_window (an area-light sample's windowed frame, light_set.hpp "Frames"): a spot
// whose principal point is shifted by (c_u, c_v) on its image plane, so every sample of
// the set sees one shared window on the reference plane.
enum class LightKind : uint8_t { sun = 0, spot = 1, sun_ground = 2, spot_window = 3 };

// Light kinds this build reads from files (pack headers, stack grids, EXR attributes), and
// their names ("sun", "spot", "sun-ground", "spot-window"; "unknown" otherwise).
bool light_kind_known(uint8_t kind);
const char* light_kind_name(LightKind kind);
// The bound check_array puts on a windowed spot's shift (c_u, c_v): the window's centre
// within about 89 degrees of the axis.
inline constexpr double kMaxWindowShift = 64;

// Bound on every coordinate and extent of a light read from a file: far above any scene
// (float's precision at 1e18 is 1e11 units), far below float's overflow.
inline constexpr double kMaxLightCoordinate = 1e18;

// What the user asked for: `sun:azimuth=DEG,elevation=DEG[,margin=F]` or
// `spot:pos=X,Y,Z,target=X,Y,Z,fov=DEG`. Parsing throws st::Error naming the bad field.
// A spot_window is never parsed: area light sets make it (light_set.hpp); fit() takes it
// as a spot with the given shift.
struct LightSpec {
  LightKind kind = LightKind::sun;
  double azimuth_deg = 30, elevation_deg = 50, margin = 0.01;  // sun
  Vec3d pos{}, target{};                                      // spot
  double fov_deg = 60;                                        // spot, full angle
  double shift_u = 0, shift_v = 0;                            // spot_window: (c_u, c_v)
  static LightSpec parse(const std::string& text);
  std::string to_string() const;
};

// A texel's ray in world space: p(t) = origin + t * dir, t in [0, 1] spans near..far for
// a sun (so t == d); for a spot, depth_of_t(t) converts.
struct LightRay {
  Vec3d origin, dir;
};

struct LightPoint {
  double u, v, d;
};

class LightSpace {
 public:
  LightSpace() = default;
  // Fits the light box/frustum to `bounds` (the scene's world AABB). Throws st::Error on
  // a zero-extent box, bad angles or a scene behind the spot light.
  static LightSpace fit(const LightSpec& spec, const Aabb& bounds);

  LightKind kind() const { return kind_; }
  const LightSpec& spec() const { return spec_; }

  LightPoint to_light(const Vec3d& world) const;
  // Ray through the centre of texel (x, y) of a map of level `level`.
  LightRay texel_ray(uint32_t level, uint64_t x, uint64_t y) const;
  // Depth of the point at parameter t on a texel ray (sun: d = t).
  double depth_of_t(const LightRay& ray, double t) const;
  // The world point at light coordinates (u, v, d): to_light's inverse (up to rounding):
  // on the ray through image point (u, v), at depth d.
  Vec3d to_world(double u, double v, double d) const;
  // Ground frame (LightKind::sun_ground) and what every parallel-ray light shares.
  // True for sun and sun_ground: every texel ray has one direction and t == d.
  bool parallel() const { return kind_ == LightKind::sun || kind_ == LightKind::sun_ground; }
  // The ray direction per unit of depth distance: sun, spot: forward; sun_ground:
  // forward / (forward . n), whose component along n is 1. texel_ray's origin is
  // origin + axis_u (u E) + axis_v (v E) + ray_axis() * near for both parallel kinds.
  Vec3d ray_axis() const { return kind_ == LightKind::sun_ground ? ray_axis_ : forward_; }
  // The unit axis along which depth distance is measured: sun, spot: forward;
  // sun_ground: n = axis_u x axis_v (texel origins all lie in one plane normal to it).
  Vec3d depth_axis() const { return kind_ == LightKind::sun_ground ? depth_axis_ : forward_; }
  // sun_ground: the smallest sine of the angle between the sun's ray and the reference
  // plane that check_array accepts (about 1 degree; a ray this shallow crosses ~57 times
  // the slab's height horizontally).
  static constexpr double kMinGroundSine = 0.0174524064372835;  // sin(1 degree)

  // Integer texel containing (u, v) at `level`, clamped to the map.
  static std::array<uint64_t, 2> texel_of(uint32_t level, double u, double v);
  // The side, in world units, of one texel of `level` at world point p: the map's width
  // (a parallel light's box side; a perspective light's image-plane width at p's distance
  // from the eye, |p - origin| * extent) divided by 2^level. The one home of this
  // formula: filtered lookups, receiver offsets, the renderers and the client's public
  // LightTransform all call it (so their results agree bit for bit).
  double texel_size(const Vec3d& p, uint32_t level) const {
    // 2^level exactly, as ldexp gives it, without the library call on hot paths.
    const double side = level < 64 ? double(uint64_t(1) << level) : std::ldexp(1.0, int(level));
    return (parallel() ? extent_uv_ : length(p - origin_) * extent_uv_) / side;
  }

  // Basis and extents, for serialization in pack headers.
  // sun: corner of the near plane; spot: eye; sun_ground: corner of the square on the
  // reference plane (near and far are then signed distances along n from that plane).
  Vec3d origin() const { return origin_; }
  Vec3d axis_u() const { return axis_u_; }
  Vec3d axis_v() const { return axis_v_; }
  Vec3d forward() const { return forward_; }
  double extent_uv() const { return extent_uv_; }  // sun: side of the square box
  double near_plane() const { return near_; }
  double far_plane() const { return far_; }
  // spot_window: the principal point's shift (c_u, c_v); {0, 0} for the other kinds.
  std::array<double, 2> window_shift() const { return {spec_.shift_u, spec_.shift_v}; }
  // The ray direction through image point (u, v) of a perspective light (spot or
  // spot_window): unit forward component. What texel_ray returns at texel centres.
  Vec3d perspective_dir(double u, double v) const;

  // Serialized form: 18 doubles + kind; exact round trip. Slots: origin 0-2, axis_u 3-5,
  // axis_v 6-8, forward 9-11, extent 12, near 13, far 14, then sun: azimuth, elevation,
  // margin; spot: azimuth, elevation (unused), fov; spot_window: c_u, c_v, fov.
  std::array<double, 18> to_array() const;
  static LightSpace from_array(LightKind kind, const std::array<double, 18>& a);
  // What is wrong with a serialized light that fit() could never have made, or "" if
  // nothing: a value that is not finite, a coordinate or extent beyond
  // kMaxLightCoordinate (tracers convert to float, and 1e308 overflows there), axes that
  // are not orthonormal (to 1e-6), extent <= 0, near < 0 or far <= near, and spec
  // fields outside what LightSpec::parse accepts; sun_ground (on its own terms): axis_u,
  // axis_v unit and orthogonal, forward unit with forward . (axis_u x axis_v) >=
  // kMinGroundSine, extent > 0, near < far (either may be negative), the ray's reach
  // (far - near) / sine within kMaxLightCoordinate, sun elevation and margin as for sun;
  // spot_window: |c_u|, |c_v| above kMaxWindowShift. Any other kind is refused
  // ("unknown light kind"). Readers of untrusted packs call it
  // before from_array (a NaN light once reached Embree's assertions).
  static std::string check_array(LightKind kind, const std::array<double, 18>& a);

 private:
  LightKind kind_ = LightKind::sun;
  LightSpec spec_{};
  Vec3d origin_{}, axis_u_{1, 0, 0}, axis_v_{0, 0, 1}, forward_{0, -1, 0};
  double extent_uv_ = 1;    // sun: box side; spot: tan(fov/2) * 2 (image plane at 1)
  double near_ = 0, far_ = 1;
  void derive_ground();
  LightPoint to_light_ground(const Vec3d& r) const;
  static std::string check_ground_array(const std::array<double, 18>& a);
  // sun_ground only (derived from the axes in from_array, so a round trip is exact).
  Vec3d ray_axis_{0, -1, 0}, depth_axis_{0, -1, 0};
  double ku_ = 0, kv_ = 0;  // ray_axis . axis_u, ray_axis . axis_v
};

}  // namespace st

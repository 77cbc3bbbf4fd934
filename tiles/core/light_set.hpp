// Light sets: the N light samples of a shadow-map stack (MH 2016 §4, Fig. 7). Slice w of
// the stack is the shadow map of sample w; texel (x, y) of slice w is the ray of sample w
// through that texel (each sample has its own LightSpace, light.hpp).
//
// Syntax (one `--light` argument; LightSetSpec::parse throws st::Error naming the field):
//
//   sun-path:azimuth=A0..A1,elevation=E0..E1,samples=N[,margin=F][,frame=ground|ortho][,ground=Y]
//       A sun moving along a path known in advance (MH §4 "varying light positions"):
//       sample w (w = 0..N-1) is `sun:azimuth=A,elevation=E` with A and E linear in
//       t_w = w / (N - 1) (t_0 = 0 when N = 1), in the frames described below.
//       A0..A1 may run either way (a sun turning west or east) but spans at most 360
//       degrees; E0..E1 may rise or set, both ends in (0, 90]. A single angle `A` means A..A.
//       frame=ground (the default) gives every sample the ground-aligned (oblique) frame,
//       frame=ortho an orthographic box perpendicular to its own direction (below).
//       ground=Y (frame=ground only) puts the reference plane at height Y, inside the
//       scene's box; unset, LightSet::fit takes the box's bottom and a build from a scene
//       (fit_light_set, tiles/bake/stack_build.hpp) the scene's ground: the height of its
//       largest horizontal up-facing area (the city's street level, not its slab's bottom),
//       recorded in the pack's spec as ground=Y.
//
//   area:pos=X,Y,Z,target=X,Y,Z,size=W,H,samples=N[,fov=DEG][,jitter=J][,seed=S]
//        [,frame=window|translate]
//       A W x H rectangle centred on pos, facing target (its axes are the spot light's
//       u and v axes of pos -> target). Sample w is a light at a point of the rectangle
//       looking along the same axis (every sample shares one basis), in the frame below
//       ("Frames": window, the default, or translate). The points are the cells
//       of a 2^g x 2^g grid (the smallest with 4^g >= N) taken in Hilbert-curve order
//       (MH §4 after Ritschel et al. 2007), N of them spread evenly along the curve, so
//       consecutive slices are neighbouring points. jitter J in [0, 1] moves each point
//       uniformly within J times its cell (seeded by S, default 1: the same set every run);
//       J = 0 (default) takes cell centres. fov as for spot lights (default 60).
//
// Frames (why the slices of a stack line up: the octree compresses what neighbouring
// slices share, MH §4).
//
// frame=ground (LightKind::sun_ground, light.hpp): texel (u, v) of every slice indexes one
// fixed square on a horizontal reference plane y = Y (the ground: ground=Y, or the scene
// box's bottom plane lo.y; +Y is up), with
// world-aligned axes u = +X, v = +Z. The ray of texel (u, v) in slice w runs along sample
// w's sun direction through that ground point; depth is linear along it and defined by
// height: d = (top - y) / (top - bottom) with top = hi.y + m H, bottom = lo.y - m H
// (H = hi.y - lo.y, m the margin; a flat scene pads by m times a thousandth of its
// width). So a world point has the same depth in every slice and a point on the ground
// the same texel in every slice: only what stands above the ground moves between slices,
// by (height) x (the change of the sun's horizontal offset cot(E)) instead of angle x r
// for every point. The square is the union over the samples of the scene box (or, from a
// scene, a hull of its geometry: LightSet::fit's `extent`) projected along each sample's
// direction onto the ground, grown by the margin (1 + 2m) and made square about its
// centre. Cost: a sample at elevation E stretches the square by
// H cot(E) along its azimuth, so the texels per metre on the ground fall by
// W / (W + H cot E) against a map of the box's width W alone (city, 25 degrees: H cot E
// = 2.1 H); a sun this low also projects each texel into a longer strip on vertical
// faces. Refused (st::Error, before anything is traced): a square wider than
// kMaxGroundStretch times the scene's largest extent (a sun near the horizon over a
// tall scene: use frame=ortho or raise the lowest elevation); checked per sample, a ray
// within about 1 degree of the ground (LightSpace::kMinGroundSine).
//
// frame=ortho: a sun path's samples all take u = the horizontal axis normal to the
// azimuth (LightSpace::fit's own choice below about 64 degrees of elevation, but without
// its switch of helper axis near the zenith, so the frame never jumps between two
// samples), v = forward x u, and one box size and depth range: the largest any sample needs,
// each box centred on the scene. An area light's samples share the spot basis and one
// near/far range (the union of the samples' fits), in one of the two frames below. Texel size and depth scale are thus the
// same in every slice; what remains is the geometry's own motion (an orthographic sun
// turning by an angle a shifts a point at distance r from the box centre by about a * r).
//
// Area light frames. The reference plane is the plane through `target` perpendicular to
// the axis pos -> target, at distance D from the rectangle (the rectangle is parallel to
// it, so every sample is at distance D).
//   frame=window (default; LightKind::spot_window): every sample's frustum passes through
//       one shared window on the reference plane, centred on target. Sample w at offset
//       (o_u, o_v) from pos is a spot at its point with the basis of pos -> target and its
//       principal point shifted to the window's centre, (c_u, c_v) = the image-plane
//       coordinates of target seen from the sample (= (-o_u, -o_v) / D), and one extent E
//       for every sample: E = 2 tan(fov / 2) (the centred spot's), grown where needed so
//       that every sample's frustum through the window holds what the centred spot sees
//       of the scene box between near and far (that box clipped to its frustum; the
//       largest |image coordinate - shift| over the clipped part's vertices, exact since
//       the coordinate is linear-fractional in the point). A point on the reference plane
//       lands on the same (u, v) in every slice (u = dot(p - pos, axis_u) / (D E) + 0.5,
//       whatever the sample; up to rounding); a point at distance
//       z moves between two samples by their offset times |1/z - 1/D| / E of the image
//       (the translate frame: offset / (z E)), so receivers near the plane read nearly one
//       (x, y) in every slice. A growth beyond a 170-degree field of view (the seen part
//       of the scene reaching up to the light) is refused with a clear error: use
//       frame=translate.
//   frame=translate (LightKind::spot): sample w is the spot light pos -> target translated
//       with its point (its target moves with it), extent E = 2 tan(fov / 2); the whole
//       image shifts by offset / z between samples.
// Depth in both: the spot's (linear in distance along the axis, one near/far for the set).
//
// Bounds: 1 <= N <= kMaxLightSamples. Every number finite, sizes > 0, coordinates within
// kMaxLightCoordinate. A light set the build cannot represent (more samples than the stack
// may hold, a window frame wider than 170 degrees) is refused here, before anything is
// traced.
#pragma once
#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "tiles/core/light.hpp"

namespace st {

// The most samples a stack holds: the stack's w axis is padded to 2^12 (MHOCT.md).
inline constexpr uint32_t kMaxLightSamples = 4096;

enum class LightSetKind : uint8_t { sun_path = 0, area = 1 };
enum class SunFrame : uint8_t { ground = 0, ortho = 1 };  // sun-path frame= ("Frames" above)
// An area light's sample frames (see "Area light frames" above).
enum class AreaFrame : uint8_t { window = 0, translate = 1 };

// frame=ground: the largest ground square, in multiples of the scene box's largest
// extent (with the margin), that a sun path may need.
inline constexpr double kMaxGroundStretch = 8;

struct LightSetSpec {
  LightSetKind kind = LightSetKind::sun_path;
  uint32_t samples = 1;
  // sun-path
  double azimuth0_deg = 0, azimuth1_deg = 0, elevation0_deg = 45, elevation1_deg = 45, margin = 0.01;
  SunFrame sun_frame = SunFrame::ground;
  double ground = std::numeric_limits<double>::quiet_NaN();  // ground=Y; NaN: unset
  // area
  Vec3d pos{}, target{};
  double width = 1, height = 1, fov_deg = 60, jitter = 0;
  uint64_t seed = 1;
  AreaFrame area_frame = AreaFrame::window;

  // True when `text` names a light set (starts with "sun-path:" or "area:"), so a caller
  // can route `--light` to LightSpec::parse or here.
  static bool names_light_set(const std::string& text);
  static LightSetSpec parse(const std::string& text);
  std::string to_string() const;

  // The N per-sample light specs, in slice order (sun-path: sun specs; area: the
  // translate frame's spot specs, whose pos is the sample's point whatever the frame).
  std::vector<LightSpec> sample_specs() const;
};

// The fitted set: one LightSpace per slice.
struct LightSet {
  LightSetSpec spec;
  std::vector<LightSpace> samples;

  // Fits every sample to the scene bounds in the frames above; throws st::Error naming the
  // sample that cannot be fitted.
  static LightSet fit(const LightSetSpec& spec, const Aabb& bounds);
  // The same, where the ground frame's square covers the projections of `extent` (points
  // inside `bounds` whose convex hull holds the scene's geometry; empty: the box's
  // corners) instead of the whole box: the air above the box's upper corners needs no
  // texels (fit_light_set passes a conservative hull per height band).
  static LightSet fit(const LightSetSpec& spec, const Aabb& bounds, const std::vector<Vec3d>& extent);
  uint32_t size() const { return uint32_t(samples.size()); }
  // The time of slice w in [0, 1]: w / (N - 1), 0 for N = 1 (visibility(point, time)).
  double time_of(uint32_t w) const;
};

// Point d (0 <= d < 4^order) of the Hilbert curve over a 2^order x 2^order grid: its cell
// (x, y). Consecutive d are edge-neighbouring cells.
void hilbert_cell(uint32_t order, uint64_t d, uint32_t& x, uint32_t& y);

}  // namespace st

// Receiver-plane depth bias for filtered lookups (PCF at the levels of the hierarchical
// blend, MH 2016 §3.3). A PCF kernel compares every tap with one receiver depth; on a
// surface sloped to the light the taps beside the receiver store the surface's own depth
// at their texels, in front of the receiver on one side, so the kernel shadows the
// receiver's own surface (acne). Worse at a coarse level of the blend: its taps are 2^s
// finest texels apart and an open surface's coarse value (hi = lo, mode finding) is one
// child's own depth anywhere in the coarse texel, so the shadowed fraction grows with
// the level: rings around the camera on sloped ground. Instead, each tap compares the
// receiver's plane extrapolated over the tap's texel (Isidoro 2006, "Shadow mapping: GPU-
// based tips and techniques", receiver plane depth bias): its least depth over the texel,
// so a stored sample of the same plane anywhere in the texel answers lit.
//
// The arithmetic, written once for the CPU evaluators and the GLSL mirror
// (gpu/shaders/st_eval.glsl st_pcf_plane) that answers bit for bit the same:
//
//   input   the receiver's finest texel (fx, fy) at the map's finest level L; `corner`, the
//           plane's depth at that texel's low corner (float); gx, gy: depth per finest
//           texel along x and y (float, clamped by the caller, finite).
//   tap     texel (tx, ty) of level l <= L, s = L - l, its finest span [tx 2^s, (tx+1) 2^s).
//           ox = tx 2^s - fx, plus 2^s where gx < 0 (the texel's end with the least depth);
//           oy likewise; both as float (exact: |o| < 2^24 for L <= 24).
//   depth   (corner + gx * ox) + gy * oy, float, one rounding per operation in this order
//           (no fused multiply-add: the build is ISO C++ with contraction off, the GLSL is
//           `precise`).
//           Zero slopes (both) answer `corner` itself, with no arithmetic.
//   lit     depth <= stored value (the lossless lit test, ARCHITECTURE.md "Definitions").
//
// Float rounding is monotone, so a tap's depth never decreases as ox (oy) moves the way
// gx (gy) rises: over any block of taps the least and greatest depths are those of two
// opposite corner taps (pcf_plane_bounds), which lets kernels count square blocks of taps
// that share a stored value without visiting each.
#pragma once
#include <cstdint>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/light.hpp"

namespace st {

// The steepest receiver plane the lookups take: a slope per texel of at most this many
// texels' depth along the light ray (a surface within about 76 degrees of edge-on to the
// light; steeper ones are taken at this slope, or far taps would lie behind anything).
// The renderer (render/render.cpp filtered_lookup), the shaders (shadowtile.glsl
// kStMaxReceiverSlope) and their CPU twin (tests/gpu/shadow_twins.cpp) use it.
inline constexpr float kMaxReceiverSlope = 4.0f;

// The normal offsets of a filtered lookup's point, in finest-level texels (render.hpp's
// "Receivers and bias"): open surfaces (hi = lo, their own depth) and closed ones.
inline constexpr double kOpenReceiverOffsetTexels = 1.5;
inline constexpr double kClosedReceiverOffsetTexels = 0.5;

struct ReceiverPlane {
  uint64_t fx = 0, fy = 0;  // the receiver's texel of the finest level
  uint32_t finest = 0;      // the map's finest level
  float corner = 0;         // plane depth at (fx, fy)'s low corner
  float gx = 0, gy = 0;     // depth per finest texel along x, y
};

// A filtered lookup of a surface point `pos` with unit normal `normal` (facing the
// light): the lookup point `lp` (pos moved along the normal by kClosedReceiverOffsetTexels
// or kOpenReceiverOffsetTexels finest texels, no more) and its receiver plane: the depth
// slopes per finest texel from the normal through the light's transform (differences of
// to_light over one texel along two surface tangents), each clamped to kMaxReceiverSlope
// times the depth of one texel along the light ray; a degenerate normal gives zero
// slopes. False when lp lies outside the map (lit). The renderer's filtered path
// (render.hpp filtered_lookup) and the client's Map::visibility_filtered with a normal
// call it, so both answer bit for bit alike.
bool receiver_plane_at(const LightSpace& light, uint32_t map_level, const Vec3d& pos, const Vec3d& normal,
                       bool closed, LightPoint& lp, ReceiverPlane& plane);

// The least depth of the receiver's plane over texel (tx, ty) of `level` (<= p.finest).
inline float receiver_plane_depth(const ReceiverPlane& p, uint32_t level, uint64_t tx, uint64_t ty) {
  if (p.gx == 0 && p.gy == 0) return p.corner;  // one receiver depth (Evaluator::pcf)
  const uint32_t s = p.finest - level;
  const int64_t span = int64_t(1) << s;
  const int64_t ox = int64_t(tx << s) - int64_t(p.fx) + (p.gx < 0 ? span : 0);
  const int64_t oy = int64_t(ty << s) - int64_t(p.fy) + (p.gy < 0 ? span : 0);
  const float px = p.gx * float(ox);
  const float along_x = p.corner + px;
  const float py = p.gy * float(oy);
  return along_x + py;
}

// The plane of a map's receiver in the coordinates of one of its trees (a tile): the
// tile's first texel at map level `level` is (x0, y0), and the tile answers that level as
// its own level `rel`. receiver_plane_depth(in_tree, rel, x - x0, y - y0) ==
// receiver_plane_depth(p, level, x, y) bit for bit (the same integer offsets; fx may wrap,
// as int64 it is the offset of the tile's origin from the receiver, negative or not).
inline ReceiverPlane plane_in_tree(const ReceiverPlane& p, uint32_t level, uint32_t rel, uint64_t x0, uint64_t y0) {
  const uint32_t s = p.finest - level;
  ReceiverPlane q = p;
  q.finest = rel + s;
  q.fx = p.fx - (x0 << s), q.fy = p.fy - (y0 << s);
  return q;
}

// How a window walk counts the lit texels of a part [ax, bx] x [ay, by] of one level whose
// texels all answer `value` (a leaf, a missing child, a node with nothing valued below).
// FlatTaps: one receiver depth (Evaluator::pcf), the part at once.
struct FlatTaps {
  float receiver;
  uint32_t count(float value, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by) const {
    return receiver <= value ? uint32_t((bx - ax + 1) * (by - ay + 1)) : 0u;
  }
  bool lit(float value, uint64_t, uint64_t) const { return receiver <= value; }
};

// PlaneTaps: each texel against the receiver plane over it (pcf_on_plane). The part at
// once when the plane's greatest depth over it is lit (all lit) or its least is not (none:
// also a NaN value, which no texel's test passes), the depths of two opposite corners
// (monotone, above): the rule of the shaders' blocks whose corners agree. Else the part is
// halved along its longer side, down to single texels; the plane is flat, so the parts
// that straddle it lie along one line of the window. Bit for bit the count of the
// per-texel tests.
struct PlaneTaps {
  ReceiverPlane p;
  uint32_t level;
  bool flat() const { return p.gx == 0 && p.gy == 0; }
  bool lit(float value, uint64_t x, uint64_t y) const { return receiver_plane_depth(p, level, x, y) <= value; }
  uint32_t count(float value, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by) const {
    const uint32_t area = uint32_t((bx - ax + 1) * (by - ay + 1));
    if (flat()) return p.corner <= value ? area : 0u;
    if (receiver_plane_depth(p, level, p.gx < 0 ? ax : bx, p.gy < 0 ? ay : by) <= value) return area;
    if (!(receiver_plane_depth(p, level, p.gx < 0 ? bx : ax, p.gy < 0 ? by : ay) <= value)) return 0u;
    // Neither: at least two texels (one texel's least and greatest are the same depth).
    if (bx - ax >= by - ay) {
      const uint64_t mx = ax + (bx - ax) / 2;
      return count(value, ax, ay, mx, by) + count(value, mx + 1, ay, bx, by);
    }
    const uint64_t my = ay + (by - ay) / 2;
    return count(value, ax, ay, bx, my) + count(value, ax, my + 1, bx, by);
  }
};

// r x r PCF at texel (x, y) of `level` with each tap compared with receiver_plane_depth of
// its own (clamped) texel: lit taps / (r * r) in float, as Evaluator::pcf. The same as
// eval.pcf_on_plane (which it calls); Evaluator's base implementation is
// pcf_plane_extremes: first the kernel's extreme tap depths through eval.pcf (every tap
// lit at the greatest: 1; none at the least: 0), else tap by tap.
inline float pcf_plane(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                       const ReceiverPlane& p) {
  return eval.pcf_on_plane(level, x, y, r, p);
}
float pcf_plane_extremes(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                         const ReceiverPlane& p);

// The tap-by-tap plane PCF over any stored depths: each tap of the r x r kernel at (x, y)
// of `level` (clamped, pcf_tap) compared with receiver_plane_depth of its own texel,
// depth(tx, ty) the stored value of texel (tx, ty) of `level`; lit taps / (r * r) in float.
// r in [1, Evaluator::kMaxPcf] (the caller clamps). The one loop behind pcf_plane_by_taps
// (an Evaluator), window_pcf_plane and the client's shared lookups at the map's edge, and
// the GPU twin of st_pcf_plane (a client::Map).
template <class Depth>
float pcf_plane_each_tap(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p, Depth&& depth) {
  const uint64_t side = uint64_t(1) << level;
  uint32_t lit = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i) {
      const uint64_t tx = pcf_tap(x, i, r, side), ty = pcf_tap(y, j, r, side);
      lit += receiver_plane_depth(p, level, tx, ty) <= depth(tx, ty) ? 1u : 0u;
    }
  return float(lit) / float(r * r);
}

// The tap-by-tap definition of Evaluator::pcf_on_plane, through depth() alone: the
// reference every shortcut must equal, and the fallback where none applies (the pack
// evaluator outside its tiles, a plane tile's kernel over too many blocks).
float pcf_plane_by_taps(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                        const ReceiverPlane& p);

// pcf_on_plane for a tree with a window walk (tap_batch.hpp WindowDepths, `eval` the same
// object): a kernel with no tap clamped is one count_window_plane; at the map's edge the
// window's depths (depth_window), each tap tested against its own clamped texel. `level`
// is clamped to the tree's levels and x, y to its texels as the encodings' pcf does.
class WindowDepths;
float window_pcf_plane(const WindowDepths& win, uint32_t level, uint64_t x, uint64_t y, uint32_t r,
                       const ReceiverPlane& p);

// pcf_plane's last step alone: every tap's plane depth against its value (depth_region
// squares shared), lit taps / (r * r). For callers that asked the extremes themselves.
float pcf_plane_taps(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p);

// The least and greatest tap depths of the r x r kernel at (x, y) of `level`.
void pcf_plane_bounds(const ReceiverPlane& p, uint32_t level, uint64_t x, uint64_t y, uint32_t r, float& least,
                      float& greatest);

// Evaluator::pcf_footprint with pcf_plane at both levels: (u, v) in [0, 1) is the
// receiver's light-space position (its finest texel is p.fx, p.fy).
float pcf_footprint_plane(const Evaluator& eval, double u, double v, const ReceiverPlane& p, float footprint,
                          uint32_t r);

}  // namespace st

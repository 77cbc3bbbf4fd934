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

namespace st {

// The steepest receiver plane the lookups take: a slope per texel of at most this many
// texels' depth along the light ray (a surface within about 76 degrees of edge-on to the
// light; steeper ones are taken at this slope, or far taps would lie behind anything).
// The renderer (render/render.cpp filtered_lookup), the shaders (shadowtile.glsl
// kStMaxReceiverSlope) and their CPU twin (gpu/shadow_reference.cpp) use it.
inline constexpr float kMaxReceiverSlope = 4.0f;

struct ReceiverPlane {
  uint64_t fx = 0, fy = 0;  // the receiver's texel of the finest level
  uint32_t finest = 0;      // the map's finest level
  float corner = 0;         // plane depth at (fx, fy)'s low corner
  float gx = 0, gy = 0;     // depth per finest texel along x, y
};

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

// r x r PCF at texel (x, y) of `level` with each tap compared with receiver_plane_depth of
// its own (clamped) texel: lit taps / (r * r) in float, as Evaluator::pcf. Exact for any
// evaluator: first the kernel's extreme tap depths through eval.pcf (every tap lit at the
// greatest: 1; none at the least: 0), else tap by tap.
float pcf_plane(const Evaluator& eval, uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p);

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

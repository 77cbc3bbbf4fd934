// Exit-depth counting of one texel ray (MH §3 and §3.1; voxel paper §6.1 "closed
// objects"), apart from any ray tracer: the tracer offers every candidate hit of a
// traversal, the counter says which to accept, and between traversals it says whether
// the ray goes on and over which t range. No Embree here, so the state machine is tested
// on synthetic hit sequences.
//
// The interval of a ray:
//   lo = t of the first hit (the ordinary shadow map),
//   hi = t where the ray leaves all closed objects again.
// Counting: front faces +1, back faces -1, stop when the counter is back to 0 (MH §3);
// one counter per closed mesh (voxel §6.1 counts per pixel so that intersecting closed
// objects work), so a ray inside mesh A that crosses an edge of a nested mesh B (where a
// watertight traversal may report two triangles) can never make A look exited.
//
// Hits are taken in groups of exactly equal t: one traversal gathers every primitive at
// the smallest t not yet processed (offer() accepts a smaller t, records an equal one and
// rejects it so that the traversal goes on reporting the others), the next traversal
// starts at that t and excludes every primitive already processed, by id. No epsilon
// steps, so coplanar faces and faces touching at one t are handled, and a primitive
// reported twice counts once. Within a group a mesh contributes the sign of the sum of
// its facings, in {-1, 0, +1}: two triangles of one mesh met at a shared edge count once,
// a silhouette edge (front + back) counts zero.
//
// Touching faces (a building standing on the ground slab): a tracer's float t of two
// coplanar faces may differ by an ulp either way, and its box culling can hide a hit an
// ulp below the accepted one. So later traversals start kBackoff * (t range) before the
// last group (ids exclude what was processed), and when the counters reach 0 on an exit
// face that may touch another mesh (ClosedFaces::touchable) a look-ahead traversal over
// exit +- kLookAhead * (t range) gathers the unprocessed closed hits; one counts as
// touching only when its exact ray-plane t in double is within kTouchDouble * (t range)
// of the exit's.
//
// Conservative fallbacks (hi = lo, fell_back()): the first closed hit would make a
// counter negative (a back face first, inverted winding), any counter would go negative
// later, the ray leaves the scene with a counter > 0, or a per-ray table overflows (more
// than kMaxGroup hits at one t, kMaxDone primitives, kMaxMeshes meshes entered,
// kMaxTraversals traversals). A first group without closed hits (open geometry) or one
// that enters nothing (a grazing touch) gives hi = lo without a fallback. Open surfaces
// met while inside a closed object are ignored. No hit: lit (kLitDepth, [1, 1]).
//
// Float arithmetic: every t is the tracer's float; the t ranges of later traversals are
// float expressions of it; only the touching test uses double. The counting decides
// which groups are the first hit and the exit; the stored depths are then the canonical
// depths of those primitives (canonical_depth.hpp; exit_prim() names the exit's faces).
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/vec.hpp"

namespace st {

// How a closed face meets the texel rays. Under a sun every ray has one direction, so the
// facing is known per face; under a spot it depends on the ray.
enum class Facing : uint8_t { front = 0, back = 1, edge_on = 2, per_ray = 3 };

// What the counting reads of each closed primitive, indexed by its id among the closed
// primitives (the tracer's primitive id of its closed geometry).
struct ClosedFaces {
  std::vector<uint32_t> info;        // mesh << 2 | Facing: one 4-byte read per counted hit
  std::vector<Vec3d> normal;         // geometric normal, outwards (double)
  std::vector<double> plane;         // dot(normal, v0 - origin of the recentred frame)
  // 1 when a closed face of another mesh may lie in the same plane facing the other way
  // (a possible touching contact); exits through the others need no look-ahead.
  std::vector<uint8_t> touchable;

  void add(uint32_t mesh, Facing facing, const Vec3d& outward_normal, double plane_offset) {
    info.push_back(mesh << 2 | uint32_t(facing));
    normal.push_back(outward_normal);
    plane.push_back(plane_offset);
  }
  size_t size() const { return info.size(); }
  uint32_t mesh(uint32_t prim) const { return info[prim] >> 2; }
  // +1 entering, -1 leaving, 0 edge-on, for a ray of direction `dir`.
  int32_t facing(uint32_t prim, const Vec3d& dir) const {
    const uint32_t code = info[prim] & 3;
    if (code != uint32_t(Facing::per_ray)) return code == 0 ? 1 : (code == 1 ? -1 : 0);
    const double f = dot(normal[prim], dir);
    return f < 0 ? 1 : (f > 0 ? -1 : 0);  // against the outward normal: entering
  }
  // Exact ray parameter of the face's plane (double, recentred origin).
  double plane_t(uint32_t prim, const Vec3d& origin, const Vec3d& dir) const {
    const Vec3d& n = normal[prim];
    return (plane[prim] - dot(n, origin)) / dot(n, dir);
  }
};

// The counting state of one texel ray. Protocol:
//   start(...); traverse [t_min, t_max] offering every candidate hit;
//   if something was accepted and first_traversal_done():
//     do traverse [tnear(), tfar()] offering every candidate hit; while (traversal_done());
//   interval(light) (or lo_t(), hi_t()), fell_back().
// A first-hit trace (no counting) calls take_first_hit(t) instead.
//
// Plain data until start(): a packet of rays keeps one per lane on the stack, and
// clearing the tables for every packet would cost trace time for nothing.
class ExitDepthRay {
 public:
  static constexpr float kNoHit = std::numeric_limits<float>::infinity();
  // Per-ray table bounds; exceeding one makes the ray fall back to hi = lo.
  static constexpr uint32_t kMaxGroup = 16;       // hits at one exactly equal t
  static constexpr uint32_t kMaxDone = 48;        // primitives processed on one ray
  static constexpr uint32_t kMaxMeshes = 16;      // closed meshes entered on one ray
  static constexpr uint32_t kMaxTraversals = 64;  // traversals of one ray
  // Fractions of the ray's t range: how far before the last group a traversal starts,
  // how far around an exit the look-ahead searches (wide enough for the float error of
  // big triangles), and how close in exact t a face must be to touch the exit.
  static constexpr float kBackoff = 16.0f / (1 << 24);
  static constexpr float kLookAhead = 1.0f / (1 << 13);
  static constexpr double kTouchDouble = 1e-9;

  // A new ray from `origin` (recentred, double) along `dir`, traced over [t_min, t_max];
  // `faces` must outlive the ray. The first traversal covers the whole range.
  void start(const ClosedFaces& faces, const Vec3d& origin, const Vec3d& dir, float t_min,
             float t_max);

  // One candidate hit during a traversal: true accepts it (the traversal then looks only
  // at t up to this one), false rejects it (the traversal goes on as if it were not
  // there). Call it for every candidate, including those at the current best t.
  bool offer(float t, bool closed, uint32_t prim) {
    const uint64_t key = key_of(closed, prim);
    if (contains(done_, n_done_, key)) return false;
    if (window_) {  // look-ahead: record every unprocessed hit, accept none
      record(key);
      return false;
    }
    if (t < best_t_) {
      best_t_ = t;
      group_[0] = key;
      n_group_ = 1;
      overflow_ = false;
      return true;
    }
    if (t == best_t_) record(key);
    return false;
  }

  // After the first traversal, which accepted a hit. True: trace again over
  // [tnear(), tfar()]; false: the interval is final.
  bool first_traversal_done();
  // After each later traversal (whether or not it accepted a hit); same answer.
  bool traversal_done();
  float tnear() const { return tnear_; }
  float tfar() const { return tfar_; }

  // First-hit trace: the interval is [t, t].
  void take_first_hit(float t) { lo_t_ = hi_t_ = t; }

  bool hit() const { return lo_t_ != kNoHit; }
  float lo_t() const { return lo_t_; }  // kNoHit when nothing was hit
  float hi_t() const { return hi_t_; }
  bool fell_back() const { return fell_back_; }
  // The closed primitives of the group where the counters reached 0 (the exit faces),
  // valid when hi_t() > lo_t(); the tracer evaluates their canonical depth.
  uint32_t exit_count() const { return n_exit_; }
  uint32_t exit_prim(uint32_t k) const { return exit_[k]; }
  // The texel's depths: [kLitDepth, kLitDepth] without a hit, else both t mapped to
  // depth (depth_of_t) with lo <= hi.
  Interval interval(const LightSpace& light) const;

 private:
  static uint64_t key_of(bool closed, uint32_t prim) {
    return (uint64_t(closed ? 0 : 1) << 32) | prim;
  }
  static bool is_closed(uint64_t key) { return (key >> 32) == 0; }
  static bool contains(const uint64_t* keys, uint32_t n, uint64_t key) {
    for (uint32_t i = 0; i < n; ++i)
      if (keys[i] == key) return true;
    return false;
  }
  void record(uint64_t key) {
    if (contains(group_, n_group_, key)) return;
    if (n_group_ < kMaxGroup) group_[n_group_++] = key;
    else overflow_ = true;
  }
  bool apply_group(uint32_t& closed_hits);
  void mark_group_done();
  void prepare_traversal();
  void record_exit_group() {
    n_exit_ = 0;
    for (uint32_t k = 0; k < n_group_; ++k)
      if (is_closed(group_[k])) exit_[n_exit_++] = uint32_t(group_[k]);
  }

  const ClosedFaces* faces_;
  Vec3d origin_, dir_;
  float t_min_, t_max_;
  float backoff_, look_ahead_;  // kBackoff, kLookAhead times the t range
  double touch_;                // kTouchDouble times the t range

  // What the current traversal gathers: the smallest unprocessed t and every primitive
  // hit at exactly that t (or, in a look-ahead, every unprocessed hit in the window).
  float best_t_;
  bool window_, overflow_;
  uint32_t n_group_, n_done_;
  uint64_t group_[kMaxGroup];
  uint64_t done_[kMaxDone];  // primitives of earlier groups: never counted twice

  // Counting: one counter per closed mesh entered, and their sum.
  uint32_t n_mesh_;
  int32_t total_;
  uint32_t mesh_[kMaxMeshes];
  int32_t count_[kMaxMeshes];

  float lo_t_, hi_t_;
  float floor_t_;  // t of the last group: the next traversal starts just below it
  float exit_t_;   // float t where the counters reached 0, while a look-ahead is due
  double exit_d_;  // its exact t (the largest plane t of the exit's closed hits)
  uint32_t exit_[kMaxGroup];  // closed primitives of the exit group
  uint32_t n_exit_;
  uint32_t traversals_;
  bool fell_back_;
  float tnear_, tfar_;
};

// Depth of ray parameter t: t itself under a sun (either frame), (t - near) / (far - near) under a spot,
// in double, clamped to [0, 1], then float.
inline float depth_of_t(const LightSpace& light, float t) {
  double d = light.parallel()
                 ? double(t)
                 : (double(t) - light.near_plane()) / (light.far_plane() - light.near_plane());
  return float(std::clamp(d, 0.0, 1.0));
}

// Defined here, like offer(), because the tracer calls them once per texel.
inline void ExitDepthRay::start(const ClosedFaces& faces, const Vec3d& origin, const Vec3d& dir,
                                float t_min, float t_max) {
  faces_ = &faces;
  origin_ = origin;
  dir_ = dir;
  t_min_ = t_min;
  t_max_ = t_max;
  backoff_ = kBackoff * (t_max - t_min);
  look_ahead_ = kLookAhead * (t_max - t_min);
  touch_ = kTouchDouble * (double(t_max) - t_min);
  best_t_ = kNoHit;
  window_ = overflow_ = false;
  n_group_ = n_done_ = 0;
  n_mesh_ = 0;
  total_ = 0;
  lo_t_ = hi_t_ = exit_t_ = kNoHit;
  floor_t_ = 0;
  exit_d_ = -INFINITY;
  traversals_ = 1;
  n_exit_ = 0;
  fell_back_ = false;
  tnear_ = t_min;
  tfar_ = t_max;
}

inline Interval ExitDepthRay::interval(const LightSpace& light) const {
  if (lo_t_ == kNoHit) return Interval{kLitDepth, kLitDepth};
  Interval iv;
  iv.lo = depth_of_t(light, lo_t_);
  iv.hi = std::max(iv.lo, depth_of_t(light, hi_t_));
  return iv;
}

}  // namespace st

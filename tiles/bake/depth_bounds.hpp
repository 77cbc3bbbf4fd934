// Dual depth bounds with Embree 3 (MH §3 and §3.1; voxel paper §6.1 "closed objects").
//
// For each texel of a map of level L the ray from the light through the texel centre
// (LightSpace::texel_ray) gives an Interval:
//   lo = depth of the first hit (the ordinary shadow map),
//   hi = depth where the ray leaves all closed objects again.
// A scene without triangles is valid and traces to [1, 1] everywhere (the caller fits the
// light).
//
// Definition: (lo, hi) are the canonical coverage and hit list of canonical_coverage.hpp
// (which triangles a texel ray hits, decided in double by signed Plücker edge tests; the
// sorted hit list reduced by exit counting per closed mesh) with the canonical depth of
// canonical_depth.hpp, hits taken with t in [0, 1] (sun) or [near, far] (spot). Embree
// only finds candidates: every triangle is a user primitive whose box provably holds a
// point of every texel ray the definition covers (depth_bounds.cpp states the bound), the
// intersect callback runs the definition and never accepts, so one traversal of the whole
// ray sees every candidate. The light-space rasterizer (raster_bounds.hpp, sun lights)
// evaluates the same definition, so the two builders agree bit for bit on every texel,
// and any batching (packet shape, region) gives the same bits. A triangle so thin or so
// nearly edge-on that the bound cannot confine it (its edge errors add up to a quarter
// of its projected area) gets a wider box instead (wide_candidates(): under a sun, a slab
// around its plane; under a spot light, every ray).
//
// The baseline modes (first_hit, bounds_tracer_t) trace Embree's float triangles with the
// exit counting of exit_depth.hpp, as before the canonical coverage; their scene is built
// on first use.
//
// Precision: vertices are recentred on the scene AABB centre in double, and texel rays
// are transformed the same way, so a scene offset by 1e7 traces like the same scene at
// the origin.
//
// Thread safety: the constructor builds the Embree scene once; trace() is const and may
// be called concurrently from several threads (each call also parallelises internally
// with TBB over blocks of rows; 8-wide coherent packets on 2x4 texel blocks).
// Errors: st::Error for non-finite vertices, bad indices, bad regions, Embree failures.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>

#include "scene/scene.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"

namespace st {

struct DepthBoundsStats {
  uint64_t texels = 0;      // texels traced
  uint64_t rays = 0;        // texel rays (== texels)
  uint64_t traversals = 0;  // Embree traversals, counted per active ray lane
  uint64_t hits = 0;        // texels with a first hit (lo < kLitDepth or hit at 1)
  uint64_t closed = 0;      // texels with hi > lo
  uint64_t fallbacks = 0;   // texels where counting was not trusted (hi = lo)
  double seconds = 0;       // wall time of the call

  DepthBoundsStats& operator+=(const DepthBoundsStats& o);
};

enum class TraceMode : uint8_t {
  bounds,     // canonical lo and hi (hi = lo everywhere when the scene has no closed mesh)
  first_hit,  // plain shadow map of the tracer's float t: one traversal per ray, hi = lo
              // (benchmark baseline; not canonical)
  bounds_tracer_t,  // lo and hi from the tracer's float t, as before the canonical depth
                    // (benchmark baseline only: depends on the batching)
  static_bounds,    // bounds, and where the first hit is open (hi = lo, no fallback) hi
                    // reaches to just below the next depth of the canonical hit list above
                    // lo, or 1 if none (the static-geometry interval, voxel paper §6.1)
};

// How texels are batched into Embree queries. Every shape gives bit-identical canonical
// bounds (canonical_depth.hpp); x4y2 (rtcIntersect8 on 4 x 2 texels) is the fastest.
enum class PacketShape : uint8_t { single, x4y1, x4y2, x8y1, x4y4, x16y1 };

struct TraceRegion {
  uint32_t level = 0;  // map of 2^level texels a side, level <= kMaxLevel
  uint64_t x0 = 0, y0 = 0;
  uint32_t width = 0, height = 0;
};

class DepthBoundsTracer {
 public:
  // The largest region one call traces (8192^2 texels: 512 MiB of intervals).
  static constexpr uint64_t kMaxRegionTexels = uint64_t(8192) * 8192;

  // Builds the Embree scene of candidate boxes. Throws st::Error.
  DepthBoundsTracer(const Scene& scene, const LightSpace& light);
  ~DepthBoundsTracer();
  DepthBoundsTracer(const DepthBoundsTracer&) = delete;
  DepthBoundsTracer& operator=(const DepthBoundsTracer&) = delete;

  // False when the scene has no closed mesh: exit depths are never traced (hi = lo).
  bool traces_exit_depths() const;
  double build_seconds() const;
  uint64_t triangle_count() const;
  // Triangles with a wider box than their own grown one (see above).
  uint64_t wide_candidates() const;

  // Traces a rectangular region of the level-`region.level` map. Throws st::Error when
  // the region is empty, leaves the map or exceeds kMaxRegionTexels. If `progress` is
  // given, the number of finished texels is added to it as rows complete (another
  // thread may poll it). `stats`, if given, receives this call's figures.
  IntervalTile trace(const TraceRegion& region, TraceMode mode = TraceMode::bounds,
                     DepthBoundsStats* stats = nullptr,
                     std::atomic<uint64_t>* progress = nullptr,
                     PacketShape packet = PacketShape::x4y2) const;

  // Checks a region against the map and the size limit (same messages as trace()).
  static void check_region(const TraceRegion& region);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace st

// A light-space rasterizer of canonical depth bounds (MH §3.1; the GPU construction of
// MH §5 bins and rasterizes the same way): its output is the canonical coverage and
// hit-list -> (lo, hi) function of canonical_coverage.hpp on every texel, bit for bit,
// so any region shape gives the same bits and any evaluator of the definition agrees.
//
// How (raster_bounds.cpp):
//   - once, at construction: per triangle the recentred double vertices, the canonical
//     plane, the three directed edges' Plücker coefficients (edge value = C + o . N,
//     affine in the ray origin o for the sun's fixed direction) with a bound on how far
//     that fast value and the definition's own double evaluation can both be from the
//     exact value; and a uniform grid over light space (u, v) of the triangles' boxes;
//   - per region: the grid gives the candidate triangles, each is binned to the 16 x 16
//     texel tiles its conservative texel box touches; a tile with nothing in its
//     light-space prism stays lit ([1, 1]) without per-texel work;
//   - per tile (TBB): the texel origins once (as LightSpace::texel_ray computes them),
//     then each triangle visits only the row spans of its box where its edge values,
//     affine in the texel, may still admit coverage (the sign a covered texel's edges
//     share is known per triangle), classified by a branch-free loop; an edge whose fast
//     value lies beyond the bound has the definition's sign, otherwise the texel is
//     decided by the definition itself (canonical_cover);
//     covered texels append (t, triangle) to per-texel fragment lists held in per-thread
//     scratch (nothing is allocated per texel once the scratch has grown), which are
//     sorted and reduced by canonical_interval(). A tile without closed triangles keeps
//     only the nearest hit.
//
// Scope: sun lights (parallel texel rays: orthographic or the ground frame's sheared
// map, whose origins are affine in the texel too), the closed-object interval rule
// (TraceMode::bounds) and the static-geometry rule (TraceMode::static_bounds: where the
// reduced interval is open, hi reaches to just below the next depth of the texel's hit
// list, exactly as the tracer does; tiles without closed triangles keep only the nearest
// depth and the next larger one); a spot light is refused with st::Error (the Embree
// tracer handles it).
// Assumption shared with every binning rasterizer: the definition's double evaluation
// never covers a texel centre more than a texel outside the triangle's light-space box
// (it would take edges shorter than about 1e-9 of the scene at level 20).
// Thread safety: trace() is const and may run concurrently; it parallelises over tiles.
// Errors: st::Error for bad indices, non-finite vertices, spot lights, bad regions.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "tiles/bake/depth_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"

namespace st {

// Per-tile skip of the coverage work (MH 2016 §3.1; voxel shadows 2014 §6.1, closed
// objects). Edge values and plane depths are affine in the texel origin, so their values
// at a binning tile's four corner texels (with the error bounds) decide, for the whole
// tile, whether a candidate covers every texel centre, misses every one, or neither:
//   exact:  a tile whose every candidate covers it or misses it (inside one surface, or a
//           stack of them: roofs, walls, slabs, flat terrain, open or closed) builds each
//           texel's hit list from the covering triangles' planes without edge tests and
//           reduces it as the full path does: the same bits as `off`;
//   narrow: also, a tile whose hit lists are provably exactly (F entering, B leaving) of
//           one closed mesh, every other candidate missing the tile or lying beyond (open:
//           after F; closed: beyond B's exit and its touching window), gets one interval
//           [a, b]: a = F's largest depth over the tile, b = B's smallest (conservative),
//           when a <= b (else as exact). [a, b] lies inside every texel's true (lo, hi), so
//           a hierarchy built from it keeps the lossless invariant against the true
//           intervals, but stored intervals may differ from an unnarrowed build's (the pack
//           records intervals_narrowed=yes). Open geometry is never narrowed.
//   static: under TraceMode::static_bounds, narrow and regions also prove an open layer:
//           the live candidates whose depths are not provably beyond the nearest one's
//           (a roof, the ground between buildings; any meshes, open, one facing) cover
//           every texel centre exactly once (the patch proof below) and every other
//           candidate lies beyond the layer's largest depth. Each texel's first hit is
//           then a layer member, open, and the next larger depth comes from the others,
//           so [largest layer depth, just below the others' smallest depth] (or 1 when
//           none can be hit) lies inside every texel's static interval.
//   regions: narrow, and a build (map_build.hpp) builds each cell's hierarchy top-down
//           over square regions: a region that region_interval() proves (all lit, or
//           one closed mesh's F and B) becomes one node without per-texel work, any other
//           splits in four down to kRegionLeafSide, rasterized as under narrow. Work then
//           grows with the length of the edges between surfaces in light space, not the
//           texel count; intervals are narrowed as under narrow.
//   off:    every tile through the full coverage path.
enum class RasterSkip { off, exact, narrow, regions };
const char* to_string(RasterSkip s);                  // "off", "exact", "narrow", "regions"
RasterSkip parse_raster_skip(const std::string& text);  // st::Error naming the text

class RasterBounds {
 public:
  static constexpr uint32_t kTile = 16;  // texels a side of a binning tile

  // `mode`: TraceMode::bounds or TraceMode::static_bounds (else st::Error).
  RasterBounds(const Scene& scene, const LightSpace& light, RasterSkip skip = RasterSkip::exact,
               TraceMode mode = TraceMode::bounds);
  ~RasterBounds();
  RasterBounds(const RasterBounds&) = delete;
  RasterBounds& operator=(const RasterBounds&) = delete;

  // False when the scene has no closed mesh (hi = lo everywhere).
  bool traces_exit_depths() const;
  double setup_seconds() const;  // the per-triangle setup and the grid
  uint64_t triangle_count() const;
  RasterSkip skip() const;
  TraceMode mode() const;
  // Texels filled by the skip path over every trace() call so far (all threads).
  uint64_t skipped_texels() const;

  // Bounds of a region (same limits and messages as DepthBoundsTracer::check_region).
  // `progress`, if given, gets the finished texels added as tiles complete; `stats` this
  // call's figures (rays = texels; traversals counts triangle-texel tests).
  IntervalTile trace(const TraceRegion& region, DepthBoundsStats* stats = nullptr,
                     std::atomic<uint64_t>* progress = nullptr) const;
  // One interval inside every texel's true (lo, hi) over the square region of `side`
  // texels at (x0, y0) of `level`, when the region's four corner texels prove it (the
  // narrow test above, on the region instead of a binning tile; the coverage and depth
  // arguments hold on any square of texel centres): [1, 1] where every triangle misses
  // every texel centre (all lit: exactly the definition's interval), else the narrow
  // [a, b] of one closed mesh's entry F and exit B. std::nullopt when neither is proven.
  // Costs one candidate gathering and a corner test per candidate, no per-texel work:
  // what lets a build skip whole regions (MapBuildOptions::raster_skip == regions).
  std::optional<Interval> region_interval(uint32_t level, uint64_t x0, uint64_t y0, uint64_t side) const;

  // Reference: the same definition on one texel with every triangle as a candidate,
  // straight from canonical_coverage.hpp (no setup, no bounds, no binning), under mode().
  Interval brute_force_texel(uint32_t level, uint64_t x, uint64_t y) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace st

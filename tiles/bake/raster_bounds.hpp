// A light-space rasterizer of canonical depth bounds (MH §3.1; GPU construction MH §5):
// triangles are binned to screen tiles of texels by a conservative light-space box, and
// on every texel a triangle may cover the canonical coverage predicate and the canonical
// hit-list -> (lo, hi) function (canonical_coverage.hpp) are evaluated. Its output is a
// function of (scene, light, level, x, y) alone, so any region shape gives bit-identical
// bounds and any evaluator of the same definition agrees bit for bit.
//
// Scope: sun lights (parallel texel rays); a spot light is refused with st::Error.
// Vertices and rays are recentred on the scene AABB centre in double.
// Thread safety: trace() is const; it parallelises over tiles with TBB.
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/scene.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"

namespace st {

class RasterBounds {
 public:
  static constexpr uint32_t kTile = 16;  // texels a side of a binning tile

  RasterBounds(const Scene& scene, const LightSpace& light);

  // Bounds of a region (same limits and messages as DepthBoundsTracer::check_region).
  IntervalTile trace(const TraceRegion& region) const;
  // Reference: the same definition on one texel with every triangle as a candidate.
  Interval brute_force_texel(uint32_t level, uint64_t x, uint64_t y) const;

 private:
  Interval texel(uint32_t level, uint64_t x, uint64_t y, const uint32_t* cand, size_t n) const;

  LightSpace light_;
  Vec3d centre_;
  std::vector<Vec3d> v_;                       // recentred vertices
  std::vector<std::array<uint32_t, 3>> tri_;   // triangle vertex indices
  std::vector<uint32_t> mesh_;                 // mesh of each triangle
  std::vector<uint8_t> closed_;                // 1 when its mesh is closed
  std::vector<std::array<double, 4>> box_;     // light-space u0, v0, u1, v1
};

}  // namespace st

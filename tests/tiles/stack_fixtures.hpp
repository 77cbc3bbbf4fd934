// Interval stacks for the shadow-map stack tests (MH 2016 §4): random, coherent and
// traced ones, the lossless check over every texel of every slice, and a pack's round trip
// against its octree.
#pragma once
#include <cstdint>
#include <string>

#include "tiles/encode/mh_octree_build.hpp"
#include "tiles/core/light_set.hpp"

namespace st::stacks {

// Independent random intervals in [0, 1] (a third of them zero-width, some [1, 1]).
IntervalStack random_stack(uint32_t level, uint32_t slices, uint64_t seed);
// A few boxes whose shadows slide slowly with w over a ground plane: neighbouring slices
// differ in a few texels, as a sun path's do.
IntervalStack coherent_stack(uint32_t level, uint32_t slices, uint64_t seed);
// Dual depth bounds of `scene` under every sample of `set` (DepthBoundsTracer).
IntervalStack traced_stack(const std::string& scene, const LightSet& set, uint32_t level);
LightSet fitted_set(const std::string& scene, const std::string& light_set);
// One slice as a 2D tile.
IntervalTile slice(const IntervalStack& s, uint32_t w);

// "" when depth(x, y, w) lies in the stack's interval on every texel of every slice, else
// the first failure.
template <class F>
std::string first_violation(const IntervalStack& s, F&& depth) {
  for (uint32_t w = 0; w < s.slices; ++w)
    for (uint64_t y = 0; y < s.side(); ++y)
      for (uint64_t x = 0; x < s.side(); ++x) {
        const Interval& iv = s.at(x, y, w);
        const float v = depth(x, y, w);
        if (!(iv.lo <= v && v <= iv.hi))
          return "texel (" + std::to_string(x) + ", " + std::to_string(y) + ") of slice " + std::to_string(w) +
                 ": " + std::to_string(v) + " outside [" + std::to_string(iv.lo) + ", " + std::to_string(iv.hi) + "]";
      }
  return "";
}

// A stack pack's round trip against its octree: "" when map.depth(x, y, w, level) (a
// StackMap read back from the pack) equals the uncut octree's depth_at at every level of every
// slice, else the first difference.
template <class Map>
std::string first_octree_difference(const OctHierarchy& h, const Map& map) {
  const moct::Geometry& g = h.geo;
  for (uint32_t level = 0; level <= g.n; ++level) {
    const uint32_t T = g.level_of_xy(level);
    for (uint32_t w = 0; w < h.slices; ++w)
      for (uint64_t y = 0; y < (uint64_t(1) << level); ++y)
        for (uint64_t x = 0; x < (uint64_t(1) << level); ++x) {
          const float got = map.depth(x, y, w, level), want = h.depth_at(T, x, y, w >> (g.k - g.w_bits(T)));
          if (!(got == want))
            return "level " + std::to_string(level) + " texel (" + std::to_string(x) + ", " + std::to_string(y) +
                   ") slice " + std::to_string(w) + ": " + std::to_string(got) + ", the octree " + std::to_string(want);
        }
  }
  return "";
}

bool small_scale();

}  // namespace st::stacks

// Lookups in a shadow-map stack (MH 2016 §4): a world point against the slices of an
// MhOctree, each slice in its own sample's light space (LightSet).
//
// Contract:
// - lit(p, w): the lit test of slice w at the finest level (receiver depth r of p in
//   sample w's light space, rounded to float once; lit iff r <= depth), (u, v) clamped
//   to the map as in the 2D evaluator. Lossless: for a receiver outside every object it
//   is the test of the uncompressed map of sample w (ARCHITECTURE.md "Lossless invariant").
// - visibility(p, time): time in [0, 1] (clamped; NaN reads as 0) runs over the samples,
//   sample w at time w / (N - 1) (LightSet::time_of). With s = time * (N - 1), a = floor(s),
//   f = s - a: (1 - f) * lit(p, a) + f * lit(p, a + 1). Exact at the samples: where s is
//   within 1e-9 of an integer w, the result is lit(p, w) alone (0 or 1). Between samples it
//   blends linearly, so a sun moving through time never pops. An area light's "time" is
//   just its Hilbert order.
// - soft_visibility(p): the fraction of the N samples that are lit, exactly
//   (lit samples) / N in float, equal to the average of lit(p, w) over w (tested). The
//   samples share the walk (MhOctree::depth_along): each starts from the deepest node its
//   path has in common with the previous sample's (MH §3.3's lowest common node and
//   last-sample cache, carried over w). Neighbouring samples (trajectory or Hilbert order)
//   are neighbouring slices, and where a node (a leaf, or a node without the child the path
//   needs) answers for all the w under it, the next samples are answered by that node
//   without reading anything new. The samples' texels come a run of up to 32 at a time
//   from SampleTexels (sample_texels.hpp), lit()'s transform bit for bit.
//
// Thread safety: const lookups; noexcept, no allocation. The octree and the light set are
// borrowed and must outlive the lookup.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "tiles/core/light_set.hpp"
#include "tiles/core/mh_octree.hpp"
#include "tiles/core/sample_texels.hpp"

namespace st {

// Per-node bounds of the values stored in an octree node's subtree (its own value if it
// has one, and every value below; an empty node's texels may also read the value it
// inherits, which the lookup adds), computed by one walk when made: 8 bytes
// per tree word, not stored in the format. They let a lookup stop at the first node
// where a receiver depth lies at or below every such value (lit) or above all of them
// (shadowed): StackLookup::soft_visibility_bounded. Throws nothing but std::bad_alloc.
class StackBounds {
 public:
  explicit StackBounds(const MhOctree& octree);
  struct Range {
    float lo = 0, hi = 0;
  };
  const Range& at(uint64_t word) const { return range_[word]; }
  size_t bytes() const { return range_.size() * sizeof(Range); }

 private:
  std::vector<Range> range_;  // by the node's first word
};

class StackLookup {
 public:
  // Throws st::Error when the light set's sample count differs from the octree's slices.
  StackLookup(const MhOctree& octree, const LightSet& lights);

  bool lit(const Vec3d& p, uint32_t w) const noexcept;
  float visibility(const Vec3d& p, double time) const noexcept;
  float soft_visibility(const Vec3d& p) const noexcept;
  // out[i] = soft_visibility(points[i]) for i < min(points.size(), out.size()), bit for bit
  // (tested, fuzzed): each point's shared walk as above, the walks of up to kWalkLanes
  // points interleaved so that their cache misses overlap (walk_interleave.hpp). A batch
  // of a frame's receivers is where a soft lookup pays least per point.
  void soft_visibility(std::span<const Vec3d> points, std::span<float> out) const noexcept;
  // The same fraction from N independent walks (the reference and the benchmark's baseline).
  float soft_visibility_independent(const Vec3d& p) const noexcept;
  // The same fraction again, each sample's walk stopping at the first node whose bounds
  // decide its lit test (`bounds` made from this lookup's octree). Equal to
  // soft_visibility bit for bit (tested): d <= lo <= the texel's value, or d > hi >= it.
  float soft_visibility_bounded(const Vec3d& p, const StackBounds& bounds) const noexcept;

  // Tree nodes the last soft_visibility call on this thread visited (benchmark figure; a
  // batch: summed over its points).
  static uint64_t last_nodes_visited() noexcept;
  // Steps of the last batched soft_visibility call on this thread into a node on a cache
  // line other than its parent's: the prefetches it issued, the misses it can have had
  // in the tree (benchmark figure).
  static uint64_t last_lines_prefetched() noexcept;

 private:
  const MhOctree& tree_;
  const LightSet& lights_;
  SampleTexels texels_;  // the soft lookups' batched transforms (sample_texels.hpp)
};

}  // namespace st

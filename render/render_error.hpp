// Shadow error of a map against ray-traced ground truth (`shadowtile report`).
//
// A FrameTruth holds one camera frame's receivers (Embree primary rays) and, for every
// light-facing receiver, the ray-traced visibility (one shadow ray) and, per PCF radius,
// a supersampled reference: the mean ray-traced visibility over the kernel's footprint
// ((2R+1)^2 texels of the finest map, 2x2 rays per texel, the receiver moved across the
// light's u/v axes and back along the light ray onto its tangent plane, so each ray
// samples the lit fraction of the surface the kernel covers).
//
// For hierarchical filtering (MH §3.3) a frame may also hold, per light-facing receiver,
// its pixel footprint in finest-level texels (receiver_footprint_texels) and, per radius
// R >= 0, a footprint reference: the mean ray-traced visibility over a square of
// (2R+1) * max(1, footprint) finest texels (the kernel scaled to the pixel, what a
// filtered lookup tries to answer), sampled on a regular grid of 2(2R+1) points a side
// (twice as many where the footprint exceeds a texel) and projected onto the receiver's
// tangent plane like the PCF reference. Where the footprint is at most a texel it is the
// PCF reference above. Fixed-level PCF and filtered lookups are both measured against it.
//
// FlatMapEvaluator is the uncompressed baseline: one float per texel of one level (the
// midpoint of each texel's dual depth interval, so closed receivers need no bias, like
// the compressed map; open geometry gets the same normal offset as render.hpp).
#pragma once
#include <cstdint>
#include <vector>

#include "render/render.hpp"
#include "tiles/core/interval.hpp"

namespace st {

struct FrameTruth {
  Camera camera;
  uint32_t width = 0, height = 0;
  std::vector<Receiver> receivers;
  std::vector<uint32_t> lit_facing;          // indices of receivers with n.l > 0
  std::vector<float> traced;                 // per lit-facing receiver: 0 or 1
  std::vector<std::vector<float>> pcf_truth; // [radius - 1][lit-facing receiver]
  double pixel_angle = 0;                    // add_footprint_truth's, 0 if none
  std::vector<float> footprint;              // per lit-facing receiver, finest texels
  std::vector<std::vector<float>> footprint_truth;  // [radius][lit-facing receiver]
};

// `map_level` sets the PCF reference's texel size; pcf_radii lists radii >= 1.
FrameTruth make_frame_truth(const SceneTracer& tracer, const Camera& camera, uint32_t width, uint32_t height,
                            uint32_t map_level, const std::vector<uint32_t>& pcf_radii);

// Adds the footprints (for `pixel_angle` radians per pixel) and the footprint references
// for each radius in `radii` (0..4) at the map's finest level `map_level`.
void add_footprint_truth(const SceneTracer& tracer, FrameTruth& f, uint32_t map_level,
                         const std::vector<uint32_t>& radii, double pixel_angle);

struct FrameError {
  uint64_t receivers = 0, differing = 0;  // single tap: lit answers that differ
  double mean_abs = 0;                    // PCF: mean |map - reference|
  double seconds = 0;                     // evaluation time of the frame (one thread)
  double fraction() const { return receivers ? double(differing) / double(receivers) : 0; }
};

// Single tap (pcf_radius 0) or PCF at `level` of `eval` against the frame's truth.
FrameError frame_error(const Evaluator& eval, const LightSpace& light, const FrameTruth& f, uint32_t pcf_radius,
                       uint32_t level);
class FlatMapEvaluator;

// (2R+1)^2 PCF (R = 0: one tap) of `eval` against the footprint reference of radius R:
// `hierarchical` filters at the footprint's two levels (map_visibility_filtered), else
// at the finest level. Footprints are rescaled to `eval`'s finest level, so a coarser
// uncompressed baseline is filtered for the same pixels. mean_abs is the error.
FrameError footprint_error(const Evaluator& eval, const LightSpace& light, const FrameTruth& f, uint32_t radius,
                           bool hierarchical);

// Receivers whose single-tap answers of `a` and of the uncompressed full map differ
// (lossless check). Both maps store a value in each texel's [lo, hi], so the answers for
// a receiver of lookup depth d can differ only where lo < d <= hi of its texel: a lookup
// point inside (or at the far side of) a closed object as the texel-centre ray sees it,
// where every stored value is lossless by definition. `within_interval` counts those
// (the legitimate class; zero on open geometry, where hi = lo); `outside()` the others,
// which the lossless invariant makes zero at full residency.
// `slab_bits` > 0: `a` is a voxel shadow DAG of 2^slab_bits depth slabs, whose contract
// (tiles/core/VSDAG.md "Exactness contract") also lets it differ where d lies in the slab
// of the texel's lo or hi (vsdag::receiver_slab); `within_slab` counts those apart from
// `within_interval`, and `outside()` the rest, which its contract makes zero.
struct Disagreements {
  uint64_t total = 0, within_interval = 0, within_slab = 0;
  uint64_t outside() const { return total - within_interval - within_slab; }
};
// `full` must keep its intervals (FlatMapEvaluator(tile, true)).
Disagreements count_disagreements(const Evaluator& a, const FlatMapEvaluator& full, const LightSpace& light,
                                  const FrameTruth& f, uint32_t slab_bits = 0);

class FlatMapEvaluator final : public Evaluator {
 public:
  // Midpoints of a full level-`tile.level` interval tile (x0 = y0 = 0, side 2^level);
  // `keep_intervals` also keeps each texel's [lo, hi] (twice the memory).
  explicit FlatMapEvaluator(const IntervalTile& tile, bool keep_intervals = false);
  // The texel's interval at the finest level; nullptr unless the intervals were kept.
  const Interval* interval(uint64_t x, uint64_t y) const {
    return intervals_.empty() ? nullptr : &intervals_[(y << level_) + x];
  }
  uint32_t finest_level() const override { return level_; }
  // Coarser levels point-sample the finest (this baseline has no hierarchy).
  float depth(uint32_t level, uint64_t x, uint64_t y) const override;
  uint64_t bytes() const { return values_.size() * sizeof(float); }

 private:
  uint32_t level_;
  std::vector<float> values_;
  std::vector<Interval> intervals_;
};

}  // namespace st

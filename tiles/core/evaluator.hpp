// One evaluator interface for every encoding (MH quadtree, MMH, DAG-MH, packs, the
// client's cache). Every level of the hierarchy is a complete shadow map of 2^level
// texels a side (ARCHITECTURE.md "Definitions").
//
// Thread safety: const methods may be called concurrently from many threads.
// Coordinates are integer texels of the given level; callers clamp (x, y < 2^level).
#pragma once
#include <cstdint>
#include <span>

namespace st {

struct ReceiverPlane;  // tiles/core/receiver_plane.hpp

// One lookup of a batch (Evaluator::pcf_batch): r = 1 is a single lit test.
struct PcfQuery {
  uint64_t x = 0, y = 0;  // texel of `level`
  uint32_t level = 0;
  uint32_t r = 1;         // kernel side, 1..kMaxPcf
  float receiver = 0;     // light-space depth of the receiver
};

// A texel's value and the aligned square of texels around it that share it: every texel
// (x', y') of the same level with (x' >> shift, y' >> shift) == (x >> shift, y >> shift)
// answers `value` bit for bit. It is the node where the lookup's walk ended (a leaf, a
// missing child, a node with nothing valued below it), so a caller that keeps the last
// region skips the walk for the lookups that fall in it (MH 2016 §3.3's last-sample cache,
// DAG-MH 2021 §3.5).
struct DepthRegion {
  float value = 0;
  uint32_t shift = 0;  // 0: the texel alone; never more than the level
};

class Evaluator {
 public:
  virtual ~Evaluator() = default;

  // Finest level stored (the map is 2^finest_level() texels a side).
  virtual uint32_t finest_level() const = 0;

  // The value answering for texel (x, y) of level `level` (level <= finest_level()).
  virtual float depth(uint32_t level, uint64_t x, uint64_t y) const = 0;

  // Fraction of the r x r kernel's taps that are lit (receiver <= depth), 1 <= r <= 9.
  // The kernel covers texels [x - (r-1)/2, x - (r-1)/2 + r) on each axis, each tap clamped to
  // the map's edges (pcf_tap). The result is exactly (lit taps) / (r * r) computed in float, so it
  // equals the average of the corresponding single lookups. The base implementation
  // does r*r independent lookups; encodings override it with traversal shared down to
  // the lowest common node (MH §3.3, Fig. 5).
  virtual float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const;

  // pcf with each tap compared with the receiver's plane over the tap's own (clamped)
  // texel instead of one receiver depth (receiver_plane.hpp: receiver_plane_depth(p, level,
  // tap) <= value): exactly (lit taps) / (r * r) in float, the tap-by-tap count. `p` is in
  // this evaluator's own levels (p.finest == finest_level()). The base implementation asks
  // the kernel's extreme tap depths through pcf (all lit at the greatest: 1; none at the
  // least: 0), else counts tap by tap; the tree encodings count inside their shared
  // traversal, a square of texels that share a value counted at once when the plane over
  // it lies on one side of the value (PlaneTaps).
  virtual float pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const;

  // depth(level, x, y) and the region of texels that share it (DepthRegion), for
  // level <= finest_level() and x, y < 2^level. The base implementation answers the texel
  // alone (shift 0); the tree encodings report the node their walk ended at.
  virtual DepthRegion depth_region(uint32_t level, uint64_t x, uint64_t y) const;

  // Lit test at full resolution: receiver_depth <= stored value.
  bool lit(uint64_t x, uint64_t y, float receiver_depth) const {
    return receiver_depth <= depth(finest_level(), x, y);
  }

  // out[i] = pcf(q.level, q.x, q.y, q.r, q.receiver) for every query (out.size() >=
  // queries.size()), bit for bit. The base implementation loops; an evaluator with a
  // lock or a page table (the client's cache) overrides it to take the lock and walk the
  // top of the page table once per batch. Consecutive queries in the same tile are cheapest.
  virtual void pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const;

  // Hierarchical PCF (MH §3.3) with trilinear blending: r x r PCF at the two levels
  // filter_levels(finest_level(), footprint) picks for a footprint of `footprint`
  // finest-level texels, blended by filter_blend (tiles/core/filter_level.hpp states the
  // exact arithmetic). (u, v) in [0,1).
  float pcf_footprint(double u, double v, float receiver, float footprint, uint32_t r) const;

  static constexpr uint32_t kMaxPcf = 9;
};

// Coordinate of tap i (0 <= i < r) of an r-tap kernel around x, clamped to [0, side).
inline uint64_t pcf_tap(uint64_t x, uint32_t i, uint32_t r, uint64_t side) {
  int64_t t = int64_t(x) - int64_t((r - 1) / 2) + int64_t(i);
  return t < 0 ? 0 : uint64_t(t) >= side ? side - 1 : uint64_t(t);
}

}  // namespace st

// Bottom-up construction of the sparse multiresolution hierarchy (MH §3.1, Alg. 2), plus
// input validation and the public entry point.
//
// Working state: for every level l < n a dense array in morton order (node m's children
// are 4m..4m+3 of level l+1, in child order) holding the node's chosen interval I and two
// child masks. Level n is the input itself. That is 10 bytes per node of levels < n, i.e.
// ~3.3 bytes per texel beyond the input, and no per-node allocation.
//
// Level step (MH §3.1 "Bottom-up construction"; the authors' demo, DESIGN.md notes): the
// parent's interval is [max lo, min hi] of its four children; if non-empty it covers all
// four. Otherwise the mode by the sweep of Fig. 3 over the four children: the child lower
// bound lying inside the most child intervals, and I = the intersection of those
// children. A child is *covered* iff its interval contains I (then the parent's eventual
// value, chosen inside I, is valid for every texel the child answers for); uncovered
// children are stored with a value, covered ones with stored descendants become empty
// nodes, other covered ones disappear.
//
// By induction a node's I is exactly the intersection of the intervals of the texels it
// answers for (those reached through covered nodes only), which is the admissible
// interval HNode::lo/hi documents; the value is its float-safe midpoint.
#include "tiles/core/mh_build.hpp"

#include <algorithm>
#include <cfloat>
#include <cstring>
#include <string>

#include "tiles/core/error.hpp"
#include "tiles/core/mh_internal.hpp"

namespace st {
namespace mh_detail {
namespace {

constexpr uint32_t kMaxTileLevel = 14;  // tiles are at most 2^14 texels a side (mh_build.hpp)

// Result of one 2x2 level step.
struct StepOut {
  float lo, hi;
  uint8_t present;  // children stored (valued or empty)
  uint8_t valued;   // children stored with a value (= not covered)
};

// `desc`: bit c set iff child c has stored descendants.
inline StepOut level_step(const float lo[4], const float hi[4], uint32_t desc) {
  float l = std::max(std::max(lo[0], lo[1]), std::max(lo[2], lo[3]));
  float h = std::min(std::min(hi[0], hi[1]), std::min(hi[2], hi[3]));
  if (l <= h) return {l, h, uint8_t(desc), 0};
  // Sweep for the mode (MH Fig. 3) over four intervals: the best representative can
  // always be taken at some child's lower bound. Ties prefer covering more children
  // without descendants, since those vanish while covered inner children only turn
  // empty; then the lowest child index (deterministic).
  uint32_t best_mask = 0, best_score = 0, best = 0;
  for (uint32_t i = 0; i < 4; ++i) {
    float v = lo[i];
    uint32_t mask = 0;
    for (uint32_t j = 0; j < 4; ++j) mask |= uint32_t(lo[j] <= v && v <= hi[j]) << j;
    uint32_t score = uint32_t(__builtin_popcount(mask)) * 8 + uint32_t(__builtin_popcount(mask & ~desc));
    if (score > best_score) best_score = score, best_mask = mask, best = i;
  }
  float ih = FLT_MAX;
  for (uint32_t j = 0; j < 4; ++j)
    if (best_mask >> j & 1) ih = std::min(ih, hi[j]);
  uint32_t valued = ~best_mask & 0xFu;
  return {lo[best], ih, uint8_t(valued | (best_mask & desc)), uint8_t(valued)};
}

}  // namespace

uint32_t validate_tile(const IntervalTile& tile) {
  if (tile.width != tile.height || !is_power_of_two(tile.width))
    throw Error("build_hierarchy: tile is " + std::to_string(tile.width) + "x" + std::to_string(tile.height) +
                ", expected a square power-of-two side");
  uint32_t n = log2_exact(tile.width);
  if (n > kMaxTileLevel)
    throw Error("build_hierarchy: tile side 2^" + std::to_string(n) + " exceeds 2^" + std::to_string(kMaxTileLevel));
  size_t count = size_t(tile.width) * tile.height;
  if (tile.data.size() != count)
    throw Error("build_hierarchy: tile data holds " + std::to_string(tile.data.size()) + " intervals, expected " +
                std::to_string(count));
  // Branch-free scan first (vectorizes); locate the culprit only on failure. NaN fails
  // every comparison, so one test per bound covers NaN, infinities and lo > hi.
  bool ok = true;
  const Interval* d = tile.data.data();
  for (size_t i = 0; i < count; ++i) ok &= (d[i].lo >= -FLT_MAX) & (d[i].lo <= d[i].hi) & (d[i].hi <= FLT_MAX);
  if (ok) return n;
  for (size_t i = 0; i < count; ++i) {
    if ((d[i].lo >= -FLT_MAX) && (d[i].lo <= d[i].hi) && (d[i].hi <= FLT_MAX)) continue;
    uint64_t x = i % tile.width, y = i / tile.width;
    throw Error("build_hierarchy: texel (" + std::to_string(tile.x0 + x) + ", " + std::to_string(tile.y0 + y) +
                ") of level " + std::to_string(tile.level) + ": interval [" + std::to_string(d[i].lo) + ", " +
                std::to_string(d[i].hi) + "] is not finite with lo <= hi");
  }
  return n;
}

Hierarchy build_bottom_up(const IntervalTile& tile, uint32_t n) {
  Hierarchy h;
  h.depth = n;
  h.levels.resize(n + 1);
  if (n == 0) {
    const Interval& t = tile.data[0];
    h.levels[0].push_back(HNode{0, safe_midpoint(t.lo, t.hi), t.lo, t.hi, 0, 1});
    return h;
  }
  // Dense per-level storage for levels 0..n-1, one allocation each for bounds and masks.
  std::vector<size_t> base(n + 1, 0);
  for (uint32_t l = 0; l < n; ++l) base[l + 1] = base[l] + (size_t(1) << (2 * l));
  std::vector<float> lo(base[n]), hi(base[n]);
  std::vector<uint8_t> present(base[n]), valued(base[n]);

  // Level n -> n-1: children are texels of the row-major input (no descendants).
  {
    const size_t count = size_t(1) << (2 * (n - 1));
    const size_t out = base[n - 1];
    const Interval* d = tile.data.data();
    const size_t w = tile.width;
    for (size_t m = 0; m < count; ++m) {
      size_t px = morton_compact(m), py = morton_compact(m >> 1);
      const Interval* r0 = d + (2 * py) * w + 2 * px;
      const Interval* r1 = r0 + w;
      float clo[4] = {r0[0].lo, r0[1].lo, r1[0].lo, r1[1].lo};
      float chi[4] = {r0[0].hi, r0[1].hi, r1[0].hi, r1[1].hi};
      StepOut s = level_step(clo, chi, 0);
      lo[out + m] = s.lo, hi[out + m] = s.hi, present[out + m] = s.present, valued[out + m] = s.valued;
    }
  }
  // Levels n-1 .. 1 -> one coarser: children are contiguous in morton order.
  for (uint32_t l = n - 1; l-- > 0;) {
    const size_t count = size_t(1) << (2 * l);
    const size_t out = base[l], in = base[l + 1];
    for (size_t m = 0; m < count; ++m) {
      size_t c = in + 4 * m;
      uint32_t desc = uint32_t(present[c] != 0) | uint32_t(present[c + 1] != 0) << 1 |
                      uint32_t(present[c + 2] != 0) << 2 | uint32_t(present[c + 3] != 0) << 3;
      StepOut s = level_step(&lo[c], &hi[c], desc);
      lo[out + m] = s.lo, hi[out + m] = s.hi, present[out + m] = s.present, valued[out + m] = s.valued;
    }
  }

  // Emit present nodes level by level; walking the previous level's present nodes in
  // morton order and their children in child order keeps every level morton-sorted.
  h.levels[0].push_back(HNode{0, safe_midpoint(lo[0], hi[0]), lo[0], hi[0], present[0], 1});
  for (uint32_t l = 1; l <= n; ++l) {
    const auto& parents = h.levels[l - 1];
    auto& nodes = h.levels[l];
    size_t total = 0;
    for (const HNode& p : parents) total += size_t(__builtin_popcount(p.child_mask));
    nodes.reserve(total);
    const size_t pbase = base[l - 1];
    for (const HNode& p : parents) {
      uint32_t vmask = valued[pbase + p.morton];
      for (uint32_t mask = p.child_mask; mask; mask &= mask - 1) {
        uint32_t c = uint32_t(__builtin_ctz(mask));
        uint64_t m = 4 * p.morton + c;
        HNode node;
        node.morton = m;
        if (l < n) {
          node.lo = lo[base[l] + m], node.hi = hi[base[l] + m];
          node.child_mask = present[base[l] + m];
        } else {
          const Interval& t = tile.data[size_t(morton_compact(m >> 1)) * tile.width + morton_compact(m)];
          node.lo = t.lo, node.hi = t.hi;
        }
        node.has_value = uint8_t(vmask >> c & 1);
        if (node.has_value) {
          node.value = safe_midpoint(node.lo, node.hi);
        } else {
          node.lo = node.hi = 0;  // empty nodes carry no interval (hierarchy.hpp)
        }
        nodes.push_back(node);
      }
    }
  }
  return h;
}

}  // namespace mh_detail

Hierarchy build_hierarchy(const IntervalTile& tile, MhConstruction method) {
  uint32_t n = mh_detail::validate_tile(tile);
  switch (method) {
    case MhConstruction::bottom_up:
      return mh_detail::build_bottom_up(tile, n);
    case MhConstruction::top_down:
      return mh_detail::build_top_down(tile, n);
  }
  throw Error("build_hierarchy: unknown construction method " + std::to_string(int(method)));
}

}  // namespace st

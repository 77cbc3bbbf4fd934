// Bottom-up construction of the sparse multiresolution hierarchy (MH §3.1, Alg. 2), plus
// input validation and the public entry point.
//
// Working state: for every level l < n a dense array in morton order (node m's children
// are 4m..4m+3 of level l+1, in child order) holding the node's chosen interval I and two
// child masks. Level n is the input itself. That is 10 bytes per node of levels < n, i.e.
// ~3.3 bytes per texel beyond the input, and no per-node allocation.
//
// Level step: mh_level_step.hpp. A child is *covered* iff its interval contains the
// parent's I, so the parent's eventual value, chosen inside I, is valid for every texel
// the child answers for; covered children vanish or turn empty, the others keep a value.
//
// By induction a node's I is exactly the intersection of the intervals of the texels it
// answers for (those reached through covered nodes only), which is the admissible
// interval HNode::lo/hi documents; the value is its float-safe midpoint.
#include "tiles/encode/mh_build.hpp"

#include <algorithm>
#include <cfloat>
#include <cstdio>
#include <memory>
#include <string>

#include "common/error.hpp"
#include "tiles/encode/mh_internal.hpp"
#include "tiles/encode/mh_level_step.hpp"

namespace st {
namespace mh_detail {
namespace {

constexpr uint32_t kMaxTileLevel = 14;  // tiles are at most 2^14 texels a side (mh_build.hpp)
static_assert(sizeof(Interval) == 8, "the level step loads two intervals as four floats");

inline bool interval_ok(const Interval& v) { return (v.lo >= -FLT_MAX) && (v.lo <= v.hi) && (v.hi <= FLT_MAX); }

// Dense per-level working arrays (levels 0..n-1, morton order).
struct Dense {
  std::vector<size_t> base;  // base[l]: offset of level l (levels 0..n-1)
  // Uninitialized: every entry is written by its level step before it is read.
  std::unique_ptr<float[]> lo, hi;
  std::unique_ptr<uint8_t[]> present, valued;
  explicit Dense(uint32_t n) : base(n + 1, 0) {
    for (uint32_t l = 0; l < n; ++l) base[l + 1] = base[l] + (size_t(1) << (2 * l));
    const size_t count = base[n];
    lo.reset(new float[count]), hi.reset(new float[count]);
    present.reset(new uint8_t[count]), valued.reset(new uint8_t[count]);
  }
  void store(size_t i, const StepOut& s) { lo[i] = s.lo, hi[i] = s.hi, present[i] = s.present, valued[i] = s.valued; }
};

// A morton walk over a row-major input defeats the hardware prefetcher (each texel row is
// a page of its own at 2^10+ texels a side): when the walk enters an aligned block of
// 8x8 parents, fetch the 16 rows of 16 texels of the next block. Only called while that
// block exists (the parent grid is then at least 16 wide), so every address is in the tile.
constexpr size_t kPrefetchAhead = 64;  // parents per 8x8 block
inline void prefetch_parent_rows(const Interval* data, size_t w, size_t m) {
  size_t px = morton_compact(m), py = morton_compact(m >> 1);
  const Interval* p = data + (2 * py) * w + 2 * px;
  for (size_t r = 0; r < 16; ++r) __builtin_prefetch(p + r * w);  // 16 texels = two cache lines
  for (size_t r = 0; r < 16; ++r) __builtin_prefetch(p + r * w + 8);
}

// Level n -> n-1 straight from the row-major input; returns false if some texel fails
// validation (checked on the fly, NaN fails every comparison), so the input is read once.
bool step_from_texels(const IntervalTile& tile, uint32_t n, Dense& d) {
  const size_t count = size_t(1) << (2 * (n - 1)), out = d.base[n - 1], w = tile.width;
  const Interval* data = tile.data.data();
#if ST_MH_SSE2
  const __m128 neg_max = _mm_set1_ps(-FLT_MAX), pos_max = _mm_set1_ps(FLT_MAX);
  __m128 ok = _mm_castsi128_ps(_mm_set1_epi32(-1));
  for (size_t m = 0; m < count; ++m) {
    size_t px = morton_compact(m), py = morton_compact(m >> 1);
    const Interval* r0 = data + (2 * py) * w + 2 * px;
    if ((m & (kPrefetchAhead - 1)) == 0 && m + kPrefetchAhead < count) prefetch_parent_rows(data, w, m + kPrefetchAhead);
    __m128 a = _mm_loadu_ps(&r0->lo), b = _mm_loadu_ps(&r0[w].lo);  // lo0 hi0 lo1 hi1, lo2 hi2 lo3 hi3
    __m128 lo = _mm_shuffle_ps(a, b, _MM_SHUFFLE(2, 0, 2, 0)), hi = _mm_shuffle_ps(a, b, _MM_SHUFFLE(3, 1, 3, 1));
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmple_ps(lo, hi), _mm_and_ps(_mm_cmple_ps(neg_max, lo), _mm_cmple_ps(hi, pos_max))));
    d.store(out + m, level_step_sse(lo, hi, 0));
  }
  return _mm_movemask_ps(ok) == 0xF;
#else
  bool ok = true;
  for (size_t m = 0; m < count; ++m) {
    size_t px = morton_compact(m), py = morton_compact(m >> 1);
    const Interval* r0 = data + (2 * py) * w + 2 * px;
    const Interval* r1 = r0 + w;
    ok &= interval_ok(r0[0]) & interval_ok(r0[1]) & interval_ok(r1[0]) & interval_ok(r1[1]);
    float lo[4] = {r0[0].lo, r0[1].lo, r1[0].lo, r1[1].lo}, hi[4] = {r0[0].hi, r0[1].hi, r1[0].hi, r1[1].hi};
    d.store(out + m, level_step_scalar(lo, hi, 0));
  }
  return ok;
#endif
}

// Level l+1 -> l: children are contiguous in morton order.
void step_from_level(uint32_t l, Dense& d) {
  const size_t count = size_t(1) << (2 * l), out = d.base[l], in = d.base[l + 1];
  for (size_t m = 0; m < count; ++m) {
    size_t c = in + 4 * m;
    uint32_t desc = uint32_t(d.present[c] != 0) | uint32_t(d.present[c + 1] != 0) << 1 |
                    uint32_t(d.present[c + 2] != 0) << 2 | uint32_t(d.present[c + 3] != 0) << 3;
#if ST_MH_SSE2
    d.store(out + m, level_step_sse(_mm_loadu_ps(&d.lo[c]), _mm_loadu_ps(&d.hi[c]), desc));
#else
    d.store(out + m, level_step_scalar(&d.lo[c], &d.hi[c], desc));
#endif
  }
}

}  // namespace

uint32_t validate_tile_shape(const IntervalTile& tile) {
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
  return n;
}

void validate_tile_values(const IntervalTile& tile) {
  // Branch-free scan first; locate the culprit only on failure.
  bool ok = true;
  for (const Interval& v : tile.data) ok &= interval_ok(v);
  if (ok) return;
  for (size_t i = 0; i < tile.data.size(); ++i) {
    const Interval& v = tile.data[i];
    if (interval_ok(v)) continue;
    uint64_t x = i % tile.width, y = i / tile.width;
    char bounds[64];
    std::snprintf(bounds, sizeof bounds, "[%.9g, %.9g]", double(v.lo), double(v.hi));
    throw Error("build_hierarchy: texel (" + std::to_string(tile.x0 + x) + ", " + std::to_string(tile.y0 + y) +
                ") of level " + std::to_string(tile.level) + ": interval " + bounds + " is not finite with lo <= hi");
  }
}

Hierarchy build_bottom_up(const IntervalTile& tile, uint32_t n) {
  Hierarchy h;
  h.depth = n;
  h.levels.resize(n + 1);
  if (n == 0) {
    validate_tile_values(tile);
    const Interval& t = tile.data[0];
    h.levels[0].push_back(HNode{0, safe_midpoint(t.lo, t.hi), t.lo, t.hi, 0, 1});
    return h;
  }
  Dense d(n);  // levels 0..n-1, one allocation per array
  if (!step_from_texels(tile, n, d)) validate_tile_values(tile);  // throws, naming the texel
  for (uint32_t l = n - 1; l-- > 0;) step_from_level(l, d);

  // Emit present nodes level by level; walking the previous level's present nodes in
  // morton order and their children in child order keeps every level morton-sorted.
  h.levels[0].push_back(HNode{0, safe_midpoint(d.lo[0], d.hi[0]), d.lo[0], d.hi[0], d.present[0], 1});
  for (uint32_t l = 1; l <= n; ++l) {
    const auto& parents = h.levels[l - 1];
    auto& nodes = h.levels[l];
    size_t total = 0;
    for (const HNode& p : parents) total += kPop4[p.child_mask & 0xF];
    nodes.reserve(total);
    const size_t pbase = d.base[l - 1];
    if (l < n) {
      const size_t cbase = d.base[l];
      for (const HNode& p : parents) {
        const uint32_t vmask = d.valued[pbase + p.morton];
        for (uint32_t mask = p.child_mask; mask; mask &= mask - 1) {
          const uint32_t c = uint32_t(__builtin_ctz(mask));
          const uint64_t m = 4 * p.morton + c;
          const size_t i = cbase + m;
          // Empty nodes carry no interval (hierarchy.hpp).
          if (vmask >> c & 1)
            nodes.push_back(HNode{m, safe_midpoint(d.lo[i], d.hi[i]), d.lo[i], d.hi[i], d.present[i], 1});
          else
            nodes.push_back(HNode{m, 0, 0, 0, d.present[i], 0});
        }
      }
    } else {
      // Texels: present means stored with a value; read them from the row-major input.
      const size_t w = tile.width;
      auto first_texel = [&](uint64_t pm) {
        return tile.data.data() + size_t(2 * morton_compact(pm >> 1)) * w + 2 * morton_compact(pm);
      };
      constexpr size_t kAhead = 8;  // see prefetch_parent_rows
      for (size_t k = 0; k < parents.size(); ++k) {
        const HNode& p = parents[k];
        if (k + kAhead < parents.size()) {
          const Interval* f = first_texel(parents[k + kAhead].morton);
          __builtin_prefetch(f), __builtin_prefetch(f + w);
        }
        const Interval* r0 = first_texel(p.morton);
        for (uint32_t mask = p.child_mask; mask; mask &= mask - 1) {
          const uint32_t c = uint32_t(__builtin_ctz(mask));
          const Interval& t = r0[(c >> 1) * w + (c & 1)];
          nodes.push_back(HNode{4 * p.morton + c, safe_midpoint(t.lo, t.hi), t.lo, t.hi, 0, 1});
        }
      }
    }
  }
  return h;
}

}  // namespace mh_detail

Hierarchy build_hierarchy(const IntervalTile& tile, MhConstruction method) {
  uint32_t n = mh_detail::validate_tile_shape(tile);
  switch (method) {
    case MhConstruction::bottom_up:
      return mh_detail::build_bottom_up(tile, n);  // validates values in its first pass
    case MhConstruction::top_down:
      mh_detail::validate_tile_values(tile);
      return mh_detail::build_top_down(tile, n);
  }
  throw Error("build_hierarchy: unknown construction method " + std::to_string(int(method)));
}

}  // namespace st

// Single taps answered inside one encoded tree (an MH, MMH or DAG-MH tile): a tile's own
// Evaluator::pcf_batch (single_tap_batch; DAG-MH runs its own loop on the same scheme) and
// the client's taps one at a time (TapWalks::walk_tap, the client keeping the regions).
// Two savings over one depth() walk per tap, both exact:
//  - a tap inside the region of one of the last few answers (Evaluator::DepthRegion: the
//    node where that walk ended) takes its value without a walk (MH 2016 §3.3's
//    last-sample cache);
//  - a walk resumes from the deepest node of the previous walk that lies on its own path
//    (the nodes above the highest bit in which the two texels differ), as MH 2016 §3.3
//    Fig. 5 shares the root path among a kernel's taps and DAG-MH 2021 §3.5 caches the
//    last node traversed: a screen-coherent batch steps a level or two per tap, not the
//    whole tree.
// Every tap runs the same walk as depth() from a node on its own path, so out[i] equals
// pcf(level, x, y, 1, receiver) bit for bit (tests/tiles/depth_region_test.cpp). Queries
// with r > 1, or a level finer than the tree, go to pcf() itself. No allocation.
#pragma once
#include <algorithm>
#include <array>
#include <cstdint>
#include <new>
#include <span>
#include <type_traits>

#include "tiles/core/evaluator.hpp"

namespace st {

// The depths of a rectangle of texels of one encoded tree (an MH, MMH or DAG-MH tile),
// each node that overlaps it walked once: one walk to the rectangle's lowest common node,
// then depth first through the children that overlap it (MH 2016 §3.3 Fig. 5's shared
// root path, carried down the whole subtree), so a 5x5 PCF window costs about one walk
// plus the few nodes below the common one, not 25 walks. Every texel gets the value the
// walk of depth(level, x, y) ends at, bit for bit (tests/tiles/depth_region_test.cpp).
// out[(x - x0) * h + (y - y0)] (column-major: a PCF window of columns), for 1 <= w, h <=
// kMaxPcf and x0 + w, y0 + h <= 2^level, level <= finest_level(). Returns a region shift
// (DepthRegion): when the walk to the common node already stopped (a leaf, a missing
// child), every texel sharing (x0 >> shift, y0 >> shift) answers out[0]; else 0, which
// holds the whole rectangle only when it is one texel. No allocation. The client finds
// it on a tile's evaluator once, when the tile arrives.
class WindowDepths {
 public:
  virtual uint32_t depth_window(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                                float* out) const = 0;
  // How many texels of the same rectangle are lit for `receiver` (receiver <= depth, the
  // lit test of the lossless invariant's contract, tiles/core/interval.hpp): exactly the
  // count of the per-texel tests on depth_window's output, without writing the depths.
  // One walk as depth_window's, but a node where every texel's walk ends (a leaf, a
  // missing child, a treelet node with no value below it) adds the area of its part of
  // the rectangle at once, one test for the whole subtree (MH 2016 §3.3's hierarchical
  // PCF, DAG-MH 2021 §3.5). Same bounds as depth_window. No allocation.
  virtual uint32_t count_window(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                                float receiver) const = 0;
  // count_window with each texel compared with the receiver plane `p` (in this tree's own
  // levels: receiver_plane_depth(p, level, x, y) <= value): the same walk, a part of the
  // window whose texels share a value counted at once when the plane's least and greatest
  // depth over the part lie on one side of it, else split (PlaneTaps, receiver_plane.hpp).
  virtual uint32_t count_window_plane(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                                      const ReceiverPlane& p) const = 0;
  // A hint that lookups in this tree follow soon: start bringing its bytes toward the
  // cache. The client calls it when a lookup enters the tile, before it collects the
  // tile's taps into a batch, so the tile's lines arrive while that happens instead of one
  // dependent miss after another in the walks. Changes no answer. Default: nothing.
  virtual void prefetch() const noexcept {}

 protected:
  ~WindowDepths() = default;
};

// lit / (r * r) in float for 0 <= lit <= r * r, 1 <= r <= kMaxPcf, from a table (the
// same IEEE division, done once at compile time): a PCF kernel's fraction of lit taps.
inline float pcf_fraction(uint32_t lit, uint32_t r) {
  constexpr uint32_t kN = Evaluator::kMaxPcf;
  static constexpr auto kTable = [] {
    std::array<std::array<float, kN * kN + 1>, kN + 1> t{};
    for (uint32_t k = 1; k <= kN; ++k)
      for (uint32_t c = 0; c <= k * k; ++c) t[k][c] = float(c) / float(k * k);
    return t;
  }();
  return kTable[r][lit];
}

// A rectangle [ax, bx] x [ay, by] inside an aligned square of side 2 * half, cut along the
// square's children (slot bit 0: the right half, bit 1: the lower half): the walks of
// depth_window and count_window visit each child's part once.
struct QuadSplit {
  QuadSplit(uint64_t ax_, uint64_t ay_, uint64_t bx_, uint64_t by_, uint64_t half)
      : ax(ax_), ay(ay_), bx(bx_), by(by_), mx((ax_ & ~(2 * half - 1)) + half), my((ay_ & ~(2 * half - 1)) + half) {}
  // The part in child `slot`; false where the rectangle does not reach that child.
  bool part(uint32_t slot, uint64_t& x0, uint64_t& y0, uint64_t& x1, uint64_t& y1) const {
    x0 = slot & 1u ? std::max(ax, mx) : ax, x1 = slot & 1u ? bx : std::min(bx, mx - 1);
    y0 = slot & 2u ? std::max(ay, my) : ay, y1 = slot & 2u ? by : std::min(by, my - 1);
    return x0 <= x1 && y0 <= y1;
  }
  uint64_t ax, ay, bx, by, mx, my;
};

// Writes `value` over the texels [ax, bx] x [ay, by] of depth_window's output.
inline void window_put(float value, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by, uint64_t x0, uint64_t y0,
                       uint32_t h, float* out) {
  for (uint64_t x = ax; x <= bx; ++x)
    for (uint64_t y = ay; y <= by; ++y) out[(x - x0) * h + (y - y0)] = value;
}

// The walker's path: Cursor of each level of the last walk, levels [lo, hi] valid.
template <class Cursor, uint32_t kLevels = 33>
struct WalkPath {
  static_assert(std::is_trivially_copyable_v<Cursor> && std::is_trivially_destructible_v<Cursor>);
  // Not initialized (a level is written before it is read: [lo, hi] only), so a path on
  // the stack costs nothing for a batch of one tap.
  union {
    Cursor at[kLevels];
  };
  WalkPath() {}
  uint32_t lo = 1, hi = 0, level = 0;  // lo > hi: empty
  uint64_t x = 0, y = 0;
  // The deepest kept level on (x, y)'s path at `level` (false: none, start afresh).
  bool resume(uint32_t lv, uint64_t tx, uint64_t ty, uint32_t& out) const {
    if (lo > hi || lv != level) return false;
    const uint64_t diff = (tx ^ x) | (ty ^ y);
    const uint32_t width = diff ? 64u - uint32_t(__builtin_clzll(diff)) : 0u;
    if (width > lv) return false;
    const uint32_t l = std::min(lv - width, hi);
    if (l < lo) return false;
    out = l;
    return true;
  }
};

// The state a caller keeps between the single-tap walks of one tile (TapWalks): the last
// walk's path, in storage the tile's evaluator interprets (tap_path). Opaque to the
// caller, who only keeps it alive across a run of taps; nothing in it is initialized
// until a walk uses it, so one on the stack costs nothing.
struct TapPath {
  static constexpr size_t kBytes = 2048;
  alignas(16) unsigned char raw[kBytes];
  const void* type = nullptr;   // which path type raw holds (null: none yet)
  const void* owner = nullptr;  // the evaluator whose last walk it holds
};

// A tile's single tap as one call that resumes from the last walk's path (the walks of
// single_tap_batch below, one at a time): the client answers most taps of a batch from
// the regions it keeps (MH 2016 §3.3's last-sample cache) without calling the tile, and
// calls walk_tap only for the others, keeping one TapPath per tile it walks in. Returns
// depth_region(level, x, y) bit for bit, for x, y < 2^level, level <= finest_level().
// No allocation, no exception.
// A run of single taps that all fall in one tile, in the caller's order (TapWalks::tap_run):
// tap k is queries[order[k]], a tap of `level` (its x, y clamped to 2^level - 1 as
// pcf_tap clamps one tap), inside the tile whose first texel at `level` is (x0, y0) and
// whose tree answers it at its own level `rel`; its answer goes to out[order[k]].
// With `side` set (the tile's side at `level`, 2^rel), order[0, count) may go on past the
// tile: the run is then its longest prefix of single taps (r <= 1) of `level` inside the
// tile, which the caller need not find in a pass of its own (TapRunEnd::count). The first
// tap must be one of them.
struct TapRun {
  const PcfQuery* queries = nullptr;
  const uint16_t* order = nullptr;
  size_t count = 0;
  uint32_t level = 0, rel = 0;
  uint64_t x0 = 0, y0 = 0;
  float* out = nullptr;
  uint64_t side = ~uint64_t(0);  // ~0: every tap of order[0, count) is in the run
  // Whether tap q, at (x, y) relative to the tile (clamped, unsigned), ends the run.
  bool ends(const PcfQuery& q, uint64_t x, uint64_t y) const {
    return (q.r > 1) | (q.level != level) | (x >= side) | (y >= side);
  }
};

// What a run ends with: the last tap's texel (relative to the tile, at `rel`) and its
// answer's region, which the caller may keep; how many taps walked the tree; and how
// many taps the run had (TapRun::side).
struct TapRunEnd {
  uint64_t x = 0, y = 0;
  DepthRegion region;
  uint64_t walks = 0;
  size_t count = 0;
};

// The answer of one tap of a run: receiver <= the texel's value (the lit test).
inline float tap_lit(float receiver, float value) { return receiver <= value ? 1.0f : 0.0f; }

// tap_run's loop over a run: a tap inside the region of the last walk's answer takes it
// without a walk (MH 2016 §3.3's last-sample cache); the others call walk(rel, x, y) ->
// DepthRegion, the tile's walk_tap. One call per run of taps in a tile, not per tap, so
// a caller's own per-tap work (tiles, kept regions, a virtual call) is paid per run.
template <class Walk>
TapRunEnd tap_run_loop(const TapRun& run, Walk&& walk) {
  TapRunEnd end;
  const uint64_t top = (uint64_t(1) << run.level) - 1;
  bool have = false;
  size_t k = 0;
  for (; k < run.count; ++k) {
    const uint32_t i = run.order[k];
    const PcfQuery& q = run.queries[i];
    const uint64_t x = std::min(q.x, top) - run.x0, y = std::min(q.y, top) - run.y0;
    if (run.ends(q, x, y)) break;
    if (!have || (((x ^ end.x) | (y ^ end.y)) >> end.region.shift) != 0) {
      end.region = walk(run.rel, x, y);
      end.x = x, end.y = y, have = true;
      ++end.walks;
    }
    run.out[i] = tap_lit(q.receiver, end.region.value);
  }
  end.count = k;
  return end;
}

class TapWalks {
 public:
  virtual DepthRegion walk_tap(uint32_t level, uint64_t x, uint64_t y, TapPath& path) const noexcept = 0;
  // Every tap of `run` (count >= 1; with side set, its taps up to the first that leaves
  // the tile, TapRunEnd::count), bit for bit walk_tap's answers with the lit test:
  // out[order[k]] = receiver <= walk_tap(rel, x - x0, y - y0).value. The walks resume
  // from `path` and leave their last one in it. Default: tap_run_loop over walk_tap.
  virtual TapRunEnd tap_run(const TapRun& run, TapPath& path) const noexcept {
    return tap_run_loop(run, [&](uint32_t l, uint64_t x, uint64_t y) { return walk_tap(l, x, y, path); });
  }
  // A hint that taps of this tile follow soon (WindowDepths::prefetch's, for a tile whose
  // evaluator has taps but no window walk: a plane tile). Changes no answer. Default: nothing.
  virtual void prefetch() const noexcept {}

 protected:
  ~TapWalks() = default;
};

// The Path (a WalkPath) that `p` holds for `owner`: made in place on first use, emptied
// when it last held another owner's walk (a path resumes only within one tree).
template <class Path>
Path& tap_path(TapPath& p, const void* owner) {
  static_assert(sizeof(Path) <= TapPath::kBytes && alignof(Path) <= 16 && std::is_trivially_destructible_v<Path>);
  static constexpr char kType = 0;  // one address per Path type
  if (p.type != &kType) {
    p.type = &kType, p.owner = owner;
    return *::new (static_cast<void*>(p.raw)) Path();
  }
  Path& path = *std::launder(reinterpret_cast<Path*>(p.raw));
  if (p.owner != owner) path.lo = 1, path.hi = 0, p.owner = owner;
  return path;
}

// walk(level, x, y) -> DepthRegion: depth_region's answer for x, y < 2^level, level <=
// ev.finest_level() (the walker keeps its own WalkPath).
template <class Walk>
void single_tap_batch(const Evaluator& ev, std::span<const PcfQuery> queries, std::span<float> out, Walk&& walk) {
  const size_t n = std::min(queries.size(), out.size());
  const uint32_t finest = ev.finest_level();
  struct Kept {
    uint32_t level, shift;
    uint64_t x, y;  // texel >> shift
    float value;
  };
  constexpr uint32_t kKept = 4;
  Kept kept[kKept];
  uint32_t used = 0, next = 0, last = 0;
  for (size_t i = 0; i < n; ++i) {
    const PcfQuery& q = queries[i];
    if (q.r > 1 || q.level > finest) {
      out[i] = ev.pcf(q.level, q.x, q.y, q.r, q.receiver);
      continue;
    }
    const uint64_t top = (uint64_t(1) << q.level) - 1;  // pcf_tap's clamp of a 1-tap kernel
    const uint64_t x = std::min(q.x, top), y = std::min(q.y, top);
    const Kept* hit = nullptr;
    if (used) {
      const Kept& k = kept[last];
      if (k.level == q.level && (x >> k.shift) == k.x && (y >> k.shift) == k.y) hit = &k;
      for (uint32_t j = 0; !hit && j < used; ++j) {
        const Kept& g = kept[j];
        if (g.level == q.level && (x >> g.shift) == g.x && (y >> g.shift) == g.y) hit = &g, last = j;
      }
    }
    float value;
    if (hit) {
      value = hit->value;
    } else {
      const DepthRegion r = walk(q.level, x, y);
      value = r.value;
      kept[next] = Kept{q.level, r.shift, x >> r.shift, y >> r.shift, r.value};
      last = next;
      next = next + 1 == kKept ? 0 : next + 1;
      used = std::min(used + 1, kKept);
    }
    out[i] = q.receiver <= value ? 1.0f : 0.0f;
  }
}

}  // namespace st

// DAG-MH evaluator over a validated buffer: single lookups start at the skip table
// (§3.7); PCF walks once to the lowest common node of the kernel (MH §3.3, Fig. 5) and
// then resumes each tap from the last tap's final cursor when that lies on the tap's
// path, else from the common node (DAG-MH §3.5 "cache the last node traversed"), and a
// tap inside the region of texels sharing the last walked tap's answer
// (View::finish_region) takes that answer without a walk. depth_region reports that
// region to callers that cache across lookups (the client). Every tap runs the same walk as depth() from a cursor on its own path, so it reaches
// the same value index: pcf equals the average of single lookups exactly.
#include <algorithm>
#include <memory>

#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/dagmh_view.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st {
namespace {

class DagmhEvaluator final : public Evaluator, public WindowDepths, public TapWalks {
 public:
  DagmhEvaluator(const dagmh::View& view, std::span<const uint8_t> bytes,
                 std::shared_ptr<const dagmh::Dictionary> dict)
      : v_(view), bytes_(bytes.data()), size_(bytes.size()), dict_(std::move(dict)) {}

  uint32_t finest_level() const override { return v_.finest_level; }
  const dagmh::View& view() const { return v_; }

  float depth(uint32_t level, uint64_t x, uint64_t y) const override {
    clamp(level, x, y);
    return v_.value(v_.lookup_index(level, x, y));
  }

  DepthRegion depth_region(uint32_t level, uint64_t x, uint64_t y) const override {
    if (!texel_in_tile(level, x, y)) return {depth(level, x, y), 0};
    const dagmh::Cursor c = v_.descend(v_.start(level, level, x, y), level, level, x, y);
    uint32_t shift = 0;
    const uint32_t index = v_.finish_region(c, level, x, y, shift);
    return {v_.value(index), shift};
  }

  // Single taps (tap_batch.hpp's scheme, with wider kept regions): a tap inside a kept
  // answer's region takes its value without a walk (MH 2016 §3.3's last-sample cache); a
  // walk resumes from the deepest cursor of the last walk on its own path (DAG-MH §3.5:
  // the path above the highest bit in which the texels differ), a cursor the walk from the
  // skip table passes, so it ends at the same index. A kept region is a node's children
  // that share the answer (View::finish_siblings; below a missing child, every missing
  // child of its parent, which all answer the parent's `last`), so a row of taps crossing
  // a node walks once for its empty children, not once per child. out[i] equals
  // pcf(level, x, y, 1, receiver) bit for bit (tests/tiles/depth_region_test.cpp).
  void pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const override {
    const size_t n = std::min(queries.size(), out.size());
    WalkPath<dagmh::Cursor> path;
    struct Kept {  // the texels of `level` under node (x, y) `s` levels up, children in `mask`
      uint32_t level, s, mask;
      float value;
      uint64_t x, y;
      bool holds(uint32_t l, uint64_t tx, uint64_t ty) const {
        const uint32_t child = uint32_t((tx >> (s - 1)) & 1) | uint32_t(((ty >> (s - 1)) & 1) << 1);
        return l == level && (tx >> s) == x && (ty >> s) == y && ((mask >> child) & 1);
      }
    };
    constexpr uint32_t kKept = 4;
    Kept kept[kKept];
    uint32_t used = 0, next = 0, last = 0;
    for (size_t i = 0; i < n; ++i) {
      const PcfQuery& q = queries[i];
      if (q.r > 1 || q.level > v_.finest_level) {
        out[i] = pcf(q.level, q.x, q.y, q.r, q.receiver);
        continue;
      }
      const uint32_t level = q.level;
      const uint64_t top = (uint64_t(1) << level) - 1;  // pcf_tap's clamp of a 1-tap kernel
      const uint64_t x = std::min(q.x, top), y = std::min(q.y, top);
      const Kept* hit = nullptr;
      if (used) {
        if (kept[last].holds(level, x, y)) hit = &kept[last];
        for (uint32_t j = 0; !hit && j < used; ++j)
          if (kept[j].holds(level, x, y)) hit = &kept[j], last = j;
      }
      float value;
      if (hit) {
        value = hit->value;
      } else {
        const dagmh::Cursor c = descend_resumed(path, level, x, y);
        uint32_t index, s, mask;
        const uint32_t tag = c.ref & dagmh::kRefTagMask;
        if (tag == dagmh::kRefInner || tag == dagmh::kRefTreelet) {
          index = v_.finish_siblings(c, level, x, y, s, mask);
        } else {  // the missing child at c.level: its parent's other missing children answer alike
          index = c.last;
          s = level - c.level + 1;
          const uint32_t child = uint32_t((x >> (s - 1)) & 1) | uint32_t(((y >> (s - 1)) & 1) << 1);
          mask = 1u << child;
          if (c.level > path.lo) {  // the parent is on the path: an inner node (descend's step)
            const dagmh::Cursor& p = path.at[c.level - 1];
            mask = ~st::load_le<uint32_t>(v_.node_at(p.ref & dagmh::kRefIndexMask)) & dagmh::kNodeChildMask;
          }
        }
        value = v_.value(index);
        kept[next] = Kept{level, s, mask, value, x >> s, y >> s};
        last = next;
        next = next + 1 == kKept ? 0 : next + 1;
        used = std::min(used + 1, kKept);
      }
      out[i] = q.receiver <= value ? 1.0f : 0.0f;
    }
  }

  // WindowDepths::prefetch: the tile's first kPrefetchBytes (all of it for every tile of
  // the 4K^2 city's pack: at most 1,844 bytes, 529 on average; a larger tile's first bytes
  // hold its header, skip table and top nodes, which every walk reads) and the root node
  // when the pack dictionary holds it. A walk's loads depend on each other (node, child,
  // treelet, chunk, multipliers), so a tile whose lines left the cache otherwise costs a
  // batch several misses in a row; this asks for them all at once, when the client enters
  // the tile and before it collects the tile's taps.
  void prefetch() const noexcept override {
    const size_t n = std::min(size_, kPrefetchBytes);
    for (size_t o = 0; o < n; o += 64) __builtin_prefetch(bytes_ + o);
    if ((v_.root_ref & dagmh::kRefTagMask) == dagmh::kRefInner &&
        (v_.root_ref & dagmh::kRefIndexMask) < v_.dict_node_words)
      __builtin_prefetch(v_.node_at(v_.root_ref & dagmh::kRefIndexMask));
  }

  // TapWalks (tap_batch.hpp): the client's single taps, the walk's path kept by the caller.
  DepthRegion walk_tap(uint32_t level, uint64_t x, uint64_t y, TapPath& path) const noexcept override {
    return walk_resumed(tap_path<WalkPath<dagmh::Cursor>>(path, this), level, x, y);
  }
  // TapWalks::tap_run: the same walks, inlined into one loop over the run.
  TapRunEnd tap_run(const TapRun& run, TapPath& path) const noexcept override {
    WalkPath<dagmh::Cursor>& p = tap_path<WalkPath<dagmh::Cursor>>(path, this);
    return tap_run_loop(run, [&](uint32_t l, uint64_t x, uint64_t y) { return walk_resumed(p, l, x, y); });
  }

  DepthRegion walk_resumed(WalkPath<dagmh::Cursor>& path, uint32_t level, uint64_t x, uint64_t y) const {
    if (level >= std::size(path.at)) return depth_region(level, x, y);
    const dagmh::Cursor c = descend_resumed(path, level, x, y);
    uint32_t shift = 0;
    const uint32_t index = v_.finish_region(c, level, x, y, shift);
    return {v_.value(index), shift};
  }

  // The walk to (level, x, y) from the deepest cursor of the last walk on its own path
  // (DAG-MH §3.5), or from the skip table; `path` then holds this walk. Stops where
  // descend stops (a leaf, a treelet or a missing child); level < std::size(path.at).
  dagmh::Cursor descend_resumed(WalkPath<dagmh::Cursor>& path, uint32_t level, uint64_t x, uint64_t y) const {
    dagmh::Cursor c;
    uint32_t from = 0;
    if (path.resume(level, x, y, from)) {
      c = path.at[from];
      path.hi = from;
    } else {
      c = v_.start(level, level, x, y);
      path.lo = path.hi = c.level;
      path.at[c.level] = c;
    }
    while ((c.ref & dagmh::kRefTagMask) == dagmh::kRefInner && c.level < level) {
      c = v_.descend(c, c.level + 1, level, x, y);  // one level: descend's own step
      path.at[c.level] = c;
      path.hi = c.level;
    }
    path.level = level, path.x = x, path.y = y;
    return c;
  }

  // A kernel with no tap clamped: one count_window (each node over the window once, a
  // subtree whose texels share their answer counted whole). At the map's edge, the
  // kernel's window of distinct texels in one window walk (depth_window), its taps counted
  // from it (a clamped kernel reads its edge texels again).
  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const override {
    r = std::clamp<uint32_t>(r, 1, kMaxPcf);
    clamp(level, x, y);
    const uint64_t side = uint64_t(1) << level;
    const uint64_t x0 = pcf_tap(x, 0, r, side), x1 = pcf_tap(x, r - 1, r, side);
    const uint64_t y0 = pcf_tap(y, 0, r, side), y1 = pcf_tap(y, r - 1, r, side);
    const uint32_t w = uint32_t(x1 - x0 + 1), h = uint32_t(y1 - y0 + 1);
    if (w == r && h == r) return pcf_fraction(count_window(level, x0, y0, r, r, receiver), r);  // no tap clamped
    float win[kMaxPcf * kMaxPcf];
    depth_window(level, x0, y0, w, h, win);
    uint32_t lit = 0;
    for (uint32_t i = 0; i < r; ++i) {
      const float* col = win + (pcf_tap(x, i, r, side) - x0) * h;
      for (uint32_t j = 0; j < r; ++j) lit += receiver <= col[pcf_tap(y, j, r, side) - y0] ? 1u : 0u;
    }
    return float(lit) / float(r * r);
  }

  // WindowDepths (tap_batch.hpp). The lowest common node of the rectangle's corners (MH
  // Fig. 5); when that lies above the skip level (§3.7), each skip cell the rectangle
  // overlaps starts at its own entry, where depth() starts. Below it, every inner node
  // over the rectangle is stepped into once (descend's own step), and where depth()'s
  // walk ends (a treelet, a missing child, an inner node of `level`) each texel's index
  // comes from finish(), so each texel gets depth()'s value index.
  uint32_t depth_window(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                        float* out) const override {
    const uint64_t x1 = x0 + w - 1, y1 = y0 + h - 1;
    const uint64_t differ = (x0 ^ x1) | (y0 ^ y1);
    const uint32_t common = level - uint32_t(differ ? 64 - __builtin_clzll(differ) : 0);
    Values values;
    if (common < v_.skip_level && level >= v_.skip_level) {  // never with S = 0 (no table)
      const uint32_t cs = level - v_.skip_level;
      for (uint64_t cy = y0 >> cs; cy <= y1 >> cs; ++cy)
        for (uint64_t cx = x0 >> cs; cx <= x1 >> cs; ++cx) {
          const uint64_t ax = std::max(x0, cx << cs), bx = std::min(x1, ((cx + 1) << cs) - 1);
          const uint64_t ay = std::max(y0, cy << cs), by = std::min(y1, ((cy + 1) << cs) - 1);
          fill(v_.skip_entry(level, ax, ay), level, ax, ay, bx, by, x0, y0, h, out, values);
        }
      return 0;
    }
    const dagmh::Cursor base = v_.descend(v_.start(common, level, x0, y0), common, level, x0, y0);
    fill(base, level, x0, y0, x1, y1, x0, y0, h, out, values);
    // A missing child: every texel below it answers c.last (finish_region's rule).
    return (base.ref & dagmh::kRefTagMask) != dagmh::kRefInner && (base.ref & dagmh::kRefTagMask) != dagmh::kRefTreelet
               ? level - base.level
               : 0;
  }

  // WindowDepths::count_window: depth_window's walk (skip cells included), a part of the
  // window under a node where every texel's walk ends alike (a missing child, a treelet
  // node with no set bit below it) counted whole: one test per subtree (DAG-MH §3.5, MH
  // §3.3's hierarchical PCF).
  uint32_t count_window(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                        float receiver) const override {
    return count_window_taps(level, x0, y0, w, h, FlatTaps{receiver});
  }
  uint32_t count_window_plane(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                              const ReceiverPlane& p) const override {
    return count_window_taps(level, x0, y0, w, h, PlaneTaps{p, level});
  }
  // pcf's walks with the receiver plane (receiver_plane.hpp window_pcf_plane).
  float pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const override {
    if (level > v_.finest_level) return pcf_plane_extremes(*this, level, x, y, r, p);
    return window_pcf_plane(*this, level, x, y, r, p);
  }

 private:
  template <class Taps>
  uint32_t count_window_taps(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                             const Taps& taps) const {
    const uint64_t x1 = x0 + w - 1, y1 = y0 + h - 1;
    const uint64_t differ = (x0 ^ x1) | (y0 ^ y1);
    const uint32_t common = level - uint32_t(differ ? 64 - __builtin_clzll(differ) : 0);
    Values values;
    if (common < v_.skip_level && level >= v_.skip_level) {  // as depth_window
      const uint32_t cs = level - v_.skip_level;
      uint32_t lit = 0;
      for (uint64_t cy = y0 >> cs; cy <= y1 >> cs; ++cy)
        for (uint64_t cx = x0 >> cs; cx <= x1 >> cs; ++cx) {
          const uint64_t ax = std::max(x0, cx << cs), bx = std::min(x1, ((cx + 1) << cs) - 1);
          const uint64_t ay = std::max(y0, cy << cs), by = std::min(y1, ((cy + 1) << cs) - 1);
          lit += count(v_.skip_entry(level, ax, ay), level, ax, ay, bx, by, taps, values);
        }
      return lit;
    }
    const dagmh::Cursor base = v_.descend(v_.start(common, level, x0, y0), common, level, x0, y0);
    return count(base, level, x0, y0, x1, y1, taps, values);
  }

  // Taps of a window often share a value (a coarse node): each index decoded once.
  struct Values {
    uint32_t index[16];
    float value[16];
    Values() { std::fill(index, index + 16, ~0u); }
  };
  float value_of(uint32_t index, Values& vs) const {
    const uint32_t slot = index & 15;
    if (vs.index[slot] != index) vs.index[slot] = index, vs.value[slot] = v_.value(index);
    return vs.value[slot];
  }

  // depth_window below c, a cursor on the path of every texel of [ax, bx] x [ay, by].
  void fill(const dagmh::Cursor& c, uint32_t level, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by, uint64_t x0,
            uint64_t y0, uint32_t h, float* out, Values& vs) const {
    if ((c.ref & dagmh::kRefTagMask) != dagmh::kRefInner || c.level >= level) {
      if ((c.ref & dagmh::kRefTagMask) != dagmh::kRefInner && (c.ref & dagmh::kRefTagMask) != dagmh::kRefTreelet) {
        window_put(value_of(c.last, vs), ax, ay, bx, by, x0, y0, h, out);  // below a missing child
        return;
      }
      if ((c.ref & dagmh::kRefTagMask) == dagmh::kRefInner) {  // an inner node of `level`: one texel
        for (uint64_t x = ax; x <= bx; ++x)
          for (uint64_t y = ay; y <= by; ++y) out[(x - x0) * h + (y - y0)] = value_of(v_.finish(c, level, x, y), vs);
        return;
      }
      const uint8_t* t = v_.treelet_at(c.ref & dagmh::kRefIndexMask);
      const Treelet tr{c, st::load_le<uint64_t>(t), st::load_le<uint32_t>(t + 8),
                       std::min<uint32_t>(level - c.level, dagmh::kTreeletLevels - 1), level};
      fill_treelet(tr, 0, 0, c.last, ax, ay, bx, by, x0, y0, h, out, vs);
      return;
    }
    const uint64_t half = uint64_t(1) << (level - c.level - 1);
    const QuadSplit split(ax, ay, bx, by, half);
    for (uint32_t slot = 0; slot < 4; ++slot) {
      uint64_t cx0, cy0, cx1, cy1;
      if (!split.part(slot, cx0, cy0, cx1, cy1)) continue;
      // One step toward the part's first texel: the child in this slot.
      fill(v_.descend(c, c.level + 1, level, cx0, cy0), level, cx0, cy0, cx1, cy1, x0, y0, h, out, vs);
    }
  }

  // A treelet a window walk reached (View::finish's Alg. 1, depth first): a texel's
  // answer is the deepest set bit on its path down to treelet level `depth`, else the
  // cursor's `last`.
  struct Treelet {
    dagmh::Cursor c;
    uint64_t low;
    uint32_t high, depth, level;
  };
  // The part [ax, bx] x [ay, by] of the window under the treelet node at treelet level n,
  // bit position p; `index` answers when no deeper set bit does. Where no bit is set
  // strictly inside the node's subtree (or at treelet level `depth`), it answers the part.
  void fill_treelet(const Treelet& tr, uint32_t n, uint32_t p, uint32_t index, uint64_t ax, uint64_t ay, uint64_t bx,
                    uint64_t by, uint64_t x0, uint64_t y0, uint32_t h, float* out, Values& vs) const {
    if (dagmh::treelet_bit(tr.low, tr.high, p)) index = tr.c.base + dagmh::treelet_rank(tr.low, tr.high, p);
    if (n == tr.depth || !dagmh::treelet_any(tr.low, tr.high, p + 1, p + dagmh::kTreeletSubtree[n])) {
      window_put(value_of(index, vs), ax, ay, bx, by, x0, y0, h, out);
      return;
    }
    const uint64_t half = uint64_t(1) << (tr.level - tr.c.level - n - 1);
    const QuadSplit split(ax, ay, bx, by, half);
    for (uint32_t slot = 0; slot < 4; ++slot) {
      uint64_t cx0, cy0, cx1, cy1;
      if (!split.part(slot, cx0, cy0, cx1, cy1)) continue;
      fill_treelet(tr, n + 1, p + 1 + dagmh::kTreeletStride[n] * slot, index, cx0, cy0, cx1, cy1, x0, y0, h, out, vs);
    }
  }

  // The lit texels of [ax, bx] x [ay, by] (Taps: FlatTaps or PlaneTaps, receiver_plane.hpp):
  // fill's walk.
  template <class Taps>
  uint32_t count(const dagmh::Cursor& c, uint32_t level, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by,
                 const Taps& taps, Values& vs) const {
    const uint32_t tag = c.ref & dagmh::kRefTagMask;
    if (tag != dagmh::kRefInner || c.level >= level) {
      if (tag != dagmh::kRefInner && tag != dagmh::kRefTreelet)  // below a missing child
        return taps.count(value_of(c.last, vs), ax, ay, bx, by);
      if (tag == dagmh::kRefInner) {  // an inner node of `level`: one texel
        uint32_t lit = 0;
        for (uint64_t x = ax; x <= bx; ++x)
          for (uint64_t y = ay; y <= by; ++y) lit += taps.lit(value_of(v_.finish(c, level, x, y), vs), x, y) ? 1u : 0u;
        return lit;
      }
      const uint8_t* t = v_.treelet_at(c.ref & dagmh::kRefIndexMask);
      const Treelet tr{c, st::load_le<uint64_t>(t), st::load_le<uint32_t>(t + 8),
                       std::min<uint32_t>(level - c.level, dagmh::kTreeletLevels - 1), level};
      return count_treelet(tr, 0, 0, c.last, ax, ay, bx, by, taps, vs);
    }
    const uint64_t half = uint64_t(1) << (level - c.level - 1);
    const QuadSplit split(ax, ay, bx, by, half);
    uint32_t lit = 0;
    for (uint32_t slot = 0; slot < 4; ++slot) {
      uint64_t cx0, cy0, cx1, cy1;
      if (!split.part(slot, cx0, cy0, cx1, cy1)) continue;
      lit += count(v_.descend(c, c.level + 1, level, cx0, cy0), level, cx0, cy0, cx1, cy1, taps, vs);
    }
    return lit;
  }
  template <class Taps>
  uint32_t count_treelet(const Treelet& tr, uint32_t n, uint32_t p, uint32_t index, uint64_t ax, uint64_t ay,
                         uint64_t bx, uint64_t by, const Taps& taps, Values& vs) const {
    if (dagmh::treelet_bit(tr.low, tr.high, p)) index = tr.c.base + dagmh::treelet_rank(tr.low, tr.high, p);
    if (n == tr.depth || !dagmh::treelet_any(tr.low, tr.high, p + 1, p + dagmh::kTreeletSubtree[n]))
      return taps.count(value_of(index, vs), ax, ay, bx, by);
    const uint64_t half = uint64_t(1) << (tr.level - tr.c.level - n - 1);
    const QuadSplit split(ax, ay, bx, by, half);
    uint32_t lit = 0;
    for (uint32_t slot = 0; slot < 4; ++slot) {
      uint64_t cx0, cy0, cx1, cy1;
      if (!split.part(slot, cx0, cy0, cx1, cy1)) continue;
      lit += count_treelet(tr, n + 1, p + 1 + dagmh::kTreeletStride[n] * slot, index, cx0, cy0, cx1, cy1, taps, vs);
    }
    return lit;
  }

  bool texel_in_tile(uint32_t level, uint64_t x, uint64_t y) const {
    return level <= v_.finest_level && (x >> level) == 0 && (y >> level) == 0;
  }

  // Levels finer than the map answer like the finest level; coordinates are clamped to
  // the map (callers should not rely on either).
  void clamp(uint32_t& level, uint64_t& x, uint64_t& y) const {
    if (level > v_.finest_level) {
      const uint32_t shift = std::min<uint32_t>(level - v_.finest_level, 63);
      x >>= shift, y >>= shift;
      level = v_.finest_level;
    }
    const uint64_t top = (uint64_t(1) << level) - 1;
    x = std::min(x, top), y = std::min(y, top);
  }

  static constexpr size_t kPrefetchBytes = 2048;

  dagmh::View v_;
  const uint8_t* bytes_;  // the tile buffer the view points into (for prefetch)
  size_t size_;
  std::shared_ptr<const dagmh::Dictionary> dict_;  // kept alive while the view points into it
};

}  // namespace

std::unique_ptr<Evaluator> open_dagmh(std::span<const uint8_t> bytes) {
  return std::make_unique<DagmhEvaluator>(dagmh::validate(bytes), bytes, nullptr);
}

std::unique_ptr<Evaluator> open_dagmh(std::span<const uint8_t> bytes, std::shared_ptr<const dagmh::Dictionary> dict) {
  const dagmh::View view = dagmh::validate(bytes, dict.get());
  return std::make_unique<DagmhEvaluator>(view, bytes, std::move(dict));
}

const dagmh::View* dagmh_view(const Evaluator& ev) noexcept {
  const auto* d = dynamic_cast<const DagmhEvaluator*>(&ev);
  return d ? &d->view() : nullptr;
}

}  // namespace st

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
#include "tiles/core/encoding.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st {
namespace {

class DagmhEvaluator final : public Evaluator {
 public:
  DagmhEvaluator(const dagmh::View& view, std::shared_ptr<const dagmh::Dictionary> dict)
      : v_(view), dict_(std::move(dict)) {}

  uint32_t finest_level() const override { return v_.finest_level; }

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

  // Single taps through kept regions and walks resumed from the last walk's path
  // (tap_batch.hpp): a resumed walk starts at a cursor the same walk from the skip table
  // passes (the path above the highest differing bit), so it ends at the same index.
  void pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const override {
    WalkPath<dagmh::Cursor> path;
    single_tap_batch(*this, queries, out, [&](uint32_t level, uint64_t x, uint64_t y) -> DepthRegion {
      if (level >= std::size(path.at)) return depth_region(level, x, y);
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
      uint32_t shift = 0;
      const uint32_t index = v_.finish_region(c, level, x, y, shift);
      return {v_.value(index), shift};
    });
  }

  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const override {
    r = std::clamp<uint32_t>(r, 1, kMaxPcf);
    clamp(level, x, y);
    const uint64_t side = uint64_t(1) << level;
    uint64_t tx[kMaxPcf], ty[kMaxPcf];
    for (uint32_t i = 0; i < r; ++i) tx[i] = pcf_tap(x, i, r, side), ty[i] = pcf_tap(y, i, r, side);
    // Lowest common node: the taps agree on every coordinate bit above the highest bit
    // in which the kernel's extreme corners differ (MH Fig. 5).
    const uint64_t differ = (tx[0] ^ tx[r - 1]) | (ty[0] ^ ty[r - 1]);
    const uint32_t common = level - uint32_t(differ ? 64 - __builtin_clzll(differ) : 0);
    // A common node above the skip level is a worse start than each tap's own skip entry
    // (§3.7): then the taps start where depth() starts.
    const bool from_skip = common < v_.skip_level && level >= v_.skip_level;  // never with S = 0 (no table)
    const dagmh::Cursor lca =
        from_skip ? v_.skip_entry(level, tx[0], ty[0])
                  : v_.descend(v_.start(common, level, tx[0], ty[0]), common, level, tx[0], ty[0]);
    dagmh::Cursor cache = lca;
    uint64_t cache_x = tx[0], cache_y = ty[0];
    // Taps of a kernel often share a value (a coarse node): decode each index once.
    uint32_t cached_index[16];
    float cached_value[16];
    std::fill(cached_index, cached_index + 16, ~0u);
    // The region of texels sharing the last tap's answer (finish_region): taps inside it
    // are answered without a walk (MH §3.3's last-sample cache).
    uint32_t region_shift = 64, region_lit = 0;
    uint64_t region_x = 0, region_y = 0;
    uint32_t lit = 0;
    for (uint32_t j = 0; j < r; ++j)
      for (uint32_t i = 0; i < r; ++i) {
        if (region_shift < 64 && (tx[i] >> region_shift) == region_x && (ty[j] >> region_shift) == region_y) {
          lit += region_lit;
          continue;
        }
        const uint32_t shift = level - cache.level;
        const bool on_path = (tx[i] >> shift) == (cache_x >> shift) && (ty[j] >> shift) == (cache_y >> shift);
        const dagmh::Cursor c = v_.descend(on_path ? cache : from_skip ? v_.skip_entry(level, tx[i], ty[j]) : lca,
                                           level, level, tx[i], ty[j]);
        const uint32_t index = v_.finish_region(c, level, tx[i], ty[j], region_shift);
        const uint32_t slot = index & 15;
        if (cached_index[slot] != index) cached_index[slot] = index, cached_value[slot] = v_.value(index);
        region_lit = receiver <= cached_value[slot];
        lit += region_lit;
        region_x = tx[i] >> region_shift, region_y = ty[j] >> region_shift;
        cache = c, cache_x = tx[i], cache_y = ty[j];
      }
    return float(lit) / float(r * r);
  }

 private:
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

  dagmh::View v_;
  std::shared_ptr<const dagmh::Dictionary> dict_;  // kept alive while the view points into it
};

}  // namespace

std::unique_ptr<Evaluator> open_dagmh(std::span<const uint8_t> bytes) {
  return std::make_unique<DagmhEvaluator>(dagmh::validate(bytes), nullptr);
}

std::unique_ptr<Evaluator> open_dagmh(std::span<const uint8_t> bytes, std::shared_ptr<const dagmh::Dictionary> dict) {
  const dagmh::View view = dagmh::validate(bytes, dict.get());
  return std::make_unique<DagmhEvaluator>(view, std::move(dict));
}

}  // namespace st

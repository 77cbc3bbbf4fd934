// Top-down construction of the sparse multiresolution hierarchy (MH §3.1, Alg. 1).
//
// One global sort of all interval endpoints (lo and hi of every texel), then per node a
// sweep over the sorted endpoints of its still-uncovered texels finds the depth lying in
// the most of them (MH Fig. 3), the texels containing it are marked covered, and each
// child quadrant receives, by one linear extraction, the sorted endpoints of its
// uncovered texels; recursion stops where everything is covered.
//
// One correction to Alg. 1 as printed: a node's value answers for *every* texel of its
// region that no deeper valued node overrides, including texels an ancestor covered. So
// a node may only take a value inside the window C = intersection of the intervals of
// the already-covered texels of its region; when no uncovered interval meets C the node
// stays empty and the decision moves to its children (whose windows are wider).
// Invariant: every covered texel of a region contains the decision value of the region's
// nearest valued ancestor; so values are chosen inside D = C ∩ (the intervals newly
// covered), which keeps every level a complete map (ARCHITECTURE.md "Definitions").
// HNode::lo/hi is that D: a subset of the node's exact admissible interval, as coarse
// decisions are overridden by finer nodes for some of the texels they covered.
//
// Memory: endpoints as 64-bit keys in one buffer per depth (the list of the node being
// visited at that depth: 2·4^(n-d) entries), ~21 bytes per texel, plus a morton-ordered
// copy of the intervals and a covered flag per texel; the sort's scratch (16 bytes per
// texel) is freed before the recursion.
#include <algorithm>
#include <cfloat>
#include <cstring>

#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/mh_internal.hpp"

namespace st::mh_detail {
namespace {

// Endpoint entry: bits 63..32 the order-preserving key of the depth, bit 31 set for an
// upper bound (so at equal depth lower bounds sort first: closed intervals that touch
// count as overlapping), bits 30..0 the texel's morton index (n <= 14 needs 28).
constexpr uint64_t kHiBit = uint64_t(1) << 31;
constexpr uint64_t kTexelMask = kHiBit - 1;

// Float -> uint32 preserving order; -0.0 and 0.0 map to one key since they compare equal.
inline uint32_t order_key(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  if (u == 0x80000000u) u = 0;
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}
inline float key_value(uint32_t k) {
  uint32_t u = (k & 0x80000000u) ? (k ^ 0x80000000u) : ~k;
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

// LSD radix sort on bits 31..63 (the key and the hi flag), three passes of 11 bits; the
// texel bits below keep their (deterministic) input order.
void radix_sort(std::vector<uint64_t>& a) {
  constexpr uint32_t kBits = 11, kBuckets = 1u << kBits;
  std::vector<uint64_t> tmp(a.size());
  for (uint32_t shift = 31; shift < 64; shift += kBits) {
    std::vector<size_t> count(kBuckets + 1, 0);
    for (uint64_t e : a) ++count[((e >> shift) & (kBuckets - 1)) + 1];
    for (uint32_t b = 0; b < kBuckets; ++b) count[b + 1] += count[b];
    for (uint64_t e : a) tmp[count[(e >> shift) & (kBuckets - 1)]++] = e;
    a.swap(tmp);
  }
}

class TopDown {
 public:
  TopDown(const IntervalTile& tile, uint32_t n) : n_(n), iv_(size_t(1) << (2 * n)), covered_(iv_.size(), 0) {
    for (size_t m = 0; m < iv_.size(); ++m) iv_[m] = tile.at(morton_compact(m), morton_compact(m >> 1));
    lists_.resize(n + 1);
    for (uint32_t d = 0; d <= n; ++d) lists_[d].resize(size_t(2) << (2 * (n - d)));
    auto& root = lists_[0];
    for (size_t m = 0; m < iv_.size(); ++m) {
      root[2 * m] = uint64_t(order_key(iv_[m].lo)) << 32 | m;
      root[2 * m + 1] = uint64_t(order_key(iv_[m].hi)) << 32 | kHiBit | m;
    }
    radix_sort(root);
    h_.depth = n;
    h_.levels.resize(n + 1);
  }

  Hierarchy run() && {
    visit(0, 0, lists_[0].size(), false, 0, 0);
    return std::move(h_);
  }

 private:
  // Node at depth d whose region is the texels [base, base + 4^(n-d)) in morton order;
  // lists_[d][0, len) holds the sorted endpoints of its uncovered texels (len > 0);
  // [clo, chi] is the intersection of its covered texels' intervals if has_window.
  void visit(uint32_t d, uint64_t base, size_t len, bool has_window, float clo, float chi) {
    const uint32_t shift = 2 * (n_ - d);
    auto& level = h_.levels[d];
    if (d > 0) h_.levels[d - 1].back().child_mask |= uint8_t(1u << ((base >> shift) & 3));
    const size_t self = level.size();
    level.push_back(HNode{base >> shift, 0, 0, 0, 0, 0});

    // Sweep for the mode (MH Fig. 3) restricted to the window.
    const uint64_t* list = lists_[d].data();
    const uint32_t kclo = has_window ? order_key(clo) : 0, kchi = has_window ? order_key(chi) : ~0u;
    bool window_point_done = !has_window;
    int count = 0, best = 0;
    uint32_t best_key = 0;
    for (size_t i = 0; i < len; ++i) {
      uint32_t k = uint32_t(list[i] >> 32);
      bool is_hi = list[i] & kHiBit;
      if (!window_point_done && (k > kclo || (k == kclo && is_hi))) {
        window_point_done = true;  // count == number of intervals containing clo
        if (count > best) best = count, best_key = kclo;
      }
      if (is_hi) {
        --count;
      } else if (++count > best && k >= kclo && k <= kchi) {
        best = count, best_key = k;
      }
    }

    size_t remaining = len;
    if (best > 0) {
      const float v = key_value(best_key);
      float dlo = has_window ? clo : -FLT_MAX, dhi = has_window ? chi : FLT_MAX;
      for (size_t i = 0; i < len; ++i) {
        if (list[i] & kHiBit) continue;
        size_t t = list[i] & kTexelMask;
        const Interval& x = iv_[t];
        if (x.lo <= v && v <= x.hi) {
          covered_[t] = 1;
          dlo = std::max(dlo, x.lo), dhi = std::min(dhi, x.hi);
          remaining -= 2;
        }
      }
      ST_CHECK(dlo <= v && v <= dhi);
      HNode& node = level[self];
      node.has_value = 1, node.lo = dlo, node.hi = dhi, node.value = safe_midpoint(dlo, dhi);
    }
    if (remaining == 0 || d == n_) {
      ST_CHECK(remaining == 0);  // a single uncovered texel always covers itself
      return;
    }

    // Linear extraction of each quadrant's uncovered endpoints (order is kept, so the
    // child's list is sorted), then the child's window from its covered texels.
    const uint64_t quad = uint64_t(1) << (shift - 2);
    for (uint64_t q = 0; q < 4; ++q) {
      const uint64_t qbase = base + q * quad;
      uint64_t* out = lists_[d + 1].data();
      size_t qlen = 0;
      for (size_t i = 0; i < len; ++i) {
        uint64_t t = list[i] & kTexelMask;
        if (t - qbase < quad && !covered_[t]) out[qlen++] = list[i];
      }
      if (qlen == 0) continue;
      bool window = qlen != 2 * quad;
      float wlo = -FLT_MAX, whi = FLT_MAX;
      if (window) {
        for (uint64_t t = qbase; t < qbase + quad; ++t)
          if (covered_[t]) wlo = std::max(wlo, iv_[t].lo), whi = std::min(whi, iv_[t].hi);
      }
      visit(d + 1, qbase, qlen, window, wlo, whi);
    }
    ST_CHECK(level[self].has_value || level[self].child_mask != 0);
  }

  uint32_t n_;
  std::vector<Interval> iv_;                // texels in morton order
  std::vector<uint8_t> covered_;            // per texel (morton): answered by a node above
  std::vector<std::vector<uint64_t>> lists_;  // lists_[d]: the visited node's endpoints
  Hierarchy h_;
};

}  // namespace

Hierarchy build_top_down(const IntervalTile& tile, uint32_t n) { return TopDown(tile, n).run(); }

}  // namespace st::mh_detail

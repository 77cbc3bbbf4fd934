// An order in which to answer a batch of single taps so that taps near each other in the
// map follow each other: by the Morton (Z-order) code of their texels. A batch from a
// camera comes in screen order, and on a real level (open meshes: almost every texel its
// own value, so a walk's region is one texel) every tap walks its tile's tree; screen
// neighbours several texels apart alternate between tiles and subtrees, so each walk
// re-enters a tile through the page table and re-reads nodes that left the cache since.
// In Morton order a tile's taps come together (tiles are aligned quadtree squares, so each
// is one run of the Z curve) and consecutive walks share their paths down to the node
// above both, which the resumed walks of tap_batch.hpp then skip, their nodes still in L1.
//
// The key is 16 bits: the Morton code of the 8 highest bits in which the batch's texels
// (scaled to the finest level) differ, so a batch spanning 2^h texels is ordered by
// cells of 2^(h-8) texels, at most a few taps each, kept in batch order within a cell (two
// stable counting passes). It changes only the order: every tap's answer is its own.
#pragma once
#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <span>

#include "tiles/core/evaluator.hpp"

namespace st {

// Most taps one tap_order call orders (order entries are 16-bit).
inline constexpr size_t kTapOrderMax = 1024;
// Fewer taps than this are answered in their own order (the sort would cost more than a
// short batch can save).
inline constexpr size_t kTapOrderMin = 32;

namespace detail {
// Bit i of b moved to bit 2i (the Morton interleave of one byte).
inline constexpr std::array<uint16_t, 256> kMortonSpread = [] {
  std::array<uint16_t, 256> t{};
  for (uint32_t b = 0; b < 256; ++b) {
    uint32_t s = 0;
    for (uint32_t i = 0; i < 8; ++i) s |= ((b >> i) & 1u) << (2 * i);
    t[b] = uint16_t(s);
  }
  return t;
}();
}  // namespace detail

// Writes into order[0, n) a permutation of 0 .. n-1 (n = queries.size() <= kTapOrderMax)
// that takes the taps in Morton order of their texels (each scaled to level `finest` by
// shifting left). Stable within a cell of the key. False, order untouched, when some query
// is not a single tap at a level <= finest (a PCF kernel: a batch of kernels sliding
// along a row is best answered in its own order, remote_map.hpp). No allocation.
inline bool tap_order(std::span<const PcfQuery> queries, uint32_t finest, uint16_t* order) {
  const size_t n = std::min(queries.size(), kTapOrderMax);
  if (n == 0) return true;
  auto scaled = [finest](const PcfQuery& q, uint64_t v) { return v << (finest - std::min(q.level, finest)); };
  // One pass: the refusal's test, and the bits in which the texels differ.
  const uint64_t x0 = scaled(queries[0], queries[0].x), y0 = scaled(queries[0], queries[0].y);
  uint64_t differ = 0;
  uint32_t refuse = 0;
  for (size_t i = 0; i < n; ++i) {
    const PcfQuery& q = queries[i];
    refuse |= uint32_t(q.r > 1) | uint32_t(q.level > finest);
    differ |= (scaled(q, q.x) ^ x0) | (scaled(q, q.y) ^ y0);
  }
  if (refuse) return false;
  const uint32_t high = uint32_t(std::bit_width(differ));
  const uint32_t shift = high > 8 ? high - 8 : 0;
  // Each tap as key << 16 | index (pass 2 reads its key without a second load), sorted
  // by the key's low byte, then stably by its high byte: a 16-bit LSD radix sort.
  uint32_t keyed[kTapOrderMax], tmp[kTapOrderMax];
  uint32_t lo[256] = {}, hi[256] = {};
  for (size_t i = 0; i < n; ++i) {
    const PcfQuery& t = queries[i];
    const uint32_t kx = uint32_t(scaled(t, t.x) >> shift) & 255u;
    const uint32_t ky = uint32_t(scaled(t, t.y) >> shift) & 255u;
    const uint32_t k = uint32_t(detail::kMortonSpread[kx] | detail::kMortonSpread[ky] << 1);
    keyed[i] = k << 16 | uint32_t(i);
    ++lo[k & 255u], ++hi[k >> 8];
  }
  uint32_t sum_lo = 0, sum_hi = 0;
  for (uint32_t d = 0; d < 256; ++d) {
    const uint32_t a = lo[d], b = hi[d];
    lo[d] = sum_lo, hi[d] = sum_hi;
    sum_lo += a, sum_hi += b;
  }
  for (size_t i = 0; i < n; ++i) tmp[lo[(keyed[i] >> 16) & 255u]++] = keyed[i];
  for (size_t j = 0; j < n; ++j) order[hi[tmp[j] >> 24]++] = uint16_t(tmp[j]);
  return true;
}

// The order a batch of at most kTapOrderMax queries is answered in: tap_order's where it
// applies and the batch is large enough to pay (kTapOrderMin), else the batch's own.
inline void tap_order_or_identity(std::span<const PcfQuery> queries, uint32_t finest, uint16_t* order) {
  const size_t n = std::min(queries.size(), kTapOrderMax);
  if (!(n >= kTapOrderMin && tap_order(queries.first(n), finest, order)))
    for (size_t k = 0; k < n; ++k) order[k] = uint16_t(k);
}

}  // namespace st

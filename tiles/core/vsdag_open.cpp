// Voxel shadow DAG lookups (voxelized shadows 2014 §4, §6.2) over a validated buffer.
#include <algorithm>
#include <bit>
#include <cmath>
#include <memory>

#include "tiles/core/encoding.hpp"
#include "tiles/core/vsdag_evaluator.hpp"

namespace st {

using namespace vsdag;

VsdagEvaluator::VsdagEvaluator(std::span<const uint8_t> bytes) : v_(validate(bytes)) {
  std::fill(std::begin(level_of_bit_), std::end(level_of_bit_), int8_t(-1));
  for (uint32_t i = 0; i < v_.shape.levels; ++i)
    if (v_.shape.split[i] & kSplitXy) level_of_bit_[v_.shape.xy_shift[i]] = int8_t(i);
}

void VsdagEvaluator::clamp(uint32_t& level, uint64_t& x, uint64_t& y) const {
  const uint32_t finest = v_.shape.xy_bits;
  if (level > finest) {
    const uint32_t shift = std::min<uint32_t>(level - finest, 63);
    x >>= shift, y >>= shift;
    level = finest;
  }
  const uint64_t top = (uint64_t(1) << level) - 1;
  x = std::min(x, top) << (finest - level), y = std::min(y, top) << (finest - level);
  level = finest;
}

float VsdagEvaluator::depth(uint32_t level, uint64_t x, uint64_t y) const {
  clamp(level, x, y);
  const uint32_t f = v_.first_shadow_slab(x, y);
  if (f >= v_.slabs()) return 1.0f;
  return std::nextafter(float(f) / float(v_.slabs()), -1.0f);
}

bool VsdagEvaluator::lit_voxel(uint32_t level, uint64_t x, uint64_t y, float receiver) const {
  clamp(level, x, y);
  const int32_t k = receiver_slab(receiver, v_.shape.z_bits);
  if (k == kReceiverLit) return true;
  if (k == kReceiverShadowed) return false;
  return v_.lit(x, y, uint32_t(k));
}

float VsdagEvaluator::pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const {
  r = std::clamp<uint32_t>(r, 1, kMaxPcf);
  if (level >= v_.shape.xy_bits) {
    uint32_t l = level;
    clamp(l, x, y);
    return pcf_wide(x, y, r, receiver);
  }
  const uint64_t side = uint64_t(1) << level;
  uint32_t lit = 0;
  for (uint32_t j = 0; j < r; ++j)
    for (uint32_t i = 0; i < r; ++i) lit += lit_voxel(level, pcf_tap(x, i, r, side), pcf_tap(y, j, r, side), receiver);
  return float(lit) / float(r * r);
}

namespace {

// One leaf block's walk, resumable from any level of the previous block's path (§6.2
// "we can significantly reduce the time taken in traversal by comparing the paths of two
// consecutive leaf nodes and backtracking only to the level at which the paths diverge").
struct Walk {
  uint32_t node[kMaxLevels + 1];  // node[i]: word offset of the node at inner level i (levels: the z-node)
  int32_t reached = -1;           // deepest valid node[] entry; -1: the grid cell was uniform
  uint32_t state = kShadow;       // the block's state; kMixed: `leaf` holds its mask
  uint64_t leaf = 0;
};

}  // namespace

float VsdagEvaluator::pcf_wide(uint64_t x, uint64_t y, uint32_t r, float receiver, bool best_order) const {
  r = std::clamp<uint32_t>(r, 1, kMaxWidePcf);
  const uint64_t side = uint64_t(1) << v_.shape.xy_bits;
  x = std::min(x, side - 1), y = std::min(y, side - 1);
  const int64_t x0 = int64_t(x) - int64_t((r - 1) / 2), y0 = int64_t(y) - int64_t((r - 1) / 2);
  const int64_t x1 = x0 + r - 1, y1 = y0 + r - 1;
  const int32_t k = receiver_slab(receiver, v_.shape.z_bits);
  if (k == kReceiverLit) return 1.0f;
  if (k == kReceiverShadowed) return 0.0f;
  if (x0 < 0 || y0 < 0 || uint64_t(x1) >= side || uint64_t(y1) >= side) {
    // Taps clamped at the tile's edge repeat texels: count them one by one.
    uint32_t lit = 0;
    for (uint32_t j = 0; j < r; ++j)
      for (uint32_t i = 0; i < r; ++i) lit += v_.lit(pcf_tap(x, i, r, side), pcf_tap(y, j, r, side), uint32_t(k));
    return float(lit) / float(r * r);
  }
  const Shape& s = v_.shape;
  const uint32_t bx0 = uint32_t(x0 >> 3), by0 = uint32_t(y0 >> 3);
  const uint32_t nbx = uint32_t(x1 >> 3) - bx0 + 1, nby = uint32_t(y1 >> 3) - by0 + 1;  // <= 3 each
  // Backtracking cost of a step between neighbouring blocks along one axis: the levels
  // below the one splitting the highest coordinate bit in which they differ.
  auto step_cost = [&](uint32_t a, uint32_t b) {
    const uint32_t bit = 31 - uint32_t(std::countl_zero((a ^ b) << 3));
    const int32_t l = level_of_bit_[bit];
    return l < 0 ? s.levels + 1 : s.levels - uint32_t(l);
  };
  // Serpentine order along the cheaper major axis (§6.2 "Traversal order": backtrack to
  // the higher of the two divergence levels as rarely as possible).
  bool rows_first = true;
  if (best_order) {
    uint32_t cx = 0, cy = 0;
    for (uint32_t i = 0; i + 1 < nbx; ++i) cx += step_cost(bx0 + i, bx0 + i + 1);
    for (uint32_t j = 0; j + 1 < nby; ++j) cy += step_cost(by0 + j, by0 + j + 1);
    rows_first = nby * cx + cy <= nbx * cy + cx;
  }
  Walk w;
  uint64_t px = 0, py = 0;
  bool first = true;
  uint32_t lit = 0;
  const uint32_t n = nbx * nby;
  for (uint32_t t = 0; t < n; ++t) {
    uint32_t i, j;
    if (rows_first) j = t / nbx, i = t % nbx, i = (best_order && (j & 1)) ? nbx - 1 - i : i;
    else i = t / nby, j = t % nby, j = (i & 1) ? nby - 1 - j : j;
    const uint64_t bx = (bx0 + i) * 8ull, by = (by0 + j) * 8ull;
    // Resume: the level of the highest bit in which this block's texel differs from the last.
    int32_t from = -1;
    bool same = false;
    if (!first) {
      const uint64_t d = (bx ^ px) | (by ^ py);
      const int32_t l = level_of_bit_[63 - std::countl_zero(d)];
      if (l >= 0) {
        if (w.reached < l) same = true;  // both blocks inside one uniform node
        else from = l;
      }
    }
    if (!same) {
      int32_t lv = from;
      bool done = false;
      if (lv < 0) {
        const uint32_t cell = v_.grid_word(s.grid_cell(bx, by, uint32_t(k)));
        if ((cell >> kStateShift) != kMixed) w.reached = -1, w.state = cell >> kStateShift, done = true;
        else w.node[0] = cell & kIndexMask, lv = 0;
      }
      for (uint32_t l = uint32_t(lv); !done && l < s.levels; ++l) {
        const uint32_t mask = v_.node_word(w.node[l]), c = s.child(l, bx, by, uint32_t(k)), st = (mask >> (2 * c)) & 3;
        if (st != kMixed) w.reached = int32_t(l), w.state = st, done = true;
        else w.node[l + 1] = v_.node_word(w.node[l] + 1 + ref_slot(mask, c));
      }
      if (!done) {
        const uint32_t zn = w.node[s.levels], mask = v_.node_word(zn), c = uint32_t(k) & 7, st = (mask >> (2 * c)) & 3;
        w.reached = int32_t(s.levels), w.state = st;
        if (st == kMixed) w.leaf = v_.leaf(v_.node_word(zn + 1 + ref_slot(mask, c)));
      }
    }
    first = false, px = bx, py = by;
    if (w.state == kShadow) continue;
    // The kernel's part of this block as a mask of the 8x8 leaf (§6.2, Fig. 6).
    const uint32_t ca = uint32_t(std::max<int64_t>(x0, int64_t(bx)) - int64_t(bx));
    const uint32_t cb = uint32_t(std::min<int64_t>(x1, int64_t(bx) + 7) - int64_t(bx));
    const uint32_t ra = uint32_t(std::max<int64_t>(y0, int64_t(by)) - int64_t(by));
    const uint32_t rb = uint32_t(std::min<int64_t>(y1, int64_t(by) + 7) - int64_t(by));
    const uint64_t row = ((uint64_t(2) << cb) - 1) & ~((uint64_t(1) << ca) - 1);
    uint64_t mask = 0;
    for (uint32_t q = ra; q <= rb; ++q) mask |= row << (8 * q);
    lit += bit_count(w.state == kLit ? mask : mask & w.leaf);
  }
  return float(lit) / float(r * r);
}

std::unique_ptr<Evaluator> open_vsdag(std::span<const uint8_t> bytes) {
  return std::make_unique<VsdagEvaluator>(bytes);
}

}  // namespace st

// The voxel shadow DAG evaluator (VSDAG.md): lit tests by one walk to a voxel (§4),
// depth values from each column's transition (VSDAG.md "Depth values"), and PCF up to
// 17x17 by counting lit bits of 8x8x1 leaf masks (§6.2 "Filtered lookups") with the leaf
// visit order that backtracks least (§6.2 "Traversal order").
//
// Thread safety: const methods may be called concurrently. Lookups never allocate. The
// evaluator borrows the buffer given to open_vsdag (encoding.hpp).
#pragma once
#include <cstdint>
#include <span>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/vsdag_view.hpp"

namespace st {

class VsdagEvaluator final : public Evaluator {
 public:
  // Validates `bytes` (vsdag::validate) or throws st::FormatError.
  explicit VsdagEvaluator(std::span<const uint8_t> bytes);

  uint32_t finest_level() const override { return v_.shape.xy_bits; }
  // pred(f / 2^z_bits) for the column's first shadowed slab f (1.0 when none): the lit
  // test on it answers exactly as lit_voxel. Coarser levels answer with the column of the
  // texel's first finest-level descendant.
  float depth(uint32_t level, uint64_t x, uint64_t y) const override;
  // r <= kMaxPcf; at the finest level the same counting as pcf_wide.
  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const override;

  // One voxel: is the receiver lit at texel (x, y) of `level` (coarser levels as depth())?
  bool lit_voxel(uint32_t level, uint64_t x, uint64_t y, float receiver) const;

  // r x r PCF at the finest level, 1 <= r <= kMaxWidePcf, taps clamped to the tile
  // (pcf_tap); exactly (lit taps) / (r * r) in float. Kernels inside the tile count bits
  // in at most 9 leaves; `best_order` false visits them in raster order (the paper's
  // baseline, for the benchmark), true in the serpentine order that backtracks least.
  float pcf_wide(uint64_t x, uint64_t y, uint32_t r, float receiver, bool best_order = true) const;
  static constexpr uint32_t kMaxWidePcf = 17;

  const vsdag::View& view() const { return v_; }

 private:
  void clamp(uint32_t& level, uint64_t& x, uint64_t& y) const;
  vsdag::View v_;
  int8_t level_of_bit_[kMaxLevel + 1] = {};  // inner level splitting coordinate bit b; -1: the grid
};

}  // namespace st

// Reading a deep shadow tile (deep_format.hpp, DEEP.md) in place: open() validates
// every header field, directory entry and vertex once, so lookups need no bounds checks
// and every texel is a valid visibility function (VisibilityFunction::check() rules).
//
// Lookups (DSM 2000 §3.4, §5.3) never allocate: a point lookup reads one texel, bilinear
// four, trilinear eight; each texel costs a binary search over its vertices. Positions
// (u, v) are tile-local in [0, 1) x [0, 1) (texel centres at (i + 0.5) / side); filters
// clamp to the tile's edge texels (across tiles, the caller blends). A receiver exactly
// at a step's depth sees the value before the step (visibility_function.hpp).
//
// The view borrows the buffer: it must outlive the view and stay unchanged.
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "tiles/core/deep_format.hpp"
#include "tiles/core/visibility_function.hpp"

namespace st {

class DeepTileView {
 public:
  // Validates `bytes` (the whole tile, nothing after it). Throws st::FormatError naming
  // `what` and the first field at fault: magic, version, sizes, truncation at any
  // length, trailing bytes, offsets out of order, flags, non-finite or decreasing
  // depths, more than two vertices at one depth, increasing values, channels.
  static DeepTileView open(std::span<const uint8_t> bytes, const std::string& what = "deep tile");

  uint32_t side_bits() const { return side_bits_; }
  uint32_t mip_count() const { return side_bits_ + 1; }
  uint32_t side(uint32_t mip) const { return deep::mip_side(side_bits_, mip); }
  float epsilon() const { return epsilon_; }

  // Texel (x, y) of mip `mip` at depth z (x, y < side(mip), mip < mip_count()).
  std::array<float, 3> transmittance(uint32_t x, uint32_t y, float z, uint32_t mip) const;
  uint32_t vertex_count(uint32_t x, uint32_t y, uint32_t mip) const;
  bool monochrome(uint32_t x, uint32_t y, uint32_t mip) const;
  // The filters compute in float (u, v rounded to float first; DEEP.md "Lookups"), so a
  // GPU repeats them bit for bit (gpu/shaders/st_deep.glsl).
  // Bilinear between the four texel centres around (u, v) at one mip (clamped at edges).
  std::array<float, 3> bilinear(double u, double v, float z, uint32_t mip) const;
  // Trilinear: bilinear at floor(lod) and floor(lod) + 1, blended; lod clamped to
  // [0, mip_count() - 1] (NaN: 0).
  std::array<float, 3> trilinear(double u, double v, float z, double lod) const;
  // A footprint `width` wide (tile-local units) centred on (u, v): trilinear at the mip
  // whose texels are about as wide as the footprint, lod = e + (m - 1) for
  // float(width * side(0)) = m * 2^e (log2, linear between powers of two), 0 below 1.
  std::array<float, 3> filtered(double u, double v, float z, double width) const;

  // The stored function of a texel (allocates; tools and tests).
  VisibilityFunction function(uint32_t x, uint32_t y, uint32_t mip) const;

 private:
  struct Texel {
    const uint8_t* depths;
    const uint8_t* values;
    uint32_t n;
    bool mono;
  };
  Texel texel(uint32_t x, uint32_t y, uint32_t mip) const;
  static std::array<float, 3> eval(const Texel& t, float z);
  std::array<float, 3> bilinear_f(float u, float v, float z, uint32_t mip) const;
  // bilinear at mip m0 and m0 + 1 blended a (1 - f) + b f (f == 0 or m0 the last: m0 alone).
  std::array<float, 3> mip_blend(float u, float v, float z, uint32_t m0, float f) const;

  const uint8_t* dir_ = nullptr;
  const uint8_t* data_ = nullptr;
  uint32_t side_bits_ = 0;
  float epsilon_ = 0;
};

}  // namespace st

// The light-space texels of one world point in a run of consecutive light samples, computed
// together (the soft lookups of StackLookup and StackMap, MH 2016 §4: one point against
// the N slices of a stack). Sample w's texel and receiver depth are
//   (x, y) = LightSpace::texel_of(level, u, v), d = float(lp.d), lp = samples[w].to_light(p),
// and this computes exactly that, bit for bit (tested): the same double operations on the
// same values in the same order, two samples per vector operation (GCC/Clang vector
// extensions, 128-bit: SSE2 and NEON). No multiply-add may be contracted on either side
// (light.cpp, light_set.cpp and sample_texels.cpp are compiled with -ffp-contract=off).
//
// Per kind (light.hpp), every sample in its own frame; a ground-frame sun path whose
// samples share one frame (light_set.hpp "Frames", the usual case) takes the point's
// offsets along the frame's axes once and each sample's (u, v) from them in two operations.
// A set mixing kinds (possible only in a hand-made file) takes the scalar path.
//
// Thread safety: const after construction; run() writes only its output.
#pragma once
#include <cstdint>
#include <vector>

#include "tiles/core/light.hpp"

namespace st {

class SampleTexels {
 public:
  // The longest run one call computes.
  static constexpr uint32_t kRun = 32;
  // The finest level this class addresses (texel coordinates are 32-bit).
  static constexpr uint32_t kMaxLevel = 31;

  struct Run {
    uint32_t x[kRun], y[kRun];
    float d[kRun];
  };

  SampleTexels() = default;
  // `level` <= kMaxLevel: the map the texels index (2^level a side). Copies what it needs.
  SampleTexels(const std::vector<LightSpace>& samples, uint32_t level);

  uint32_t size() const { return count_; }
  uint32_t level() const { return level_; }

  // Samples w0 .. w0 + n - 1 of point p: out.x[i], out.y[i], out.d[i] for sample w0 + i;
  // entries from n on are unspecified. Preconditions (asserted): n <= kRun,
  // w0 + n <= size().
  void run(const Vec3d& p, uint32_t w0, uint32_t n, Run& out) const noexcept;

  // One sample the scalar way (LightSpace::to_light + texel_of): the reference.
  void texel(const Vec3d& p, uint32_t w, uint32_t& x, uint32_t& y, float& d) const noexcept;

 private:
  enum class Path : uint8_t { scalar, sun, spot, spot_window, ground_shared };
  std::vector<LightSpace> samples_;
  uint32_t count_ = 0, level_ = 0;
  Path path_ = Path::scalar;
  // Per-sample parameters, structure of arrays with one pad sample (an odd run's second
  // lane reads it): origin, axis_u, axis_v, forward (sun_ground: the depth axis n),
  // extent, near, far - near, and (c_u, c_v) of a spot_window or (k_u, k_v) of the ground
  // frame (LightSpace::ray_axis() . axis_u, . axis_v). ground_shared reads only extent
  // and (k_u, k_v) per sample.
  std::vector<double> ox_, oy_, oz_, ux_, uy_, uz_, vx_, vy_, vz_, fx_, fy_, fz_, ext_, near_, span_, c0_, c1_;
};

}  // namespace st

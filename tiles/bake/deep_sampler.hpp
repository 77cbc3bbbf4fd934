// Per-texel visibility functions of a deep shadow map (Lokovic and Veach 2000, DSM 2000
// §3.1-§3.2), traced with Embree through the partial occluders of a scene.
//
// Per texel, samples_per_side^2 rays on a jittered grid over the texel (one random point
// in each cell of an s x s grid; the jitter is a function of (seed, level, x, y, cell)
// alone, so a texel's function does not depend on the region or thread that traced it).
// Each ray's transmittance function (§3.2, Figure 4) is the product of
//   - the surface transmittance: every crossing of a partial mesh composited in depth
//     order (a step of the mesh's per-channel `transmit`; an alpha-tested mesh blocks
//     only where its texture is solid at the hit's interpolated UV, nearest texel), and
//   - the volume transmittance: exp(-tau) of the optical depth of every volume, marched
//     at most half a voxel per step (Volume::march), linear in depth between steps,
// evaluated at the union of both functions' vertices and linear in between (as §3.2).
// Crossings of one mesh at one depth are one crossing (a ray through a shared edge).
//
// Pixel filter: a box over the texel (every sample weight 1/N; §3.1 leaves the filter
// free). With a box, the average of a 2x2 block of texels is exactly the box-filtered
// texel of the next coarser level, so mip levels built by averaging (§5.3) are the same
// filter at every level. Samples are combined exactly by the sweep of §5.1
// (average_sweep) and then compressed with compress(f, epsilon) (§3.3).
//
// Only partial meshes (Mesh::partial()) and volumes are seen: opaque casters are the
// opaque map's (opaque_part()), and a receiver's light is the product of the two.
// Depths are light-space d (light.hpp); for a spot light the volume march is in world
// distance, so no correction factor is needed (§3.2 footnote 3).
//
// Colour (§5.2): a function is monochrome when every channel of every vertex agrees
// (every transmit and sigma it met was grey); else three channels are stored.
//
// Thread safety: the constructor builds the Embree scene; the rest is const and may run
// concurrently. Errors: st::Error for bad scenes, regions or options.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "tiles/bake/depth_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/visibility_function.hpp"

namespace st {

struct DeepSampleOptions {
  uint32_t samples_per_side = 4;  // N = samples_per_side^2 rays per texel, 1..64
  uint64_t seed = 1;
  // Compression bound (§3.3); negative: the paper's 0.25 / sqrt(N) (DSM 2000 §4).
  double epsilon = -1;
  double effective_epsilon() const;
};

struct DeepSampleStats {
  uint64_t texels = 0, rays = 0, crossings = 0, volume_steps = 0;
  uint64_t vertices_in = 0;   // vertices of the averaged functions, before compression
  uint64_t vertices_out = 0;  // after compression
  uint64_t monochrome = 0;    // texels whose function is monochrome
  double seconds = 0;
};

// One region of texels: row-major, `width * height` functions.
struct DeepRegion {
  TraceRegion region;
  std::vector<VisibilityFunction> functions;
  const VisibilityFunction& at(uint32_t i, uint32_t j) const {
    return functions[size_t(j) * region.width + i];
  }
};

class DeepSampler {
 public:
  // Builds the Embree scene of the partial meshes; validates alpha textures, volumes,
  // UVs (one entry per triangle when a mesh is alpha-tested) and mesh ranges.
  DeepSampler(const Scene& scene, const LightSpace& light);
  ~DeepSampler();
  DeepSampler(const DeepSampler&) = delete;
  DeepSampler& operator=(const DeepSampler&) = delete;

  // The transmittance function along the light ray through (u, v) of the light's image
  // plane (a single sample, uncompressed; the brute-force reference).
  VisibilityFunction ray_function(double u, double v) const;
  // Texel (x, y) of level `level`: the box-filtered average of its samples, uncompressed
  // (compressed when `compress_it`).
  VisibilityFunction texel(uint32_t level, uint64_t x, uint64_t y,
                           const DeepSampleOptions& options, bool compress_it = true) const;
  // Every texel of a region, compressed (TBB over rows). Same region limits as the
  // depth-bounds tracer, and at most 2^20 texels (functions live in memory).
  DeepRegion trace(const TraceRegion& region, const DeepSampleOptions& options,
                   DeepSampleStats* stats = nullptr, bool compress_it = true) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace st

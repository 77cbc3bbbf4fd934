// `shadowtile build` for a light set (tiles/core/light_set.hpp): traces every sample's
// slice in that sample's light space (the light-space rasterizer for sun samples, which
// gives the canonical bounds bit for bit; the Embree DepthBoundsTracer for the area
// light's perspective samples), builds the stack's octree (MH 2016 §4), cuts it at a skip
// level in (x, y, w) and writes a stack pack (tiles/PACK.md "Stack packs").
//
// Out of core (tiles/encode/stack_blocked.hpp): each slice is traced in regions and
// spilled to a file next to the output in blocks of the octree; the blocks are read back
// and reduced one at a time and the tiles streamed into the pack, so memory is one traced
// region, one block (2^24 texels) and the octree's top levels, whatever N x R^2. The spill
// needs 8 bytes per texel per slice on disk for the build's duration (checked first).
// Limits: slices up to 2^16 a side, kMaxStackTexels texels in all.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include "tiles/bake/depth_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/encode/mh_octree_build.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/core/light_set.hpp"

namespace st {

// The blocked build's limit: 2^34 texels (N x R^2; 128 GiB of spilled intervals).
inline constexpr uint64_t kMaxStackTexels = uint64_t(1) << 34;
// trace_stack's (whole stack in memory): 2^28 texels, 2 GiB of intervals.
inline constexpr uint64_t kMaxResidentStackTexels = uint64_t(1) << 28;

struct StackBuildOptions {
  uint32_t map_level = 10;  // slices are 2^map_level a side
  std::optional<uint32_t> skip_level;
  uint32_t tile_bytes = 64 * 1024;
  int compression_level = 6;
  std::string scene_spec, light_spec;
  std::function<void(uint32_t done, uint32_t total)> progress;  // slices traced
  uint64_t block_texels = kStackBlockTexels;
  std::string spill_dir;  // default: the output's directory
  StackCells cells = StackCells::smaller;  // each cell's form (stack_slices_encode.hpp)
  // A cell over tile_bytes split below K rather than the whole cut moved deeper
  // (BlockedStackCut, stack_grid.hpp "Split cells"; every reader, the GPU passes included,
  // takes both). Off: the uniform cut of earlier versions (a version-1 grid).
  bool split_cells = true;
  // A per-slice cell's slices may be plane tiles where those store smaller, as a 2D pack's
  // (stack_slices_encode.hpp; feature plane_tiles). Off: DAG-MH or MMH slices only.
  bool planes = true;
};

struct StackBuildReport {
  uint32_t slices = 0, map_level = 0, skip_level = 0, block_level = 0;
  uint64_t slice_cells = 0;  // tiles in the per-slice form
  uint64_t split_cells = 0;  // cells split below the skip level
  uint64_t cells = 0, tiles = 0, max_tile_bytes = 0, octree_nodes = 0, pack_bytes = 0, spill_bytes = 0, blocks = 0;
  double trace_seconds = 0, octree_seconds = 0, cut_seconds = 0, write_seconds = 0;
  bool exit_depths = false;
  std::string bounds_by;  // "raster" (sun samples) or "embree"
};

// The scene's ground for a sun path's ground frame (light_set.hpp "Frames"): the height
// of its largest total area of horizontal up-facing triangles (all three vertices at one
// height), when that area is at least a quarter of the scene box's horizontal extent;
// NaN otherwise (the frame then takes the box's bottom).
double scene_ground_height(const Scene& scene);
// LightSet::fit of `spec` to the scene, with ground=Y resolved from the scene
// (scene_ground_height) when a ground-frame sun path leaves it unset; the returned set's
// spec records it. What a stack build and the benchmark fit.
LightSet fit_light_set(const Scene& scene, LightSetSpec spec);

// Throws st::Error (one line) for a stack it cannot hold or trace.
StackBuildReport build_stack_pack(const Scene& scene, const LightSetSpec& spec, const StackBuildOptions& o,
                                  const std::string& out);

// Traces every slice of `set` into `spill` (block-aligned regions of about 2^22 texels), the
// rasterizer for sun samples, Embree otherwise. `slice` (if given) also gets each whole
// slice (one slice in memory: a benchmark's 2D comparison). `embree_only`: Embree for
// every sample (the benchmark's before/after). Returns "raster" or "embree".
std::string trace_stack_to_spill(const Scene& scene, const LightSet& set, StackSpill& spill, bool* exit_depths = nullptr,
                                 const std::function<void(uint32_t, uint32_t)>& progress = {},
                                 const std::function<void(uint32_t w, const IntervalTile&)>& slice = {},
                                 bool embree_only = false);

// One slice's bounds of a region as a stack build traces it: the rasterizer for a sun
// sample, Embree for a spot or when `embree` (a pack recorded as built by Embree; the two
// may differ in edge texels, so `verify` re-traces with the recorded builder).
IntervalTile trace_slice(const Scene& scene, const LightSpace& light, const TraceRegion& region, bool embree = false);

// The N slices of level `level` of a light set, traced into memory (tests, small
// benchmarks): at most kMaxResidentStackTexels texels.
IntervalStack trace_stack(const Scene& scene, const LightSet& set, uint32_t level, bool* exit_depths = nullptr,
                          const std::function<void(uint32_t, uint32_t)>& progress = {});

}  // namespace st

// `shadowtile build` for a light set (tiles/core/light_set.hpp): traces every sample's
// slice with the DepthBoundsTracer in that sample's light space, builds the stack's
// octree (MH 2016 §4), cuts it at a skip level in (x, y, w) and writes a stack pack
// (tiles/PACK.md "Stack packs").
//
// Whole-stack, in memory: the N slices' intervals (8 bytes a texel) and the octree are
// held at once, so the build refuses stacks above kMaxStackTexels texels (N x R^2, 2 GiB
// of intervals), naming the figures; out-of-core construction per skip cell, as the 2D
// build does, is not done yet.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include "tiles/bake/scene.hpp"
#include "tiles/build/mh_octree_build.hpp"
#include "tiles/core/light_set.hpp"

namespace st {

inline constexpr uint64_t kMaxStackTexels = uint64_t(1) << 28;

struct StackBuildOptions {
  uint32_t map_level = 10;  // slices are 2^map_level a side
  std::optional<uint32_t> skip_level;
  uint32_t tile_bytes = 64 * 1024;
  int compression_level = 6;
  std::string scene_spec, light_spec;
  std::function<void(uint32_t done, uint32_t total)> progress;  // slices traced
};

struct StackBuildReport {
  uint32_t slices = 0, map_level = 0, skip_level = 0;
  uint64_t cells = 0, tiles = 0, max_tile_bytes = 0, octree_nodes = 0, pack_bytes = 0;
  double trace_seconds = 0, octree_seconds = 0, cut_seconds = 0, write_seconds = 0;
  bool exit_depths = false;
};

// Throws st::Error (one line) for a stack it cannot hold or trace.
StackBuildReport build_stack_pack(const Scene& scene, const LightSetSpec& spec, const StackBuildOptions& o,
                                  const std::string& out);

// The N slices of level `level` of a light set, traced (tests, verify): the fitted set
// and the stack. Same limit.
IntervalStack trace_stack(const Scene& scene, const LightSet& set, uint32_t level, bool* exit_depths = nullptr,
                          const std::function<void(uint32_t, uint32_t)>& progress = {});

}  // namespace st

#include "tiles/bake/stack_build.hpp"

#include <algorithm>
#include <chrono>

#include "common/error.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/build/stack_pack.hpp"

namespace st {
namespace {

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

IntervalStack trace_stack(const Scene& scene, const LightSet& set, uint32_t level, bool* exit_depths,
                          const std::function<void(uint32_t, uint32_t)>& progress) {
  const uint32_t n = set.size();
  const uint64_t side = uint64_t(1) << level;
  if (level > 13 || double(n) * double(side) * double(side) > double(kMaxStackTexels))
    throw Error("build: a stack of " + std::to_string(n) + " slices of " + std::to_string(side) + "^2 texels exceeds " +
                "the 2^28 texels (2 GiB of intervals) a whole-stack build holds; lower --resolution or samples=");
  IntervalStack stack{level, n, {}};
  stack.data.reserve(size_t(side * side) * n);
  for (uint32_t w = 0; w < n; ++w) {
    DepthBoundsTracer tracer(scene, set.samples[w]);
    if (exit_depths) *exit_depths = tracer.traces_exit_depths();
    const IntervalTile t = tracer.trace({level, 0, 0, uint32_t(side), uint32_t(side)});
    stack.data.insert(stack.data.end(), t.data.begin(), t.data.end());
    if (progress) progress(w + 1, n);
  }
  return stack;
}

StackBuildReport build_stack_pack(const Scene& scene, const LightSetSpec& spec, const StackBuildOptions& o,
                                  const std::string& out) {
  StackBuildReport r;
  const LightSet set = LightSet::fit(spec, scene.bounds());
  auto t0 = std::chrono::steady_clock::now();
  IntervalStack stack = trace_stack(scene, set, o.map_level, &r.exit_depths, o.progress);
  r.trace_seconds = since(t0);
  t0 = std::chrono::steady_clock::now();
  const OctHierarchy h = build_octree(stack);
  stack.data = {};
  r.octree_seconds = since(t0);
  r.octree_nodes = h.node_count();
  t0 = std::chrono::steady_clock::now();
  StackCut cut = cut_stack(h, o.skip_level, o.tile_bytes);
  r.cut_seconds = since(t0);
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = spec.to_string();
  if (cut.grid.spec.size() > kStackMaxSpecBytes) throw Error("build: the light set's spec exceeds 4096 bytes");
  StackPackParams pp;
  pp.tile_bytes = o.tile_bytes;
  pp.flags = r.exit_depths ? uint32_t(kFeatureExitDepths) : 0u;
  pp.scene_hash = scene.content_hash();
  pp.compression_level = o.compression_level;
  pp.build_params = {{"light", o.light_spec.empty() ? spec.to_string() : o.light_spec},
                     {"scene", o.scene_spec.empty() ? scene.name : o.scene_spec},
                     {"slices", std::to_string(set.size())},
                     {"tool", "shadowtile 0.1.0"}};
  std::sort(pp.build_params.begin(), pp.build_params.end());
  t0 = std::chrono::steady_clock::now();
  r.pack_bytes = write_stack_pack(out, cut, pp);
  r.write_seconds = since(t0);
  r.slices = set.size();
  r.map_level = o.map_level;
  r.skip_level = cut.grid.skip_level;
  r.cells = cut.grid.entries.size();
  r.tiles = cut.tiles.size();
  r.max_tile_bytes = cut.max_tile_bytes;
  return r;
}

}  // namespace st

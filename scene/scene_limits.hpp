// What reading one scene file may cost (SECURITY.md "Reading files: packs and scenes").
// Files are read in a child process (scene_isolated.hpp) under `memory_bytes` and
// `seconds`; the triangle and texel budgets are counted before anything is allocated for
// them. A file past a limit is an st::Error of one line naming the limit and the CLI's
// --scene-limits key that raises it. The defaults hold scenes of a few million triangles
// and a few large alpha textures; raise them for bigger ones.
#pragma once
#include <cstdint>
#include <string>

#include "scene/scene.hpp"

namespace st {

struct SceneLimits {
  uint64_t memory_bytes = uint64_t(1) << 30;  // the reader's memory above its start; 0: unlimited
  double seconds = 50;                         // the reader's wall time; 0: unlimited
  uint64_t max_triangles = uint64_t(1) << 22;  // triangles emitted, mesh instances counted
  uint64_t max_texels = uint64_t(1) << 28;     // alpha-texture texels, all textures together
  bool isolate = true;  // false: read in this process (no memory or time limit; trusted files)
};

// Parses "memory=MIB,seconds=S,triangles=N,texels=N,isolate=0|1" (any subset, in any
// order; empty: `limits` unchanged) over `limits`; "none" lifts every limit but the child process (crashes and
// recursion stay contained). Throws st::Error naming the bad key or value.
SceneLimits parse_scene_limits(const std::string& text, SceneLimits limits = {});

// load_scene (scene.hpp) under `limits`; the two-argument form uses SceneLimits{}.
Scene load_scene(const std::string& spec, const SceneOptions& options, const SceneLimits& limits);

}  // namespace st

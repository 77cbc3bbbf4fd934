// The deep loopback tests' pack: a scene's opaque part as a depth map (level 5, skip
// level 2, 8 KiB tiles) with the scene's deep tiles appended, as `shadowtile build` writes
// a pack with a deep part.
#pragma once
#include <string>

#include "tests/client/loopback.hpp"
#include "tiles/bake/deep_build.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "tiles/core/deep_pack.hpp"

namespace st::looptest {

constexpr uint32_t kDeepLevel = 5;

inline DeepSampleOptions deep_options(double epsilon) {
  DeepSampleOptions so;
  so.samples_per_side = 2;
  so.epsilon = epsilon;
  return so;
}

// Builds the pack at `path` and returns its deep tiles (the caller keeps them alive
// while anything views their bytes).
inline DeepMapBuild build_deep_pack(const Scene& s, const LightSpace& light, const DeepSampleOptions& so,
                                    const std::string& path) {
  DeepMapBuild deep = build_deep_tiles(DeepSampler(s, light), kDeepLevel, 2, so, 8192);
  MapBuildOptions o;
  o.map_level = kDeepLevel;
  o.skip_level = 2;
  o.encoding = first_encoding();
  o.tile_bytes = 8192;
  o.before_finish = [&](PackWriter& w) { append_deep_map(w, deep, so.epsilon, so.samples_per_side); };
  build_map(opaque_part(s), light, o, path);
  return deep;
}

}  // namespace st::looptest

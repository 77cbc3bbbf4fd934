// Every texel of packs built from open geometry, in every encoding, with several skip
// levels and tile bounds: the pack's value lies in a fresh trace's [lo, hi] bit-exactly.
// On open meshes hi = lo, so the build (traced cell by cell) and the check (one region)
// must agree on every depth to the bit: the canonical depth (canonical_depth.hpp). The
// fresh trace uses the builder the build used (the rasterizer for these suns).
#include <gtest/gtest.h>

#include <filesystem>

#include "interval_fields.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace {

namespace fs = std::filesystem;

struct BuildCase {
  const char* scene;
  Encoding encoding;
  uint32_t skip_level, tile_bytes;
  const char* light;
  uint32_t level;  // the map is 2^level texels a side (three levels less under small scale)
};

Scene scene_named(const std::string& name) {
  if (name == "hazards") return test::hazard_town();
  if (name == "rotated_terrain") return test::rotated_terrain();
  return test::all_open(load_scene("procedural:city,size=3,seed=9"));
}

class OpenScenesLossless : public ::testing::TestWithParam<BuildCase> {};

TEST_P(OpenScenesLossless, EveryTexelOfThePackIsWithinTheFreshTrace) {
  const BuildCase& c = GetParam();
  const Scene scene = scene_named(c.scene);
  const LightSpace light = LightSpace::fit(LightSpec::parse(c.light), scene.bounds());
  const uint32_t L = fields::small_test_scale() ? c.level - 3 : c.level;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = c.encoding;
  o.skip_level = std::min(c.skip_level, L - 2);
  o.tile_bytes = c.tile_bytes;
  fs::create_directories(SHADOWTILE_TEST_TMP);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/open_" + c.scene + "_" +
                           to_string(c.encoding) + "_" + std::to_string(c.skip_level) + ".pack";
  const MapBuildReport r = build_map(scene, light, o, path);
  EXPECT_FALSE(r.exit_depths) << "every mesh here is open";
  const TraceRegion all{L, 0, 0, 1u << L, 1u << L};
  const IntervalTile truth =
      r.builder == "raster" ? RasterBounds(scene, light).trace(all) : DepthBoundsTracer(scene, light).trace(all);
  uint64_t hit = 0;
  for (const Interval& iv : truth.data) hit += iv.lo < kLitDepth;
  EXPECT_GT(hit, truth.data.size() / 32);
  PackEvaluator eval(PackReader::open(path));
  EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }),
            "");
  fs::remove(path);
}

INSTANTIATE_TEST_SUITE_P(
    All, OpenScenesLossless,
    ::testing::Values(BuildCase{"hazards", Encoding::mh, 3, 64 * 1024, "sun:azimuth=30,elevation=50", 11},
                      BuildCase{"hazards", Encoding::mmh, 4, 4096, "sun:azimuth=30,elevation=50", 10},
                      BuildCase{"hazards", Encoding::dagmh, 5, 64 * 1024, "sun:azimuth=250,elevation=0.5", 11},
                      BuildCase{"town", Encoding::mh, 4, 64 * 1024, "sun:azimuth=30,elevation=50", 11},
                      BuildCase{"town", Encoding::mmh, 8, 64 * 1024, "sun:azimuth=30,elevation=50", 10},
                      BuildCase{"town", Encoding::dagmh, 4, 2048, "sun:azimuth=30,elevation=89.99", 10},
                      BuildCase{"rotated_terrain", Encoding::dagmh, 3, 64 * 1024,
                                "sun:azimuth=120,elevation=20", 10}),
    [](const auto& info) {
      return std::string(info.param.scene) + "_" + to_string(info.param.encoding) + "_K" +
             std::to_string(info.param.skip_level);
    });

}  // namespace
}  // namespace st

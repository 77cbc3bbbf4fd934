// The two depth-bounds builders of a map build (map_build.hpp BoundsBuilder): packs built
// with the light-space rasterizer and with the Embree tracer are each lossless against a
// fresh trace by their own builder on every texel, on a city, terrain, a hairball, open
// soups and under a grazing sun, and the two builders' (lo, hi) are equal on every texel
// (both evaluate the canonical coverage; tracer_raster_exact_test.cpp has more scenes).
// The builder is recorded in the pack, and the choice follows the light.
#include <gtest/gtest.h>

#include <filesystem>

#include "common/error.hpp"
#include "interval_fields.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace {

namespace fs = std::filesystem;

std::string tmp_path(const std::string& name) {
  fs::create_directories(SHADOWTILE_TEST_TMP);
  return std::string(SHADOWTILE_TEST_TMP) + "/" + name;
}

std::string recorded_builder(const std::string& path) {
  const auto reader = PackReader::open(path);
  for (const auto& [k, v] : reader->params())
    if (k == "builder") return v;
  return "";
}

void check_scene(const Scene& scene, const char* sun) {
  const LightSpace light = LightSpace::fit(LightSpec::parse(sun), scene.bounds());
  const uint32_t L = fields::small_test_scale() ? 6 : 7, side = 1u << L;
  const RasterBounds raster(scene, light);
  const DepthBoundsTracer tracer(scene, light);
  const IntervalTile by_raster = raster.trace({L, 0, 0, side, side});
  const IntervalTile by_tracer = tracer.trace({L, 0, 0, side, side});
  uint64_t differ = 0;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      const Interval a = by_raster.at(x, y), b = by_tracer.at(x, y);
      if (a.lo == b.lo && a.hi == b.hi) continue;
      ++differ;
      const Interval ref = raster.brute_force_texel(L, x, y);
      EXPECT_TRUE(ref.lo == a.lo && ref.hi == a.hi) << scene.name << " " << sun << " texel " << x << "," << y;
    }
  EXPECT_EQ(differ, 0u) << scene.name << " " << sun;

  for (BoundsBuilder b : {BoundsBuilder::raster, BoundsBuilder::embree}) {
    MapBuildOptions o;
    o.map_level = L;
    o.skip_level = 2;
    o.encoding = Encoding::dagmh;
    o.builder = b;
    const std::string path = tmp_path(std::string("builder_") + to_string(b) + ".pack");
    const MapBuildReport r = build_map(scene, light, o, path);
    EXPECT_EQ(r.builder, to_string(b));
    EXPECT_EQ(recorded_builder(path), to_string(b));
    const IntervalTile& truth = b == BoundsBuilder::raster ? by_raster : by_tracer;
    PackEvaluator eval(PackReader::open(path));
    EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }), "")
        << scene.name << " " << sun << " built by " << to_string(b);
  }
}

TEST(BoundsBuilder, BothBuildersGiveLosslessPacksAndAgreeOnEveryTexel) {
  check_scene(make_procedural("procedural:city,size=3,seed=5"), "sun:azimuth=30,elevation=50");
  check_scene(test::rotated_terrain(), "sun:azimuth=30,elevation=50");
  check_scene(make_procedural("procedural:hairball,count=8,segments=12"), "sun:azimuth=30,elevation=50");
  check_scene(test::all_open(test::hazard_town()), "sun:azimuth=30,elevation=50");
  check_scene(test::hazard_town(), "sun:azimuth=77,elevation=0.5");  // grazing
}

TEST(BoundsBuilder, AutoPicksRasterForTheSunAndEmbreeOtherwise) {
  const Scene s = make_procedural("procedural:cube");
  const LightSpace sun = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  const LightSpace spot =
      LightSpace::fit(LightSpec::parse("spot:pos=3,6,2,target=0,0.5,0,fov=50"), s.bounds());
  EXPECT_EQ(resolve_builder(BoundsBuilder::automatic, sun, IntervalRule::closed_objects), BoundsBuilder::raster);
  EXPECT_EQ(resolve_builder(BoundsBuilder::automatic, spot, IntervalRule::closed_objects), BoundsBuilder::embree);
  EXPECT_EQ(resolve_builder(BoundsBuilder::automatic, sun, IntervalRule::static_geometry), BoundsBuilder::raster);
  EXPECT_EQ(resolve_builder(BoundsBuilder::raster, sun, IntervalRule::static_geometry), BoundsBuilder::raster);
  EXPECT_THROW(resolve_builder(BoundsBuilder::raster, spot, IntervalRule::closed_objects), Error);
  EXPECT_THROW(parse_bounds_builder("gpu"), Error);
  MapBuildOptions o;
  o.map_level = 5;
  o.skip_level = 1;
  const std::string path = tmp_path("builder_spot.pack");
  EXPECT_EQ(build_map(s, spot, o, path).builder, "embree");
  EXPECT_EQ(recorded_builder(path), "embree");
}

}  // namespace
}  // namespace st

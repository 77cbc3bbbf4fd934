// The lossless invariant on real traced scenes: cube, city, terrain and
// hairball, every encoding, both constructions, every texel; and a million random texels
// of an 8K^2 city built tile by tile (MH §3.1 tiled construction).
#include <gtest/gtest.h>

#include "interval_fields.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"

namespace st {
namespace {

struct SceneCase {
  const char* spec;
  const char* light;
};

class EncodingsOnScenes : public ::testing::TestWithParam<SceneCase> {};

TEST_P(EncodingsOnScenes, EveryTexelOfEveryEncodingIsLossless) {
  const SceneCase c = GetParam();
  Scene scene = load_scene(c.spec);
  LightSpace light = LightSpace::fit(LightSpec::parse(c.light), scene.bounds());
  DepthBoundsTracer tracer(scene, light);
  const uint32_t L = fields::small_test_scale() ? 10 : 11;
  IntervalTile truth = tracer.trace({L, 0, 0, 1u << L, 1u << L});
  for (MhConstruction m : {MhConstruction::bottom_up, MhConstruction::top_down}) {
    Hierarchy h = build_hierarchy(truth, m);
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      SCOPED_TRACE(std::string(c.spec) + " " + to_string(e) +
                   (m == MhConstruction::bottom_up ? " bottom-up" : " top-down"));
      std::vector<uint8_t> bytes = encode(h, e);
      auto eval = open_encoded(e, bytes);
      ASSERT_EQ(eval->finest_level(), L);
      EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval->depth(L, i, j); }), "");
      // PCF equals the average of single lookups on real data too.
      for (uint32_t k = 0; k < 200; ++k) {
        uint32_t x = (k * 7919u) % (1u << L), y = (k * 104729u) % (1u << L);
        float recv = truth.at(x, y).lo + 0.001f;
        uint32_t lit = 0;
        for (uint32_t j = 0; j < 3; ++j)
          for (uint32_t i = 0; i < 3; ++i)
            lit += recv <= eval->depth(L, pcf_tap(x, i, 3, 1u << L), pcf_tap(y, j, 3, 1u << L));
        ASSERT_EQ(eval->pcf(L, x, y, 3, recv), float(lit) / 9.0f);
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    Scenes, EncodingsOnScenes,
    ::testing::Values(SceneCase{"procedural:cube", "sun:azimuth=20,elevation=35"},
                      SceneCase{"procedural:city", "sun:azimuth=30,elevation=50"},
                      SceneCase{"procedural:terrain", "sun:azimuth=120,elevation=25"},
                      SceneCase{"procedural:hairball", "sun:azimuth=10,elevation=70"}),
    [](const auto& info) {
      std::string s = info.param.spec;
      return s.substr(s.find(':') + 1);
    });

TEST(EncodingsOnScenes, MillionRandomTexelsOfATiledCity) {
  Scene scene = load_scene("procedural:city");
  LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  DepthBoundsTracer tracer(scene, light);
  const bool small = fields::small_test_scale();
  const uint32_t L = small ? 12 : 13, T = 11;  // tiles of 2048^2, stitched
  const uint32_t g = L - T, n = 1u << g;
  std::vector<Hierarchy> parts;
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i)
      parts.push_back(build_hierarchy(tracer.trace({L, uint64_t(i) << T, uint64_t(j) << T, 1u << T, 1u << T})));
  Hierarchy h = stitch_tiles(std::move(parts), g);
  fields::Rng rng(7);
  const uint32_t blocks = small ? 2000 : 15625;  // 8x8 texels each: 1M texels at full scale
  for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
    SCOPED_TRACE(to_string(e));
    std::vector<uint8_t> bytes = encode(h, e);
    auto eval = open_encoded(e, bytes);
    uint64_t bad = 0;
    for (uint32_t b = 0; b < blocks; ++b) {
      uint64_t x0 = rng.below((1u << L) - 8), y0 = rng.below((1u << L) - 8);
      IntervalTile t = tracer.trace({L, x0, y0, 8, 8});
      for (uint32_t j = 0; j < 8; ++j)
        for (uint32_t i = 0; i < 8; ++i) bad += !t.at(i, j).contains(eval->depth(L, x0 + i, y0 + j));
    }
    EXPECT_EQ(bad, 0u);
  }
}

}  // namespace
}  // namespace st

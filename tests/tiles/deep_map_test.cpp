// A deep map cut into deep tiles (DSM 2000 §5.4): every texel of the map answers what
// the sampler gives for it, empty tiles are not stored (a scene without partial
// occluders has no deep data), and bad tiles are refused.
#include <gtest/gtest.h>

#include "common/error.hpp"
#include "tiles/bake/deep_build.hpp"
#include "tiles/core/deep_map.hpp"

namespace st {
namespace {

TEST(DeepMap, EveryTexelAnswersTheSampledFunction) {
  const Scene s = make_procedural("procedural:forest,trees=2,leaves=60,size=12,translucency=0.5");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=55"), s.bounds());
  const DeepSampler sampler(s, light);
  DeepSampleOptions o;
  o.samples_per_side = 2;
  o.epsilon = 0.02;
  const uint32_t level = 4, bits = 2;
  const DeepMapBuild b = build_deep_tiles(sampler, level, bits, o);
  EXPECT_EQ(b.tiles.size() + b.empty_tiles, 16u);
  EXPECT_GT(b.tiles.size(), 0u);
  EXPECT_GT(b.empty_tiles, 0u);  // trees leave part of the ground in the open
  DeepMap map(level, bits);
  for (const DeepTileBytes& t : b.tiles) map.add_tile(t.tx, t.ty, t.bytes);
  EXPECT_EQ(map.tile_count(), b.tiles.size());
  for (uint32_t y = 0; y < 16; ++y)
    for (uint32_t x = 0; x < 16; ++x) {
      const VisibilityFunction f = sampler.texel(level, x, y, o);
      const double u = (x + 0.5) / 16, v = (y + 0.5) / 16;
      for (float z : {0.1f, 0.3f, 0.5f, 0.7f, 0.9f}) {
        const auto got = map.transmittance(u, v, z);
        const auto want = f.eval(z);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], want[c], deep::kQuantisation + 1e-6) << x << "," << y;
        // A footprint of one texel at its centre is the texel itself.
        const auto one = map.filtered(u, v, z, 1.0 / 16);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(one[c], got[c], 1e-5) << x << "," << y;
      }
    }
  // Wide footprints and hostile coordinates still answer in [0, 1].
  for (double w : {0.0, 0.3, 10.0, -1.0, double(NAN)})
    for (float t : map.filtered(0.4, NAN, 0.5f, w)) EXPECT_TRUE(t >= 0 && t <= 1);
}

TEST(DeepMap, OpaqueScenesHaveNoDeepTilesAndBadTilesAreRefused) {
  const Scene city = make_procedural("procedural:city,size=2");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=55"), city.bounds());
  const DeepSampler sampler(city, light);
  DeepSampleOptions o;
  o.samples_per_side = 1;
  const DeepMapBuild b = build_deep_tiles(sampler, 3, 2, o);
  EXPECT_TRUE(b.tiles.empty());
  EXPECT_EQ(b.empty_tiles, 4u);
  EXPECT_THROW(build_deep_tiles(sampler, 3, 4, o), Error);
  const std::vector<VisibilityFunction> lit(16);
  const std::vector<uint8_t> tile = encode_deep_tile(lit, 2, 0.01);
  DeepMap map(3, 2);
  map.add_tile(1, 0, tile);
  EXPECT_THROW(map.add_tile(1, 0, tile), Error);  // twice
  EXPECT_THROW(map.add_tile(2, 0, tile), Error);  // outside
  const std::vector<uint8_t> small = encode_deep_tile(std::vector<VisibilityFunction>(4), 1, 0.01);
  EXPECT_THROW(map.add_tile(0, 0, small), FormatError);  // another side
  std::vector<uint8_t> cut(tile.begin(), tile.end() - 1);
  EXPECT_THROW(map.add_tile(0, 1, cut), FormatError);
  EXPECT_EQ(map.transmittance(0.1, 0.1, 0.5f), (std::array<float, 3>{1, 1, 1}));
}

}  // namespace
}  // namespace st

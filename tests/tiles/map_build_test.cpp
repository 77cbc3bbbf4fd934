// End-to-end map builds: scene -> depth bounds (the rasterizer, the default for a sun)
// -> MH -> encode -> pack, then the pack is checked against a fresh trace of every texel (the lossless invariant), across
// encodings, a killed-and-resumed build, and a region of a 2^20 map.
#include <gtest/gtest.h>

#include <filesystem>

#include "interval_fields.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "common/error.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace map_build_test {

namespace fs = std::filesystem;

std::string tmp_path(const std::string& name) {
  fs::create_directories(SHADOWTILE_TEST_TMP);
  return std::string(SHADOWTILE_TEST_TMP) + "/" + name;
}

struct Built {
  Scene scene;
  LightSpace light;
};

Built city() {
  Built b{load_scene("procedural:city,size=4,seed=3"), {}};
  b.light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), b.scene.bounds());
  return b;
}

// Every texel of the finest level lies in the traced interval; every coarser level lies
// within [min lo, max hi] of the texels it covers.
void expect_lossless(const Evaluator& eval, const IntervalTile& truth) {
  const uint32_t L = truth.level;
  std::string v = fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); });
  EXPECT_EQ(v, "");
  for (uint32_t l : {L - 1, L - 3}) {
    const uint32_t s = 1u << (L - l);
    for (uint32_t y = 0; y < (1u << l); y += 7)
      for (uint32_t x = 0; x < (1u << l); x += 5) {
        float lo = INFINITY, hi = -INFINITY;
        for (uint32_t j = 0; j < s; ++j)
          for (uint32_t i = 0; i < s; ++i) {
            lo = std::min(lo, truth.at(x * s + i, y * s + j).lo);
            hi = std::max(hi, truth.at(x * s + i, y * s + j).hi);
          }
        float d = eval.depth(l, x, y);
        ASSERT_TRUE(lo <= d && d <= hi) << "level " << l << " texel " << x << "," << y;
      }
  }
}

class MapBuildEncodings : public ::testing::TestWithParam<Encoding> {};

TEST_P(MapBuildEncodings, EveryTexelOfTheBuiltPackIsLossless) {
  auto b = city();
  const uint32_t L = fields::small_test_scale() ? 9 : 11;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = GetParam();
  o.skip_level = 4;
  const std::string path = tmp_path("mb_" + to_string(GetParam()) + ".pack");
  MapBuildReport r = build_map(b.scene, b.light, o, path);
  EXPECT_EQ(r.cells_built, 256u);
  EXPECT_TRUE(r.exit_depths);
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  RasterBounds tracer(b.scene, b.light);  // the builder a sun build uses by default
  IntervalTile truth = tracer.trace({L, 0, 0, 1u << L, 1u << L});
  PackEvaluator eval(PackReader::open(path));
  expect_lossless(eval, truth);
}

INSTANTIATE_TEST_SUITE_P(All, MapBuildEncodings,
                         ::testing::Values(Encoding::mh, Encoding::mmh, Encoding::dagmh),
                         [](const auto& info) { return to_string(info.param); });

TEST(MapBuild, SmallTileBoundCutsDeeperAndStaysLossless) {
  auto b = city();
  const uint32_t L = fields::small_test_scale() ? 9 : 10;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = Encoding::mh;
  o.skip_level = 2;
  o.tile_bytes = 512;
  const std::string path = tmp_path("mb_small_tiles.pack");
  MapBuildReport r = build_map(b.scene, b.light, o, path);
  EXPECT_GT(r.index_tile_count, 0u);
  RasterBounds tracer(b.scene, b.light);  // the builder a sun build uses by default
  PackEvaluator eval(PackReader::open(path));
  expect_lossless(eval, tracer.trace({L, 0, 0, 1u << L, 1u << L}));
}

TEST(MapBuild, KilledBuildResumesToIdenticalAnswers) {
  auto b = city();
  const uint32_t L = 9;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = Encoding::dagmh;
  o.skip_level = 4;
  const std::string whole = tmp_path("mb_whole.pack"), resumed = tmp_path("mb_resumed.pack");
  fs::remove(resumed + ".tmp");
  fs::remove(resumed);  // a previous run of this test leaves the finished pack
  build_map(b.scene, b.light, o, whole);

  MapBuildOptions killed = o;
  killed.stop_after_cells = 100;
  EXPECT_THROW(build_map(b.scene, b.light, killed, resumed), Error);
  EXPECT_TRUE(fs::exists(resumed + ".tmp"));
  EXPECT_FALSE(fs::exists(resumed));  // never a half-written pack under the final name

  MapBuildOptions again = o;
  again.resume = true;
  MapBuildReport r = build_map(b.scene, b.light, again, resumed);
  EXPECT_GE(r.cells_resumed, 90u);  // the last cells may be torn (two writers in flight)
  EXPECT_EQ(r.cells_resumed + r.cells_built, 256u);
  PackEvaluator a(PackReader::open(whole)), c(PackReader::open(resumed));
  for (uint32_t l = 0; l <= L; ++l)
    for (uint32_t y = 0; y < (1u << l); y += (l > 6 ? 3 : 1))
      for (uint32_t x = 0; x < (1u << l); x += (l > 6 ? 3 : 1))
        ASSERT_EQ(a.depth(l, x, y), c.depth(l, x, y)) << "level " << l << " " << x << "," << y;
}

TEST(MapBuild, RegionOfAMillionTexelMapIsExactAtTheFarCorner) {
  auto b = city();
  const uint32_t L = 20;
  const uint64_t R = uint64_t(1) << L;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = Encoding::dagmh;
  o.skip_level = 9;  // cells of 2048^2 texels
  o.region = TexelRegion{R - 300, R - 200, 300, 200};
  const std::string path = tmp_path("mb_region.pack");
  MapBuildReport r = build_map(b.scene, b.light, o, path);
  EXPECT_EQ(r.cells_built, 1u);
  EXPECT_EQ(r.cells_outside_region, (uint64_t(1) << 18) - 1);
  PackEvaluator eval(PackReader::open(path));
  RasterBounds tracer(b.scene, b.light);  // the builder a sun build uses by default
  IntervalTile truth = tracer.trace({L, R - 64, R - 64, 64, 64});
  for (uint32_t j = 0; j < 64; ++j)
    for (uint32_t i = 0; i < 64; ++i) {
      float v = eval.depth(L, R - 64 + i, R - 64 + j);
      ASSERT_TRUE(truth.at(i, j).contains(v)) << "texel " << (R - 64 + i) << "," << (R - 64 + j);
    }
  // The far corner texel itself, traced alone, and a cell outside the region (constant).
  IntervalTile corner = tracer.trace({L, R - 1, R - 1, 1, 1});
  EXPECT_TRUE(corner.at(0, 0).contains(eval.depth(L, R - 1, R - 1)));
  EXPECT_EQ(eval.depth(L, 0, 0), kLitDepth);
}

TEST(MapBuild, BadOptionsAreClearErrors) {
  auto b = city();
  MapBuildOptions o;
  o.map_level = 10;
  o.region = TexelRegion{1000, 0, 100, 10};
  try {
    build_map(b.scene, b.light, o, tmp_path("mb_bad.pack"));
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("region"), std::string::npos) << e.what();
  }
  o.region.reset();
  o.skip_level = 15;
  EXPECT_THROW(build_map(b.scene, b.light, o, tmp_path("mb_bad.pack")), Error);
}

}  // namespace map_build_test
}  // namespace st

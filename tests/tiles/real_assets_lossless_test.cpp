// Every texel of packs built from real open-mesh assets (Debian's assimp-testmodels,
// installed by scripts/deps): models exported by real tools, with their boundary and
// non-manifold edges, duplicate vertices and slivers, where the open-geometry rule
// (hi = lo) holds almost everywhere. Each pack's value at every texel must lie in a
// fresh trace's [lo, hi] bit-exactly, in every encoding. Maps are small (the real asset
// benches are scripts/bench-real); a missing package skips with the command to run.
#include <gtest/gtest.h>

#include <filesystem>

#include "interval_fields.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace {

namespace fs = std::filesystem;

constexpr const char* kModels = "/usr/share/assimp/models/";

struct RealCase {
  const char* file;  // under kModels
  Encoding encoding;
  uint32_t skip_level;
  const char* light;
  const char* up;  // up_axis_text() of the loaded scene
};

class RealAssetsLossless : public ::testing::TestWithParam<RealCase> {};

TEST_P(RealAssetsLossless, EveryTexelOfThePackIsWithinTheFreshTrace) {
  const RealCase& c = GetParam();
  const std::string file = std::string(kModels) + c.file;
  if (!fs::exists(file)) GTEST_SKIP() << file << " missing: run scripts/deps (Debian package assimp-testmodels)";
  const Scene scene = load_scene(file);
  ASSERT_FALSE(scene.triangles.empty());
  EXPECT_LT(scene.closed_triangle_count(), scene.triangles.size()) << "a real asset with open meshes";
  EXPECT_EQ(up_axis_text(scene), c.up) << "the axis the file records, without being told";
  const LightSpace light = LightSpace::fit(LightSpec::parse(c.light), scene.bounds());
  const uint32_t L = fields::small_test_scale() ? 8 : 10;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = c.encoding;
  o.skip_level = c.skip_level;
  o.dagmh_dictionary = o.dagmh_mixed_tiles = c.encoding == Encoding::dagmh;  // the CLI's default build
  fs::create_directories(SHADOWTILE_TEST_TMP);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/real_" + fs::path(c.file).stem().string() + "_" +
                           to_string(c.encoding) + ".pack";
  build_map(scene, light, o, path);
  const TraceRegion all{L, 0, 0, 1u << L, 1u << L};
  const IntervalTile truth = RasterBounds(scene, light).trace(all);
  uint64_t hit = 0, open = 0;
  for (const Interval& iv : truth.data) {
    hit += iv.lo < kLitDepth;
    open += iv.lo < kLitDepth && iv.lo == iv.hi;
  }
  EXPECT_GT(hit, truth.data.size() / 32) << "the asset must cover part of the map";
  EXPECT_GT(open, hit / 8) << "many covered texels see an open surface";
  PackEvaluator eval(PackReader::open(path));
  EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }), "");
  fs::remove(path);
}

INSTANTIATE_TEST_SUITE_P(
    Assimp, RealAssetsLossless,
    ::testing::Values(
        // Three teapots, Z-up in the file (<up_axis>), every mesh open.
        RealCase{"Collada/teapots.DAE", Encoding::dagmh, 4, "sun:azimuth=30,elevation=50",
                 "z (from the file's <up_axis>, turned by assimp)"},
        RealCase{"Collada/teapots.DAE", Encoding::mmh, 3, "sun:azimuth=200,elevation=20",
                 "z (from the file's <up_axis>, turned by assimp)"},
        // A game character from FBX: closed and open parts.
        RealCase{"FBX/spider.fbx", Encoding::dagmh, 3, "sun:azimuth=30,elevation=50", "y (from the file's metadata)"},
        RealCase{"FBX/spider.fbx", Encoding::mh, 4, "sun:azimuth=120,elevation=70", "y (from the file's metadata)"}),
    [](const auto& info) {
      return fs::path(info.param.file).stem().string() + "_" + to_string(info.param.encoding);
    });

}  // namespace
}  // namespace st

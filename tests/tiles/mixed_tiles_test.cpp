// Mixed tiles (tiles/PACK.md "Mixed tiles"): a DAG-MH pack whose tiles are each DAG-MH or,
// where that stores in fewer bytes, MMH. On open geometry (hi = lo) MMH's merged subtrees
// win on the flat patches; the pack says so (feature mixed_tiles), every texel stays
// within a fresh trace's interval, and the pack is no larger than the MMH pack or the
// all-DAG-MH pack of the same map.
#include <gtest/gtest.h>

#include <filesystem>

#include "common/bytes.hpp"
#include "interval_fields.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace mixed_tiles_test {

namespace fs = std::filesystem;

struct Built {
  std::string path;
  uint64_t file = 0, payloads = 0, dagmh_tiles = 0, mmh_tiles = 0;
  uint32_t flags = 0;
};

Built build(const Scene& scene, const LightSpace& light, uint32_t level, Encoding e, bool mixed, const char* name,
            bool exhaustive = false) {
  MapBuildOptions o;
  o.map_level = level;
  o.encoding = e;
  o.skip_level = 4;
  o.dagmh_dictionary = e == Encoding::dagmh;  // as the CLI builds by default
  o.dagmh_mixed_tiles = mixed;
  o.dagmh_mixed_exhaustive = exhaustive;
  o.planes = false;  // the tree encodings' own choice, without plane tiles (plane_tiles_test.cpp)
  fs::create_directories(SHADOWTILE_TEST_TMP);
  Built b;
  b.path = std::string(SHADOWTILE_TEST_TMP) + "/mixed_" + name + ".pack";
  build_map(scene, light, o, b.path);
  const auto r = PackReader::open(b.path);
  b.file = fs::file_size(b.path);
  b.flags = r->header().flags;
  for (const TileIndexEntry& t : r->tiles()) {
    b.payloads += t.stored_size;
    if (t.kind != TileKind::encoded) continue;
    const std::vector<uint8_t> raw = r->read_raw(t.id);
    if (is_mmh_buffer(raw)) ++b.mmh_tiles;
    else if (load_le<uint32_t>(raw.data()) == dagmh::kMagic) ++b.dagmh_tiles;
  }
  return b;
}

// The default mixed build predicts each tile's smaller encoding from its share of
// zero-width intervals and encodes both only where unsure; exhaustive encodes every tile
// both ways. On a closed city (wide intervals) the prediction keeps DAG-MH, on its open
// copy MMH: both packs stay no larger than the MMH pack and within 2% of exhaustive.
TEST(MixedTiles, PredictedChoiceStaysNoLargerThanMmhAndNearExhaustive) {
  const uint32_t L = fields::small_test_scale() ? 8 : 10;
  const Scene closed = load_scene("procedural:city,size=3,seed=9");
  for (const Scene& scene : {closed, test::all_open(closed)}) {
    const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
    const Built mmh = build(scene, light, L, Encoding::mmh, false, "p_mmh");
    const Built predicted = build(scene, light, L, Encoding::dagmh, true, "p_predicted");
    const Built exhaustive = build(scene, light, L, Encoding::dagmh, true, "p_exhaustive", true);
    const bool open = !scene.any_closed();
    EXPECT_LE(predicted.file, mmh.file) << (open ? "open" : "closed");
    // Within 2% of exhaustive; 8% at the sanitizers' small scale (level 8: a few dozen tiles,
    // where one tile predicted the wrong way is several percent of the pack).
    const double slack = fields::small_test_scale() ? 1.08 : 1.02;
    EXPECT_LE(double(predicted.payloads), slack * double(exhaustive.payloads)) << (open ? "open" : "closed");
    if (open) {
      EXPECT_EQ(predicted.dagmh_tiles, 0u) << "zero-width intervals: MMH predicted everywhere";
    } else {
      EXPECT_EQ(predicted.mmh_tiles, 0u) << "wide intervals: DAG-MH predicted everywhere";
    }
    for (const Built* b : {&mmh, &predicted, &exhaustive}) fs::remove(b->path);
  }
}

TEST(MixedTiles, OpenTownTakesMmhWhereSmallerStaysLosslessAndNoLargerThanEither) {
  const Scene scene = test::all_open(load_scene("procedural:city,size=3,seed=9"));
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  const uint32_t L = fields::small_test_scale() ? 8 : 10;
  const Built mmh = build(scene, light, L, Encoding::mmh, false, "mmh");
  const Built only = build(scene, light, L, Encoding::dagmh, false, "dagmh_only");
  const Built mixed = build(scene, light, L, Encoding::dagmh, true, "dagmh_mixed");
  EXPECT_EQ(only.mmh_tiles, 0u);
  EXPECT_FALSE(only.flags & kFeatureMixedTiles);
  ASSERT_GT(mixed.mmh_tiles, 0u) << "open planar patches: MMH stores some tile smaller";
  EXPECT_TRUE(mixed.flags & kFeatureMixedTiles);
  EXPECT_LE(mixed.file, mmh.file) << "mixed " << mixed.file << " B, MMH " << mmh.file << " B";
  EXPECT_LE(mixed.payloads, only.payloads);

  const TraceRegion all{L, 0, 0, 1u << L, 1u << L};
  const IntervalTile truth = RasterBounds(scene, light).trace(all);
  PackEvaluator eval(PackReader::open(mixed.path));
  EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }), "");
  // Every level answers as a complete map (the multiresolution contract) through both kinds.
  for (uint32_t l = 0; l < L; ++l) {
    const float v = eval.depth(l, (1u << l) / 3, (1u << l) / 2);
    EXPECT_FALSE(std::isnan(v)) << "level " << l;
  }
  for (const Built* b : {&mmh, &only, &mixed}) fs::remove(b->path);
}

}  // namespace mixed_tiles_test
}  // namespace st

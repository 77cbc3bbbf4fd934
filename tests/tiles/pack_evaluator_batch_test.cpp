// PackEvaluator::pcf_batch (what `render PACK` calls): answers equal pcf() query for query,
// whatever the order, with repeats, kernels mixed in, clamped texels, coarse levels that
// the page table answers, and a cache smaller than the taps' tiles (evictions between runs).
// A real open mesh (2CylinderEngine) with plane tiles, DAG-MH and MMH.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <random>

#include "scene/scene.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace pack_evaluator_batch_test {

namespace fs = std::filesystem;

TEST(PackEvaluatorBatch, AnswersLikePcfPerQueryInAnyOrderWithASmallCache) {
  const std::string file = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
  if (!fs::exists(file)) GTEST_SKIP() << "assimp-testmodels missing: run scripts/deps";
  const Scene scene = load_scene(file);
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  fs::create_directories(SHADOWTILE_TEST_TMP);
  for (Encoding e : {Encoding::dagmh, Encoding::mmh}) {
    MapBuildOptions o;
    o.map_level = 9;
    o.skip_level = 4;
    o.encoding = e;
    o.planes = true;
    const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/pack_eval_batch_" + to_string(e) + ".pack";
    build_map(scene, light, o, path);
    const std::shared_ptr<const PackReader> reader = PackReader::open(path);
    const PackEvaluator small(reader, 3), big(reader, 4096);
    std::mt19937 rng(11);
    std::vector<PcfQuery> q;
    // A screen-like sweep at the finest level (neighbours), then random taps at every level.
    for (uint64_t y = 100; y < 140; y += 3)
      for (uint64_t x = 0; x < 512; x += 5) q.push_back({x, y, 9, 1, 0});
    for (int k = 0; k < 3000; ++k) {
      const uint32_t l = rng() % 10;
      const uint64_t side = uint64_t(1) << l;
      PcfQuery t{rng() % (side + 2), rng() % (side + 2), l, 1, 0};  // a few past the edge: clamped
      if (k % 50 == 0) t.r = 3;
      q.push_back(t);
      if (k % 9 == 0) q.push_back(t);  // repeated
    }
    for (PcfQuery& t : q) {
      const uint64_t top = (uint64_t(1) << t.level) - 1;
      const float v = big.depth(t.level, std::min(t.x, top), std::min(t.y, top));
      const int pick = int(rng() % 3);
      t.receiver = pick == 0 ? v : pick == 1 ? std::nextafter(v, 0.0f) : std::nextafter(v, 2.0f);
    }
    // Each opened tile wrote its raw bytes into its slot, not the whole slot: with no
    // evictions (4096 slots) the slots hold at most every encoded tile's raw bytes once,
    // and less than a whole slot per opened tile (index tiles write none).
    uint64_t raw_total = 0, slot_bytes = 1;  // a slot holds the pack's largest raw tile
    for (const TileIndexEntry& t : reader->tiles()) {
      raw_total += t.kind == TileKind::index ? 0 : t.raw_size;
      slot_bytes = std::max<uint64_t>(slot_bytes, t.raw_size);
    }
    ASSERT_GT(big.tiles_opened(), 0u);
    EXPECT_GT(big.slot_bytes_written(), 0u);
    EXPECT_LE(big.slot_bytes_written(), raw_total) << to_string(e);
    EXPECT_LT(big.slot_bytes_written(), big.tiles_opened() * slot_bytes) << to_string(e);
    for (int shuffled = 0; shuffled < 2; ++shuffled) {
      if (shuffled) std::shuffle(q.begin(), q.end(), rng);
      for (const PackEvaluator* ev : {&small, &big}) {
        std::vector<float> out(q.size(), -1.0f);
        ev->pcf_batch(q, out);
        for (size_t i = 0; i < q.size(); ++i)
          ASSERT_EQ(out[i], ev->pcf(q[i].level, q[i].x, q[i].y, q[i].r, q[i].receiver))
              << to_string(e) << " query " << i << " level " << q[i].level << " texel " << q[i].x << "," << q[i].y
              << (ev == &small ? " (3-tile cache)" : "");
      }
    }
  }
}

}  // namespace pack_evaluator_batch_test
}  // namespace st

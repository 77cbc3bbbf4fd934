// A plane tile's taps in runs (TapWalks::tap_run, what the client's batches call): every
// tap answers depth_region's value with the lit test, whatever the order of the run
// (Morton, shuffled, with repeats), and the run's end region holds its value on every
// texel; a run bounded by a tile's side (TapRun::side) stops at its first tap outside;
// walk_tap is depth_region. On real open-mesh tiles (2CylinderEngine), every level,
// each inner encoding.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <numeric>
#include <random>

#include "scene/scene.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/tap_batch.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/plane_fit.hpp"

namespace st {
namespace plane_tap_run_test {

// Taps `xs` of `level` as one run through tap_run (path kept by the caller), against
// depth_region tap by tap; receivers at, just below and just above each texel's value.
void expect_run_like_regions(const Evaluator& ev, const TapWalks& walks, uint32_t level,
                             const std::vector<std::array<uint32_t, 2>>& texels, TapPath& path, std::mt19937& rng) {
  const size_t n = texels.size();
  std::vector<PcfQuery> q(n);
  std::vector<uint16_t> order(n);
  for (size_t i = 0; i < n; ++i) {
    const float v = ev.depth(level, texels[i][0], texels[i][1]);
    const int pick = int(rng() % 3);
    const float r = pick == 0 ? v : pick == 1 ? std::nextafter(v, 0.0f) : std::nextafter(v, 2.0f);
    q[i] = PcfQuery{texels[i][0], texels[i][1], level, 1, r};
  }
  // The run's order is a permutation of its queries (stored in another order than asked).
  std::iota(order.begin(), order.end(), uint16_t(0));
  std::shuffle(order.begin(), order.end(), rng);
  std::vector<PcfQuery> stored(n);
  for (size_t k = 0; k < n; ++k) stored[order[k]] = q[k];
  std::vector<float> out(n, -1.0f);
  const TapRunEnd end = walks.tap_run(TapRun{stored.data(), order.data(), n, level, level, 0, 0, out.data()}, path);
  for (size_t k = 0; k < n; ++k) {
    const PcfQuery& s = stored[order[k]];
    const DepthRegion reg = ev.depth_region(level, s.x, s.y);
    ASSERT_EQ(out[order[k]], s.receiver <= reg.value ? 1.0f : 0.0f)
        << "level " << level << " tap " << k << " texel " << s.x << "," << s.y;
  }
  ASSERT_EQ(end.count, n);
  // With TapRun::side the run is its prefix inside the tile (here the quadrant x, y < half
  // at (0, 0)): those taps answered as above, the run ending at the first tap outside.
  if (level >= 1) {
    const uint64_t half = uint64_t(1) << (level - 1);
    size_t m = 0;
    while (m < n && stored[order[m]].x < half && stored[order[m]].y < half) ++m;
    if (m > 0) {
      std::vector<float> part(n, -1.0f);
      TapRun run{stored.data(), order.data(), n, level, level, 0, 0, part.data()};
      run.side = half;
      ASSERT_EQ(walks.tap_run(run, path).count, m) << "level " << level;
      for (size_t k = 0; k < n; ++k) ASSERT_EQ(part[order[k]], k < m ? out[order[k]] : -1.0f) << "tap " << k;
    }
  }
  // The end region: the last tap lies in it and every texel of it answers its value.
  const PcfQuery& last = stored[order[n - 1]];
  ASSERT_EQ((last.x >> end.region.shift), (end.x >> end.region.shift));
  ASSERT_EQ((last.y >> end.region.shift), (end.y >> end.region.shift));
  const uint64_t side = uint64_t(1) << end.region.shift;
  for (int k = 0; k < 16; ++k) {
    const uint64_t x = (end.x >> end.region.shift << end.region.shift) + rng() % side;
    const uint64_t y = (end.y >> end.region.shift << end.region.shift) + rng() % side;
    ASSERT_EQ(ev.depth(level, x, y), end.region.value) << "level " << level << " end region " << end.region.shift;
  }
}

TEST(PlaneTapRun, RunsInAnyOrderAnswerLikeDepthRegionOnRealOpenMeshTiles) {
  const std::string file = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
  if (!std::filesystem::exists(file)) GTEST_SKIP() << "assimp-testmodels missing: run scripts/deps";
  const Scene scene = load_scene(file);
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  const uint32_t depth = 6, level = 9;
  uint64_t tiles = 0;
  std::mt19937 rng(7);
  for (uint32_t ty = 2; ty < 5; ++ty) {
    const IntervalTile truth = RasterBounds(scene, light).trace(TraceRegion{level, 64 * ty, 192, 1u << depth, 1u << depth});
    const PlaneSplit s = fit_planes(build_hierarchy(truth));
    if (s.planes.empty() && s.labelled.empty()) continue;
    ++tiles;
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      const std::vector<uint8_t> bytes = wrap_planes(s.planes, depth, encode(s.pruned, e), s.labelled);
      const auto ev = open_encoded(e, bytes);  // a view of `bytes`
      const auto* walks = dynamic_cast<const TapWalks*>(ev.get());
      ASSERT_NE(walks, nullptr) << "a plane tile answers runs of taps";
      SCOPED_TRACE(to_string(e));
      TapPath path;  // kept across runs and levels, as the client keeps one per tile
      for (uint32_t l = 0; l <= depth; ++l) {
        const uint32_t side = 1u << l;
        // Every texel in Morton order (the client's order), then a shuffled sample with repeats.
        std::vector<std::array<uint32_t, 2>> all;
        for (uint32_t m = 0; m < side * side; ++m)
          all.push_back({morton_compact(m), morton_compact(uint64_t(m) >> 1)});
        for (size_t b = 0; b < all.size(); b += 1024)
          expect_run_like_regions(*ev, *walks, l, {all.begin() + ptrdiff_t(b), all.begin() + ptrdiff_t(std::min(all.size(), b + 1024))},
                                  path, rng);
        std::vector<std::array<uint32_t, 2>> sample;
        for (int k = 0; k < 300; ++k) {
          const std::array<uint32_t, 2> t{uint32_t(rng() % side), uint32_t(rng() % side)};
          sample.push_back(t);
          if (k % 7 == 0) sample.push_back(t);  // a repeated texel
        }
        expect_run_like_regions(*ev, *walks, l, sample, path, rng);
        for (int k = 0; k < 64; ++k) {
          const uint32_t x = uint32_t(rng() % side), y = uint32_t(rng() % side);
          const DepthRegion a = walks->walk_tap(l, x, y, path), b = ev->depth_region(l, x, y);
          ASSERT_EQ(a.value, b.value);
          ASSERT_EQ(a.shift, b.shift);
        }
      }
    }
  }
  EXPECT_GT(tiles, 0u) << "the engine's faces seen at a slant give plane tiles";
}

}  // namespace plane_tap_run_test
}  // namespace st

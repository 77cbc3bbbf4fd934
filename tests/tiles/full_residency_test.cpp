// With every tile resident, a pack answers every receiver like the uncompressed full map
// except where the lossless invariant allows a difference: a receiver whose lookup depth
// lies inside its texel's [lo, hi] (inside or at the far side of a closed object along the
// texel-centre ray). Pinned on a closed city (where that class exists) and on open
// hazard geometry (where it is empty: hi = lo), for every encoding
// (render_error.hpp count_disagreements; `shadowtile report` prints both counts). The
// voxel shadow DAG is held to its own contract: it may also differ in the depth slab of
// a texel's lo or hi (tiles/core/VSDAG.md), and at 64 slabs it does.
#include <gtest/gtest.h>

#include <filesystem>

#include "interval_fields.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "render/render.hpp"
#include "render/render_error.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace {

// A camera over the scene's corner looking at its centre.
Camera overview(const Scene& s) {
  const Aabb b = s.bounds();
  const Vec3d c = b.center(), e = b.extent();
  Camera cam;
  cam.pos = c + Vec3d{-0.6 * e.x, 0.35 * std::max(e.x, e.z), -0.7 * e.z};
  cam.target = c;
  cam.fov_deg = 55;
  return cam;
}

void expect_no_disagreement_outside_intervals(const Scene& s, bool open) {
  const Camera cam = overview(s);
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  const uint32_t L = fields::small_test_scale() ? 9 : 10;
  DepthBoundsTracer bounds(s, light);
  const FlatMapEvaluator full(bounds.trace({L, 0, 0, 1u << L, 1u << L}), true);
  const SceneTracer tracer(s, light);
  const FrameTruth f = make_frame_truth(tracer, cam, 200, 120, L, {});
  ASSERT_GT(f.lit_facing.size(), 2000u);
  std::filesystem::create_directories(SHADOWTILE_TEST_TMP);
  for (Encoding enc : {Encoding::mh, Encoding::mmh, Encoding::dagmh, Encoding::vsdag}) {
    SCOPED_TRACE(to_string(enc));
    MapBuildOptions o;
    o.map_level = L;
    o.encoding = enc;
    o.skip_level = 4;
    // The voxel shadow DAG at a coarse depth resolution (64 slabs), so that its slab
    // class is large; `shadowtile report` counts it apart the same way.
    const uint32_t slab_bits = enc == Encoding::vsdag ? 6 : 0;
    if (slab_bits) o.vsdag_z_bits = slab_bits;
    const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/full_residency_" + to_string(enc) + ".pack";
    build_map(s, light, o, path);
    const PackEvaluator eval(std::shared_ptr<PackReader>(PackReader::open(path)), 1 << 14);
    const Disagreements d = count_disagreements(eval, full, light, f, slab_bits);
    EXPECT_EQ(d.outside(), 0u) << d.total << " differ, " << d.within_interval << " inside an interval, "
                               << d.within_slab << " in a surface's slab";
    if (open) {
      EXPECT_EQ(d.within_interval, 0u) << "open geometry has hi = lo";
    }
    if (slab_bits) {
      // Not lossless: some receivers lie in their surface's slab and are answered
      // differently, which the lossless rule alone would count as errors.
      EXPECT_GT(d.within_slab, 0u);
      EXPECT_GT(count_disagreements(eval, full, light, f).outside(), 0u);
    } else {
      EXPECT_EQ(d.within_slab, 0u);
    }
    std::filesystem::remove(path);
  }
}

TEST(FullResidency, ClosedCityDiffersOnlyInsideIntervals) {
  expect_no_disagreement_outside_intervals(load_scene("procedural:city,size=2,seed=5"), false);
}

TEST(FullResidency, OpenHazardsNeverDiffer) {
  expect_no_disagreement_outside_intervals(test::hazard_town(), true);
}

}  // namespace
}  // namespace st

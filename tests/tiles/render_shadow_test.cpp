// The rendered view of an analytic scene (a closed cube on a closed ground slab) shaded
// with the map matches Embree shadow rays away from shadow edges.
#include <gtest/gtest.h>

#include <bit>

#include <cmath>
#include <cstdlib>

#include "tiles/bake/map_build.hpp"
#include "render/render.hpp"
#include "render/render_error.hpp"
#include "scene/scene.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tests/tiles/render_scenes.hpp"

namespace st {
namespace {

using render_test::add_box;
using render_test::cube_on_slab;

TEST(RenderShadow, CubeOnSlabMatchesRayTracedAwayFromEdges) {
  Scene s;
  s.name = "cube-on-slab";
  add_box(s, "slab", {-10, -1, -10}, {10, 0, 10});
  add_box(s, "cube", {-2, 0, -2}, {2, 4, 2});
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=40"), s.bounds());
  const bool small = std::getenv("SHADOWTILE_TEST_SCALE") && std::string(std::getenv("SHADOWTILE_TEST_SCALE")) == "small";
  MapBuildOptions o;
  o.map_level = small ? 9 : 10;
  o.encoding = Encoding::dagmh;
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/render_cube_slab.pack";
  build_map(s, light, o, path);
  const PackEvaluator eval(std::shared_ptr<PackReader>(PackReader::open(path)), 4096);
  const SceneTracer tracer(s, light);
  Camera cam;
  cam.pos = {3, 22, 4};  // from above: the shadow falls on the slab whatever the azimuth
  cam.target = {0, 0, 0};
  cam.fov_deg = 55;
  const uint32_t w = small ? 160 : 320, h = small ? 90 : 180;
  const auto rec = tracer.primary(cam, w, h);
  uint64_t compared = 0, equal = 0, shadowed = 0;
  for (const Receiver& r : rec) {
    if (!r.hit || r.n_dot_l <= 0) continue;
    // Near an edge: the 5x5 texels around the lookup disagree (2 texels either side).
    const LightPoint lp = lookup_point(r, light, eval.finest_level());
    const auto [x, y] = LightSpace::texel_of(eval.finest_level(), lp.u, lp.v);
    const float k = eval.pcf(eval.finest_level(), x, y, 5, float(lp.d));
    if (k != 0.0f && k != 1.0f) continue;
    ++compared;
    const float m = map_visibility(eval, r, light, 0, eval.finest_level());
    equal += m == tracer.traced(r);
    shadowed += m == 0;
  }
  ASSERT_GT(compared, uint64_t(w) * h / 4);
  EXPECT_GT(shadowed, compared / 50) << "the view should contain the cube's shadow";
  EXPECT_GE(double(equal), 0.995 * double(compared)) << equal << " of " << compared;

  // The image path agrees with the per-receiver answers and counts what it compares.
  RenderOptions ro;
  ro.width = w, ro.height = h, ro.diff = true;
  const RenderResult img = render_view(tracer, rec, eval, ro);
  EXPECT_EQ(img.image.size(), size_t(w) * h * 3);
  EXPECT_LE(img.differing_fraction(), 0.02);
  // Bit for bit (the sun's chunked transform and the batched lookups), single tap and 5x5.
  for (uint32_t radius : {0u, 2u}) {
    ro.pcf_radius = radius, ro.diff = false;
    const RenderResult v = render_view(tracer, rec, eval, ro);
    for (size_t i = 0; i < rec.size(); ++i)
      ASSERT_EQ(std::bit_cast<uint32_t>(v.visibility[i]),
                std::bit_cast<uint32_t>(map_visibility(eval, rec[i], light, radius, eval.finest_level())))
          << "pixel " << i << " radius " << radius;
  }
}

// A 4-unit cube on a 20-unit slab: the scene of the pack-based tests below.
// An MH pack of level 9 of `s` under `light`, built into the test folder as NAME.pack.
std::shared_ptr<PackReader> mh_level9_pack(const Scene& s, const LightSpace& light, const std::string& name) {
  MapBuildOptions o;
  o.map_level = 9;
  o.encoding = Encoding::mh;
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/" + name + ".pack";
  build_map(s, light, o, path);
  return std::shared_ptr<PackReader>(PackReader::open(path));
}

TEST(RenderShadow, FlatBaselineAtFullResolutionAgreesWithThePack) {
  const Scene s = cube_on_slab();
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=120,elevation=35"), s.bounds());
  const PackEvaluator eval(mh_level9_pack(s, light, "render_flat_slab"), 4096);
  const SceneTracer tracer(s, light);
  Camera cam;
  cam.pos = {-11, 8, 12};
  cam.target = {0, 0, 0};
  const FrameTruth f = make_frame_truth(tracer, cam, 160, 90, 9, {1});
  ASSERT_GT(f.lit_facing.size(), 1000u);
  const FrameError e = frame_error(eval, light, f, 0, 9);
  EXPECT_LT(e.fraction(), 0.02);
  const FrameError p = frame_error(eval, light, f, 1, 9);
  EXPECT_LT(p.mean_abs, 0.05);
}

// Hierarchical filtering in the report: the footprint reference is the PCF reference
// where a pixel covers at most a texel; the per-receiver filtered lookup is render's
// (bit for bit); with pixels of several texels its error stays near fixed-level PCF's,
// and with pixels under a texel it is no worse.
TEST(RenderShadow, FootprintReferenceAndHierarchicalFiltering) {
  const Scene s = cube_on_slab();
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=120,elevation=35"), s.bounds());
  const PackEvaluator eval(mh_level9_pack(s, light, "render_footprint_slab"), 4096);
  const SceneTracer tracer(s, light);
  const uint32_t w = 120, h = 68;
  Camera near_cam;
  near_cam.pos = {-11, 8, 12};
  near_cam.target = {0, 0, 0};
  // A pixel angle small enough that every footprint is under a texel: the references agree.
  FrameTruth f = make_frame_truth(tracer, near_cam, w, h, 9, {1});
  add_footprint_truth(tracer, f, 9, {0, 1}, 1e-5);
  ASSERT_GT(f.lit_facing.size(), 1000u);
  for (size_t i = 0; i < f.lit_facing.size(); ++i) {
    ASSERT_LE(f.footprint[i], 1.0f);
    ASSERT_EQ(f.footprint_truth[1][i], f.pcf_truth[0][i]) << i;
    ASSERT_GE(f.footprint_truth[0][i], 0.0f);
    ASSERT_LE(f.footprint_truth[0][i], 1.0f);
  }
  // At the finest level the filtered lookup is 3x3 PCF too, each tap against the receiver's
  // plane (tiles/core/receiver_plane.hpp) rather than one depth behind a normal offset grown
  // by the kernel's radius: no worse than fixed-level PCF (measured 0.0017 against 0.0039).
  EXPECT_LE(footprint_error(eval, light, f, 1, true).mean_abs, footprint_error(eval, light, f, 1, false).mean_abs);

  // The same view at its true pixel angle: footprints of several texels.
  const double pixel_angle = 2 * std::tan(near_cam.fov_deg * 3.14159265358979323846 / 360) / h;
  FrameTruth g = make_frame_truth(tracer, near_cam, w, h, 9, {});
  add_footprint_truth(tracer, g, 9, {2}, pixel_angle);
  ASSERT_GT(g.lit_facing.size(), 1000u);
  uint32_t wide = 0;
  for (float fp : g.footprint) wide += fp > 2.0f;
  ASSERT_GT(wide, g.lit_facing.size() / 2) << "the view should have pixels of several texels";
  const FrameError fixed = footprint_error(eval, light, g, 2, false);
  const FrameError filtered = footprint_error(eval, light, g, 2, true);
  // A single cube has no detail to alias, so filtering cannot win by much here; what it
  // must not do is shadow sloped surfaces with one receiver depth under a kernel of coarse
  // texels (2.4x the fixed-level error with the finest level's offset, before the receiver
  // plane or a level-scaled offset).
  EXPECT_LT(filtered.mean_abs, 1.25 * fixed.mean_abs) << fixed.mean_abs;

  RenderOptions ro;
  ro.width = w, ro.height = h, ro.pcf_radius = 2, ro.pixel_angle = pixel_angle;
  const RenderResult img = render_view(tracer, g.receivers, eval, ro);
  ASSERT_EQ(img.visibility.size(), g.receivers.size());
  for (uint32_t i : g.lit_facing) {
    const Receiver& r = g.receivers[i];
    const float v = map_visibility_filtered(eval, r, light, 2, receiver_footprint_texels(r, light, 9, pixel_angle));
    ASSERT_EQ(v, img.visibility[i]) << i;
  }
}

}  // namespace
}  // namespace st

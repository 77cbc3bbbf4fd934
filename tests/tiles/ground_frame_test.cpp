// The ground-aligned (oblique) sun frame of sun-path light sets (LightKind::sun_ground,
// tiles/core/light.hpp; light_set.hpp "Frames"): a point on the ground keeps its texel
// and a world point its depth in every slice, texel_ray inverts to_light, the serialized
// form round-trips and check_array refuses what fit could never make, and a traced
// ground-frame stack keeps the lossless invariant on every texel of every slice.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/bake/stack_build.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/core/light_set.hpp"
#include "tiles/core/mh_octree.hpp"
#include "tiles/core/sample_texels.hpp"
#include "tiles/core/stack_lookup.hpp"

namespace st {
namespace ground_frame_test {

Aabb town_box() {
  Aabb b;
  b.extend({-20, 0, -15});
  b.extend({25, 12, 30});
  return b;
}

LightSet ground_set(const char* text) { return LightSet::fit(LightSetSpec::parse(text), town_box()); }

TEST(GroundFrame, GroundPointsKeepTheirTexelAndPointsTheirDepthInEverySlice) {
  const LightSet set = ground_set("sun-path:azimuth=100..260,elevation=25..65,samples=9");
  ASSERT_EQ(set.size(), 9u);
  const Aabb b = town_box();
  Rng rng(3);
  const uint32_t level = 12;
  for (int i = 0; i < 200; ++i) {
    const Vec3d ground{rng.uniform(b.lo.x, b.hi.x), b.lo.y, rng.uniform(b.lo.z, b.hi.z)};
    const Vec3d above{ground.x, rng.uniform(b.lo.y, b.hi.y), ground.z};
    const LightPoint g0 = set.samples[0].to_light(ground), a0 = set.samples[0].to_light(above);
    const auto t0 = LightSpace::texel_of(level, g0.u, g0.v);
    for (const LightSpace& ls : set.samples) {
      ASSERT_EQ(ls.kind(), LightKind::sun_ground);
      const LightPoint g = ls.to_light(ground), a = ls.to_light(above);
      EXPECT_EQ(LightSpace::texel_of(level, g.u, g.v), t0) << i;
      EXPECT_NEAR(g.u, g0.u, 1e-12);
      EXPECT_NEAR(a.d, a0.d, 1e-12);  // depth is height
      EXPECT_GT(a.d, 0.0);
      EXPECT_LT(a.d, 1.0);
      EXPECT_TRUE(g.u >= 0 && g.u < 1 && g.v >= 0 && g.v < 1);
    }
  }
  // Every corner of the scene box lies inside every slice's map (the square is the union).
  for (const LightSpace& ls : set.samples)
    for (int c = 0; c < 8; ++c) {
      const Vec3d p{(c & 1) ? b.hi.x : b.lo.x, (c & 2) ? b.hi.y : b.lo.y, (c & 4) ? b.hi.z : b.lo.z};
      const LightPoint lp = ls.to_light(p);
      EXPECT_TRUE(lp.u > 0 && lp.u < 1 && lp.v > 0 && lp.v < 1 && lp.d > 0 && lp.d < 1) << c;
    }
  // The ortho frame is still there, and differs.
  const LightSet ortho = ground_set("sun-path:azimuth=100..260,elevation=25..65,samples=9,frame=ortho");
  EXPECT_EQ(ortho.samples[0].kind(), LightKind::sun);
}

TEST(GroundFrame, TexelRaysInvertToLightAndRunAlongTheSun) {
  const LightSet set = ground_set("sun-path:azimuth=30..200,elevation=12..80,samples=4");
  for (const LightSpace& ls : set.samples) {
    EXPECT_TRUE(ls.parallel());
    const Vec3d to_sun = ls.forward() * -1.0;
    for (uint64_t y : {0u, 5u, 255u})
      for (uint64_t x : {0u, 17u, 255u}) {
        const LightRay r = ls.texel_ray(8, x, y);
        EXPECT_NEAR(length(cross(normalize(r.dir), to_sun)), 0.0, 1e-12);  // along the sun
        for (double t : {0.0, 0.3, 1.0}) {
          const LightPoint lp = ls.to_light(r.origin + r.dir * t);
          EXPECT_NEAR(lp.u, (double(x) + 0.5) / 256, 1e-12);
          EXPECT_NEAR(lp.v, (double(y) + 0.5) / 256, 1e-12);
          EXPECT_NEAR(lp.d, t, 1e-12);  // t == d
          EXPECT_EQ(ls.depth_of_t(r, t), t);
        }
      }
  }
}

TEST(GroundFrame, SerializationRoundTripsAndBadArraysAreRefused) {
  const LightSet set = ground_set("sun-path:azimuth=100..260,elevation=25..65,samples=3");
  const LightSpace& ls = set.samples[1];
  const std::array<double, 18> a = ls.to_array();
  EXPECT_EQ(LightSpace::check_array(LightKind::sun_ground, a), "");
  const LightSpace back = LightSpace::from_array(LightKind::sun_ground, a);
  EXPECT_EQ(back.to_array(), a);
  const Vec3d p{3, 4, 5};
  const LightPoint x = ls.to_light(p), y = back.to_light(p);
  EXPECT_EQ(std::memcmp(&x, &y, sizeof(LightPoint)), 0);
  // As an orthographic sun the same array is wrong (forward is not normal to the axes).
  EXPECT_NE(LightSpace::check_array(LightKind::sun, a), "");
  auto refused = [&](int field, double value, const char* what) {
    std::array<double, 18> bad = a;
    bad[size_t(field)] = value;
    const std::string why = LightSpace::check_array(LightKind::sun_ground, bad);
    EXPECT_NE(why.find(what), std::string::npos) << field << " = " << value << ": '" << why << "'";
  };
  refused(3, 0.5, "axis_u has length");
  refused(8, 0.2, "axis_v has length");
  refused(10, 0.0, "forward has length");
  refused(12, 0.0, "extent");
  refused(13, a[14], "near");
  refused(16, 0.0, "elevation");
  refused(17, -1, "margin");
  refused(0, NAN, "not a finite number");
  {  // a ray almost in the ground plane, and one from below
    std::array<double, 18> bad = a;
    bad[9] = 1, bad[10] = -1e-3, bad[11] = 0;
    const double l = std::sqrt(1 + 1e-6);
    bad[9] /= l, bad[10] /= l;
    EXPECT_NE(LightSpace::check_array(LightKind::sun_ground, bad).find("sine"), std::string::npos);
    bad[9] = 0, bad[10] = 1, bad[11] = 0;
    EXPECT_NE(LightSpace::check_array(LightKind::sun_ground, bad).find("sine"), std::string::npos);
  }
  {  // axis_u, axis_v not orthogonal
    std::array<double, 18> bad = a;
    bad[6] = a[3], bad[7] = a[4], bad[8] = a[5];
    EXPECT_NE(LightSpace::check_array(LightKind::sun_ground, bad).find("orthogonal"), std::string::npos);
  }
  EXPECT_NE(LightSpace::check_array(LightKind(7), a).find("unknown light kind 7"), std::string::npos);
  EXPECT_STREQ(light_kind_name(LightKind::sun_ground), "sun-ground");
}

// ground=Y moves the reference plane: points at that height keep their texel; a scene's
// ground is its largest up-facing level (the city's streets at 0, not its slab's bottom).
TEST(GroundFrame, GroundHeightFromTheSpecOrTheScene) {
  const LightSet set = ground_set("sun-path:azimuth=100..260,elevation=25..65,samples=5,ground=4");
  EXPECT_NE(set.spec.to_string().find("ground=4"), std::string::npos);
  Rng rng(4);
  for (int i = 0; i < 50; ++i) {
    const Vec3d p{rng.uniform(-20, 25), 4, rng.uniform(-15, 30)};
    const LightPoint a = set.samples[0].to_light(p), b = set.samples[4].to_light(p);
    EXPECT_NEAR(a.u, b.u, 1e-12);
    EXPECT_NEAR(a.v, b.v, 1e-12);
  }
  EXPECT_THROW(ground_set("sun-path:azimuth=1,elevation=40,samples=2,ground=40"), Error);  // above the box
  EXPECT_THROW(LightSetSpec::parse("sun-path:azimuth=1,elevation=40,samples=2,ground=1,frame=ortho"), Error);
  const Scene city = make_procedural("procedural:city,size=2");
  EXPECT_EQ(scene_ground_height(city), 0.0);
  EXPECT_LT(city.bounds().lo.y, 0.0);
  const LightSet fitted = fit_light_set(city, LightSetSpec::parse("sun-path:azimuth=100..260,elevation=25..65,samples=2"));
  EXPECT_EQ(fitted.samples[0].origin().y, 0.0);
  EXPECT_NE(fitted.spec.to_string().find("ground=0"), std::string::npos);
}

TEST(GroundFrame, FrameFieldAndTheStretchLimit) {
  EXPECT_EQ(LightSetSpec::parse("sun-path:azimuth=1,elevation=40,samples=2").sun_frame, SunFrame::ground);
  const LightSetSpec o = LightSetSpec::parse("sun-path:azimuth=1,elevation=40,samples=2,frame=ortho");
  EXPECT_EQ(o.sun_frame, SunFrame::ortho);
  EXPECT_EQ(LightSetSpec::parse(o.to_string()).sun_frame, SunFrame::ortho);
  EXPECT_THROW(LightSetSpec::parse("sun-path:azimuth=1,elevation=40,samples=2,frame=tilted"), Error);
  // A tall narrow scene under a sun near the horizon: the square would be huge.
  Aabb tower;
  tower.extend({-1, 0, -1});
  tower.extend({1, 100, 1});
  try {
    LightSet::fit(LightSetSpec::parse("sun-path:azimuth=0..90,elevation=2..30,samples=3"), tower);
    ADD_FAILURE() << "a stretched ground square was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("frame=ground"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(
      LightSet::fit(LightSetSpec::parse("sun-path:azimuth=0..90,elevation=2..30,samples=3,frame=ortho"), tower));
}

// Every texel of every slice of a traced ground-frame stack (Embree) lies in its interval
// after the octree's encode and decode (the lossless invariant, MH §4).
TEST(GroundFrame, TracedStackIsLosslessOnEveryTexelOfEverySlice) {
  const uint32_t level = stacks::small_scale() ? 5 : 6;
  const char* scene = "procedural:city,size=2";
  const LightSet set = stacks::fitted_set(scene, "sun-path:azimuth=100..260,elevation=25..65,samples=6");
  ASSERT_EQ(set.samples[0].kind(), LightKind::sun_ground);
  const IntervalStack stack = stacks::traced_stack(scene, set, level);
  const std::vector<uint8_t> bytes = encode_octree(build_octree(stack));
  const MhOctree tree = MhOctree::open(bytes);
  EXPECT_EQ(stacks::first_violation(stack, [&](uint64_t x, uint64_t y, uint32_t w) {
              return tree.depth(x, y, w, level);
            }),
            "");
  // The soft lookup's batched transform (SampleTexels, the ground frame's shared offsets)
  // is to_light bit for bit, and the shared walk equals independent lookups; receivers on
  // the ground read one texel.
  const SampleTexels texels(set.samples, level);
  const StackLookup look(tree, set);
  const Aabb b = load_scene(scene).bounds();
  Rng rng(5);
  uint64_t ground_nodes = 0;
  for (int i = 0; i < 400; ++i) {
    const bool on_ground = i % 2 == 0;
    const Vec3d p{rng.uniform(b.lo.x, b.hi.x), on_ground ? 0.0 : rng.uniform(b.lo.y, b.hi.y), rng.uniform(b.lo.z, b.hi.z)};
    SampleTexels::Run run;
    texels.run(p, 0, set.size(), run);
    for (uint32_t w = 0; w < set.size(); ++w) {
      const LightPoint lp = set.samples[w].to_light(p);
      const auto t = LightSpace::texel_of(level, lp.u, lp.v);
      ASSERT_EQ(run.x[w], t[0]) << i << " " << w;
      ASSERT_EQ(run.y[w], t[1]) << i << " " << w;
      ASSERT_EQ(run.d[w], float(lp.d));
      if (on_ground) {
        ASSERT_EQ(run.x[w], run.x[0]);
        ASSERT_EQ(run.y[w], run.y[0]);
      }
    }
    ASSERT_EQ(look.soft_visibility(p), look.soft_visibility_independent(p)) << i;
    if (on_ground) ground_nodes += StackLookup::last_nodes_visited();
  }
  {  // the batched lookup (interleaved walks, the ground frame's shared transform)
    std::vector<Vec3d> pts;
    for (int i = 0; i < 200; ++i)
      pts.push_back({rng.uniform(b.lo.x, b.hi.x), i % 2 ? 0.0 : rng.uniform(b.lo.y, b.hi.y), rng.uniform(b.lo.z, b.hi.z)});
    std::vector<float> out(pts.size());
    look.soft_visibility(pts, out);
    for (size_t i = 0; i < pts.size(); ++i) ASSERT_EQ(out[i], look.soft_visibility(pts[i])) << i;
  }
  // One full walk and then only the w steps: under 3 nodes per sample on average.
  EXPECT_LT(ground_nodes, 200u * 3 * set.size());
  uint64_t hit = 0;
  for (uint32_t w = 0; w < stack.slices; ++w)
    for (uint64_t y = 0; y < stack.side(); ++y)
      for (uint64_t x = 0; x < stack.side(); ++x) hit += stack.at(x, y, w).lo < 1.0f;
  EXPECT_GT(hit, stack.side() * stack.side());  // geometry in view
}

}  // namespace ground_frame_test
}  // namespace st

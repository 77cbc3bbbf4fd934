// The area light's window frame (light_set.hpp "Frames", LightKind::spot_window): a point
// on the reference plane lands on one texel in every slice, every sample's map holds what
// the centred spot sees, the serialized form round-trips and bad arrays are refused, and
// a traced window-frame stack keeps the lossless invariant on every texel of every slice.
#include <gtest/gtest.h>

#include <cmath>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/core/mh_octree.hpp"

namespace st {
namespace window_frame_test {

constexpr char kLight[] = "area:pos=1,14,2,target=0,0,0,size=4,3,samples=16,jitter=0.5";

Aabb box() {
  Aabb b;
  b.extend({-6, -2, -5});
  b.extend({5, 4, 6});
  return b;
}

TEST(WindowFrame, ReferencePlanePointsShareOneTexelInEverySlice) {
  const LightSetSpec spec = LightSetSpec::parse(kLight);
  ASSERT_EQ(spec.area_frame, AreaFrame::window);
  const LightSet set = LightSet::fit(spec, box());
  const LightSpace& s0 = set.samples[0];
  const Vec3d F = s0.forward(), U = s0.axis_u(), V = s0.axis_v();
  const double D = dot(spec.target - spec.pos, F), E = s0.extent_uv();
  for (const LightSpace& ls : set.samples) {
    ASSERT_EQ(ls.kind(), LightKind::spot_window);
    EXPECT_EQ(ls.extent_uv(), E);
    EXPECT_EQ(ls.near_plane(), s0.near_plane());
    EXPECT_EQ(ls.far_plane(), s0.far_plane());
    EXPECT_EQ(ls.forward(), F);
  }
  EXPECT_GT(E, 2 * std::tan(30 * 3.14159265358979323846 / 180));  // grown past the centred spot's
  const uint32_t level = 10, side = 1u << level;
  Rng rng(3);
  uint32_t moved_translate = 0;
  const LightSet translate = LightSet::fit(LightSetSpec::parse(std::string(kLight) + ",frame=translate"), box());
  for (int i = 0; i < 500; ++i) {
    const uint64_t x = rng.next() % side, y = rng.next() % side;
    // The texel centre's point on the reference plane (u = dot(p - pos, U) / (D E) + 0.5).
    const double u = (double(x) + 0.5) / side, v = (double(y) + 0.5) / side;
    const Vec3d p = spec.target + U * ((u - 0.5) * E * D) + V * ((v - 0.5) * E * D);
    for (uint32_t w = 0; w < set.size(); ++w) {
      const LightPoint lp = set.samples[w].to_light(p);
      const auto t = LightSpace::texel_of(level, lp.u, lp.v);
      ASSERT_EQ(t[0], x) << "slice " << w;
      ASSERT_EQ(t[1], y) << "slice " << w;
      EXPECT_NEAR(lp.d, set.samples[0].to_light(p).d, 1e-12);
      // Texel (x, y)'s ray of every sample passes through p.
      const LightRay r = set.samples[w].texel_ray(level, x, y);
      EXPECT_LT(length(r.origin + r.dir * D - p), 1e-9 * D);
      const LightPoint tp = translate.samples[w].to_light(p);
      moved_translate += LightSpace::texel_of(level, tp.u, tp.v) != t;
    }
  }
  EXPECT_GT(moved_translate, 4000u) << "the translate frame moves the plane's points between slices";
  // Every point the centred spot sees between near and far is inside every sample's map.
  LightSpec centre;
  centre.kind = LightKind::spot;
  centre.pos = spec.pos, centre.target = spec.target, centre.fov_deg = spec.fov_deg;
  const LightSpace c = LightSpace::fit(centre, box());
  uint32_t seen = 0;
  for (int i = 0; i < 4000; ++i) {
    const Vec3d p{rng.uniform(-6, 5), rng.uniform(-2, 4), rng.uniform(-5, 6)};
    const LightPoint cp = c.to_light(p);
    if (!(cp.u >= 0 && cp.u < 1 && cp.v >= 0 && cp.v < 1)) continue;
    ++seen;
    for (const LightSpace& ls : set.samples) {
      const LightPoint lp = ls.to_light(p);
      ASSERT_TRUE(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1 && lp.d >= 0 && lp.d <= 1) << i;
    }
  }
  EXPECT_GT(seen, 1000u);
}

TEST(WindowFrame, SerializationRoundTripsAndBadArraysAreRefused) {
  const LightSet set = LightSet::fit(LightSetSpec::parse(kLight), box());
  const LightSpace& ls = set.samples[5];
  const std::array<double, 18> a = ls.to_array();
  EXPECT_EQ(LightSpace::check_array(LightKind::spot_window, a), "");
  const LightSpace back = LightSpace::from_array(LightKind::spot_window, a);
  EXPECT_EQ(back.to_array(), a);
  EXPECT_EQ(back.window_shift(), ls.window_shift());
  EXPECT_NE(ls.window_shift()[0], 0.0);
  const Vec3d p{0.3, 1.2, -0.7};
  EXPECT_EQ(back.to_light(p).u, ls.to_light(p).u);
  EXPECT_EQ(back.to_light(p).v, ls.to_light(p).v);
  EXPECT_NE(ls.spec().to_string().find("spot-window:"), std::string::npos);
  EXPECT_STREQ(light_kind_name(LightKind::spot_window), "spot-window");
  // A texel's ray lands back on its texel.
  const LightRay r = ls.texel_ray(7, 37, 91);
  const LightPoint q = ls.to_light(r.origin + r.dir * (0.5 * (ls.near_plane() + ls.far_plane())));
  EXPECT_EQ(LightSpace::texel_of(7, q.u, q.v), (std::array<uint64_t, 2>{37, 91}));
  auto refused = [&](std::array<double, 18> bad, LightKind kind, const char* what) {
    const std::string why = LightSpace::check_array(kind, bad);
    EXPECT_NE(why.find(what), std::string::npos) << "'" << why << "' should name " << what;
    EXPECT_EQ(why.find('\n'), std::string::npos);
  };
  std::array<double, 18> bad = a;
  bad[15] = NAN;
  refused(bad, LightKind::spot_window, "c_u");
  bad = a, bad[16] = -1e3;
  refused(bad, LightKind::spot_window, "window shift c_v");
  bad = a, bad[17] = 175;
  refused(bad, LightKind::spot_window, "fov");
  refused(a, LightKind(4), "unknown light kind 4");
  refused(a, LightKind(9), "unknown light kind 9");
  // A windowed spot's array read as a ground-frame sun is refused on the ground frame's terms.
  EXPECT_FALSE(LightSpace::check_array(LightKind::sun_ground, a).empty());
  EXPECT_FALSE(light_kind_known(4));
  EXPECT_TRUE(light_kind_known(2));
  EXPECT_TRUE(light_kind_known(3));
  // The frame is chosen by name; a window no spot can hold is refused with one line.
  EXPECT_EQ(LightSet::fit(LightSetSpec::parse(std::string(kLight) + ",frame=translate"), box()).samples[0].kind(),
            LightKind::spot);
  EXPECT_THROW(LightSetSpec::parse(std::string(kLight) + ",frame=sheared"), Error);
  EXPECT_THROW(LightSpec::parse("spot-window:pos=0,1,0,target=0,0,0"), Error);
  try {
    LightSet::fit(LightSetSpec::parse("area:pos=0,3,0,target=0,0,0,size=40,40,samples=4"), box());
    ADD_FAILURE() << "a 40 x 40 light 1 m above the scene fitted a window";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("frame=translate"), std::string::npos) << e.what();
  }
}

TEST(WindowFrame, TracedStackIsLosslessOnEveryTexelOfEverySlice) {
  const uint32_t level = stacks::small_scale() ? 5 : 6;
  const char* scene = "procedural:hairball,count=10";
  const LightSet set = stacks::fitted_set(scene, "area:pos=2,14,1,target=0,0,0,size=3,3,samples=8,jitter=0.5");
  ASSERT_EQ(set.samples[0].kind(), LightKind::spot_window);
  const IntervalStack stack = stacks::traced_stack(scene, set, level);
  uint64_t hit = 0;
  for (const Interval& iv : stack.data) hit += iv.lo < kLitDepth;
  EXPECT_GT(hit, stack.data.size() / 100);
  const std::vector<uint8_t> bytes = encode_octree(build_octree(stack));
  const MhOctree tree = MhOctree::open(bytes);
  EXPECT_EQ(stacks::first_violation(stack, [&](uint64_t x, uint64_t y, uint32_t w) {
              return tree.depth(x, y, w, level);
            }),
            "");
}

}  // namespace window_frame_test
}  // namespace st

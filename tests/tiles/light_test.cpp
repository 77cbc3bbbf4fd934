#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tiles/core/light.hpp"

namespace st {
namespace {

Aabb unit_box() {
  Aabb b;
  b.extend({-1, -1, -1});
  b.extend({1, 1, 1});
  return b;
}

TEST(LightSpec, ParsesSunAndSpotAndRejectsBadFields) {
  auto s = LightSpec::parse("sun:azimuth=30,elevation=45,margin=0.05");
  EXPECT_EQ(s.kind, LightKind::sun);
  EXPECT_DOUBLE_EQ(s.azimuth_deg, 30);
  EXPECT_DOUBLE_EQ(s.margin, 0.05);
  auto p = LightSpec::parse("spot:pos=0,10,0,target=0,0,0,fov=40");
  EXPECT_EQ(p.kind, LightKind::spot);
  EXPECT_EQ(p.pos, (Vec3d{0, 10, 0}));
  EXPECT_THROW(LightSpec::parse("sun:azimuth=30,elevation=0"), Error);
  EXPECT_THROW(LightSpec::parse("sun:azimuth=30,elevation=91"), Error);
  EXPECT_THROW(LightSpec::parse("sun:azimuth=x,elevation=45"), Error);
  EXPECT_THROW(LightSpec::parse("moon:azimuth=1"), Error);
  EXPECT_THROW(LightSpec::parse("sun:azimuth=30,elevation=45,colour=3"), Error);
  EXPECT_THROW(LightSpec::parse("spot:pos=1,2,target=0,0,0"), Error);
}

TEST(LightSpace, SunTexelRaysRoundTripThroughToLight) {
  auto ls = LightSpace::fit(LightSpec::parse("sun:azimuth=37,elevation=23"), unit_box());
  for (uint32_t level : {0u, 5u, 20u}) {
    uint64_t r = uint64_t(1) << level;
    for (uint64_t x : {uint64_t(0), r / 3, r - 1}) {
      auto ray = ls.texel_ray(level, x, r - 1 - x);
      auto p = ls.to_light(ray.origin + ray.dir * 0.25);
      auto t = LightSpace::texel_of(level, p.u, p.v);
      EXPECT_EQ(t[0], x);
      EXPECT_EQ(t[1], r - 1 - x);
      EXPECT_NEAR(p.d, 0.25, 1e-12);
    }
  }
}

TEST(LightSpace, StraightDownSunBoxContainsTheSceneWithMargin) {
  auto ls = LightSpace::fit(LightSpec::parse("sun:azimuth=0,elevation=90,margin=0"), unit_box());
  auto top = ls.to_light({0, 1, 0});
  auto bottom = ls.to_light({0, -1, 0});
  EXPECT_NEAR(top.d, 0, 1e-12);
  EXPECT_NEAR(bottom.d, 1, 1e-12);
  EXPECT_NEAR(top.u, 0.5, 1e-12);
}

TEST(LightSpace, SpotDepthIsLinearAlongTheAxis) {
  auto ls = LightSpace::fit(LightSpec::parse("spot:pos=0,10,0,target=0,0,0,fov=60"), unit_box());
  auto a = ls.to_light({0, 1, 0});
  auto b = ls.to_light({0, 0, 0});
  auto c = ls.to_light({0, -1, 0});
  EXPECT_NEAR(b.d - a.d, c.d - b.d, 1e-12);
  auto ray = ls.texel_ray(10, 100, 900);
  for (double t : {9.5, 10.0, 10.5}) {
    auto p = ls.to_light(ray.origin + ray.dir * t);
    EXPECT_NEAR(p.d, ls.depth_of_t(ray, t), 1e-12);
    auto tx = LightSpace::texel_of(10, p.u, p.v);
    EXPECT_EQ(tx[0], 100u);
    EXPECT_EQ(tx[1], 900u);
  }
}

TEST(LightSpace, ZeroExtentBoxIsAClearError) {
  Aabb point;
  point.extend({1, 2, 3});
  EXPECT_THROW(LightSpace::fit(LightSpec::parse("sun:azimuth=0,elevation=90"), point), Error);
  EXPECT_THROW(LightSpace::fit(LightSpec::parse("sun:azimuth=0,elevation=90"), Aabb{}), Error);
}

TEST(LightSpace, SerializedFormRoundTripsExactly) {
  auto ls = LightSpace::fit(LightSpec::parse("sun:azimuth=12.5,elevation=33"), unit_box());
  auto back = LightSpace::from_array(ls.kind(), ls.to_array());
  EXPECT_EQ(back.to_array(), ls.to_array());
}

}  // namespace
}  // namespace st

namespace st {
namespace {

// texel_of is floor(u * 2^level) clamped to the map (computed without a floor call): the
// definition on edges, NaN, infinities, signed zero and random values.
TEST(LightSpace, TexelOfIsTheClampedFloor) {
  auto reference = [](uint32_t level, double w) -> uint64_t {
    const double r = std::ldexp(1.0, int(level)), f = std::floor(w * r);
    if (!(f >= 0)) return 0;
    return f >= r ? uint64_t(r) - 1 : uint64_t(f);
  };
  std::vector<double> ws = {0.0, -0.0, 1.0, -1e-300, 1e-300, 0.5, 1.0 - 1e-16, 1.0 + 1e-16, 2.0, -3.5,
                            std::nan(""), INFINITY, -INFINITY, std::nextafter(1.0, 0.0)};
  Rng rng(3);
  for (int i = 0; i < 2000; ++i) ws.push_back(rng.uniform(-0.25, 1.25));
  for (uint32_t level : {0u, 1u, 7u, 10u, 20u, 40u})
    for (double w : ws) {
      const auto t = LightSpace::texel_of(level, w, 1.0 - w);
      ASSERT_EQ(t[0], reference(level, w)) << level << " " << w;
      ASSERT_EQ(t[1], reference(level, 1.0 - w)) << level << " " << w;
    }
}

}  // namespace
}  // namespace st

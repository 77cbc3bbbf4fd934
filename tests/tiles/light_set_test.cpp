#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "common/error.hpp"
#include "tiles/core/light_set.hpp"

namespace st {
namespace light_set_test {

Aabb unit_box() {
  Aabb b;
  b.extend({-1, -1, -1});
  b.extend({1, 1, 1});
  return b;
}

TEST(LightSet, SunPathSamplesAreLinearInTimeAndEachFitted) {
  auto spec = LightSetSpec::parse("sun-path:azimuth=90..270,elevation=20..60,samples=5,frame=ortho");
  ASSERT_EQ(spec.kind, LightSetKind::sun_path);
  auto set = LightSet::fit(spec, unit_box());
  ASSERT_EQ(set.size(), 5u);
  EXPECT_DOUBLE_EQ(set.samples[0].spec().azimuth_deg, 90);
  EXPECT_DOUBLE_EQ(set.samples[2].spec().azimuth_deg, 180);
  EXPECT_DOUBLE_EQ(set.samples[4].spec().elevation_deg, 60);
  EXPECT_DOUBLE_EQ(set.time_of(4), 1.0);
  // Reversed ranges are a sun moving the other way; a single angle is a constant.
  auto back = LightSetSpec::parse("sun-path:azimuth=270..90,elevation=45,samples=3").sample_specs();
  EXPECT_DOUBLE_EQ(back[1].azimuth_deg, 180);
  EXPECT_DOUBLE_EQ(back[2].elevation_deg, 45);
  // Each sample's light space is its own sun's: the forward axis follows the angles.
  EXPECT_GT(length(set.samples[0].forward() - set.samples[4].forward()), 0.5);
  // One box size and depth range for every slice; below the zenith the frame is fit()'s.
  for (const LightSpace& ls : set.samples) {
    EXPECT_EQ(ls.extent_uv(), set.samples[0].extent_uv());
    EXPECT_EQ(ls.far_plane(), set.samples[0].far_plane());
  }
  const LightSpace alone = LightSpace::fit(set.samples[2].spec(), unit_box());
  EXPECT_NEAR(dot(alone.axis_u(), set.samples[2].axis_u()), 1.0, 1e-12);
  // Through the zenith region the frame turns smoothly (fit() switches its helper axis).
  auto steep = LightSet::fit(LightSetSpec::parse("sun-path:azimuth=10..40,elevation=30..90,samples=31,frame=ortho"), unit_box());
  for (uint32_t w = 1; w < steep.size(); ++w) {
    EXPECT_GT(dot(steep.samples[w].axis_u(), steep.samples[w - 1].axis_u()), 0.99) << w;
    EXPECT_GT(dot(steep.samples[w].axis_v(), steep.samples[w - 1].axis_v()), 0.99) << w;
  }
  // Round trip through the text form.
  EXPECT_EQ(LightSetSpec::parse(spec.to_string()).sample_specs().size(), 5u);
}

TEST(LightSet, AreaSamplesFollowTheHilbertCurveOnTheRectangle) {
  auto spec = LightSetSpec::parse("area:pos=0,10,0,target=0,0,0,size=2,4,samples=16");
  auto specs = spec.sample_specs();
  ASSERT_EQ(specs.size(), 16u);
  std::set<std::pair<long, long>> seen;
  const LightSpace centre = LightSpace::fit(specs[0], unit_box());
  for (size_t w = 0; w < specs.size(); ++w) {
    const Vec3d off = specs[w].pos - spec.pos;
    EXPECT_NEAR(off.y, 0, 1e-12);  // on the rectangle through pos, facing down
    EXPECT_EQ(specs[w].target - specs[w].pos, spec.target - spec.pos);  // parallel frusta
    const double fu = dot(off, centre.axis_u()) / 2, fv = dot(off, centre.axis_v()) / 4;
    EXPECT_LT(std::fabs(fu), 0.5);
    EXPECT_LT(std::fabs(fv), 0.5);
    seen.insert({std::lround(fu * 8 + 4), std::lround(fv * 8 + 4)});
    if (w > 0) {  // Hilbert order: consecutive samples are neighbouring cells
      const Vec3d step = specs[w].pos - specs[w - 1].pos;
      const double cells = std::fabs(dot(step, centre.axis_u())) / 0.5 + std::fabs(dot(step, centre.axis_v())) / 1.0;
      EXPECT_NEAR(cells, 1.0, 1e-9) << "sample " << w;
    }
  }
  EXPECT_EQ(seen.size(), 16u);  // every cell of the 4x4 grid once
  // Jitter moves the points within their cells, the same way for the same seed.
  auto j1 = LightSetSpec::parse("area:pos=0,10,0,target=0,0,0,size=2,4,samples=16,jitter=1,seed=7").sample_specs();
  auto j2 = LightSetSpec::parse("area:pos=0,10,0,target=0,0,0,size=2,4,samples=16,jitter=1,seed=7").sample_specs();
  EXPECT_EQ(j1[3].pos, j2[3].pos);
  EXPECT_NE(j1[3].pos, specs[3].pos);
  EXPECT_LT(length(j1[3].pos - specs[3].pos), 0.5 * std::hypot(0.5, 1.0) + 1e-12);
  // N not a power of four: spread along the curve, all distinct.
  auto odd = LightSetSpec::parse("area:pos=0,10,0,target=0,0,0,size=1,1,samples=5").sample_specs();
  for (size_t w = 1; w < odd.size(); ++w) EXPECT_NE(odd[w].pos, odd[w - 1].pos);
  const LightSet fitted = LightSet::fit(spec, unit_box());
  ASSERT_EQ(fitted.size(), 16u);
  for (const LightSpace& ls : fitted.samples) {
    EXPECT_EQ(ls.near_plane(), fitted.samples[0].near_plane());
    EXPECT_EQ(ls.far_plane(), fitted.samples[0].far_plane());
    EXPECT_EQ(ls.forward(), fitted.samples[0].forward());
  }
}

TEST(LightSet, BadSetsGetOneClearLine) {
  const char* bad[] = {
      "sun-path:azimuth=0..90,elevation=10..20,samples=0",
      "sun-path:azimuth=0..90,elevation=10..20,samples=5000",
      "sun-path:azimuth=0..90,elevation=10..20,samples=2.5",
      "sun-path:azimuth=0..nan,elevation=10..20,samples=4",
      "sun-path:azimuth=0..720,elevation=10..20,samples=4",
      "sun-path:azimuth=0..90,elevation=-5..20,samples=4",
      "sun-path:azimuth=0..90,elevation=10..95,samples=4",
      "sun-path:azimuth=0..90,samples=4",
      "sun-path:azimuth=0..90,elevation=10..20",
      "sun-path:azimuth=0..90,elevation=10..20,samples=4,samples=5",
      "sun-path:azimuth=0..90,elevation=10..20,samples=4,size=1,1",
      "area:pos=0,1,0,target=0,0,0,size=0,1,samples=4",
      "area:pos=0,1,0,target=0,0,0,size=1,samples=4",
      "area:pos=0,0,0,target=0,0,0,size=1,1,samples=4",
      "area:pos=0,1,0,target=0,0,0,size=1,1,samples=4,jitter=2",
      "area:pos=0,1,0,target=0,0,0,size=1,1,samples=4,fov=180",
      "area:pos=0,1,inf,target=0,0,0,size=1,1,samples=4",
      "area:pos=0,1,0,target=0,0,0,samples=4",
      "disc:pos=0,1,0",
  };
  for (const char* text : bad) {
    try {
      LightSetSpec::parse(text);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
      EXPECT_EQ(msg.rfind("--light", 0), 0u) << msg;
    }
  }
  EXPECT_TRUE(LightSetSpec::names_light_set("sun-path:azimuth=1"));
  EXPECT_TRUE(LightSetSpec::names_light_set("area:pos=1,2,3"));
  EXPECT_FALSE(LightSetSpec::names_light_set("sun:azimuth=1,elevation=2"));
  // A single-light reader names the light set instead of calling it unknown.
  try {
    LightSpec::parse("sun-path:azimuth=0..90,elevation=10..20,samples=4");
    ADD_FAILURE() << "a single light accepted a light set";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("light set"), std::string::npos) << e.what();
  }
}

TEST(LightSet, HilbertCurveVisitsEveryCellWithUnitSteps) {
  for (uint32_t order : {0u, 1u, 3u}) {
    const uint64_t n = uint64_t(1) << (2 * order);
    std::set<std::pair<uint32_t, uint32_t>> cells;
    uint32_t px = 0, py = 0;
    for (uint64_t d = 0; d < n; ++d) {
      uint32_t x = 0, y = 0;
      hilbert_cell(order, d, x, y);
      cells.insert({x, y});
      if (d > 0) {
        EXPECT_EQ(std::abs(int(x) - int(px)) + std::abs(int(y) - int(py)), 1);
      }
      px = x, py = y;
    }
    EXPECT_EQ(cells.size(), n);
  }
}

}  // namespace light_set_test
}  // namespace st

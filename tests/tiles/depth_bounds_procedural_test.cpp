// Dual depth bounds of the procedural scenes (branch `scenes`) against the double
// reference: the loader's closed/outward meshes (MH §3.1, voxel §6.1) end to end.
#include <gtest/gtest.h>

#include "tests/tiles/depth_bounds_reference.hpp"
#include "tiles/bake/depth_bounds.hpp"

namespace st {
namespace {

struct Case {
  const char* spec;
  const char* light;
  uint32_t level, stride;
};

TEST(DepthBoundsProcedural, ScenesMatchTheDoubleReference) {
  const bool small = test::small_scale();
  const Case cases[] = {
      {"procedural:cube", "sun:azimuth=20,elevation=60", 7, 1},
      {"procedural:sphere,segments=24", "sun:azimuth=200,elevation=35", 7, 1},
      {"procedural:boxes", "sun:azimuth=45,elevation=55", 7, 1},
      {"procedural:city,size=2", "sun:azimuth=30,elevation=50", 9, small ? 400u : 100u},
      {"procedural:terrain,size=32", "sun:azimuth=120,elevation=20", 8, small ? 100u : 50u},
      {"procedural:hairball,count=8", "sun:azimuth=10,elevation=70", 8, small ? 100u : 50u},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.spec);
    Scene s = load_scene(c.spec);
    LightSpace l = LightSpace::fit(LightSpec::parse(c.light), s.bounds());
    DepthBoundsTracer tracer(s, l);
    EXPECT_TRUE(tracer.traces_exit_depths());
    const uint32_t level = small ? c.level - 1 : c.level;
    DepthBoundsStats st;
    auto tile = tracer.trace({level, 0, 0, 1u << level, 1u << level}, TraceMode::bounds, &st);
    for (const Interval& iv : tile.data) {
      ASSERT_LE(iv.lo, iv.hi);
      ASSERT_GE(iv.lo, 0.0f);
      ASSERT_LE(iv.hi, 1.0f);
    }
    auto r = test::compare_with_reference(s, l, tile, 16, c.stride);
    EXPECT_GT(r.compared, 100u);
    EXPECT_GT(st.hits, 0u);
    EXPECT_GT(st.closed, st.hits / 2) << "every procedural mesh is closed";
    EXPECT_LT(st.fallbacks, st.hits / 200 + 2);
  }
}

}  // namespace
}  // namespace st

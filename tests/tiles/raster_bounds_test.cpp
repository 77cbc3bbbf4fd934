// The light-space rasterizer (tiles/bake/raster_bounds.hpp) against the same canonical
// definition evaluated with every triangle as a candidate: binning is the only thing the
// rasterizer adds, so (lo, hi) must agree bit for bit on every texel, on open soups,
// coplanar hazards, terrain, a city of touching buildings on a slab, hairball tubes and
// a sphere, under oblique, grazing and steep suns; any sub-region gives the same bits.
#include <gtest/gtest.h>

#include <cstring>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/tiles/depth_bounds_reference.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/canonical_coverage.hpp"
#include "tiles/bake/raster_bounds.hpp"

namespace st {
namespace {

bool same_bits(const Interval& a, const Interval& b) {
  return std::memcmp(&a.lo, &b.lo, sizeof(float)) == 0 &&
         std::memcmp(&a.hi, &b.hi, sizeof(float)) == 0;
}

const char* const kSuns[] = {
    "sun:azimuth=30,elevation=50",
    "sun:azimuth=77,elevation=0.5",     // grazing
    "sun:azimuth=200,elevation=89.99",  // steep
};

void expect_equal_to_brute_force(const Scene& scene, const char* sun, uint32_t level) {
  const LightSpace light = LightSpace::fit(LightSpec::parse(sun), scene.bounds());
  const RasterBounds rb(scene, light);
  const uint32_t side = 1u << level;
  const IntervalTile whole = rb.trace(TraceRegion{level, 0, 0, side, side});
  uint64_t hits = 0, closed = 0;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      const Interval ref = rb.brute_force_texel(level, x, y);
      const Interval got = whole.at(x, y);
      ASSERT_TRUE(same_bits(ref, got)) << scene.name << " " << sun << " texel " << x << ","
                                       << y << ": raster [" << got.lo << ", " << got.hi
                                       << "] reference [" << ref.lo << ", " << ref.hi << "]";
      hits += ref.lo < kLitDepth;
      closed += ref.hi > ref.lo;
    }
  EXPECT_GT(hits, 0u) << scene.name << " " << sun;
  // An odd sub-region at an odd offset gives the same bits.
  const uint32_t x0 = side / 3 + 1, y0 = side / 5 + 3, w = side / 2 + 1, h = side / 3 + 1;
  const IntervalTile part = rb.trace(TraceRegion{level, x0, y0, w, h});
  for (uint32_t j = 0; j < h; ++j)
    for (uint32_t i = 0; i < w; ++i)
      ASSERT_TRUE(same_bits(part.at(i, j), whole.at(x0 + i, y0 + j))) << i << "," << j;
  (void)closed;
}

TEST(RasterBounds, EqualsTheCanonicalDefinitionOnEveryTexel) {
  const std::vector<Scene> scenes = {
      test::hazard_town(), test::rotated_terrain(), test::all_open(test::hazard_town()),
      make_procedural("procedural:city,size=2"),
      make_procedural("procedural:sphere,segments=24"),
      make_procedural("procedural:hairball,count=8,segments=12"),
  };
  for (const Scene& s : scenes)
    for (const char* sun : kSuns) expect_equal_to_brute_force(s, sun, test::small_scale() ? 4 : 5);
}

// Edges through texel centres: a heightfield whose vertices lie on the texel rays of every
// other texel, so rows, columns and diagonals of texel centres fall on edges and
// vertices, where the fast edge values are within their bounds and the definition
// decides (with the bounds set to zero this test fails).
TEST(RasterBounds, EdgesThroughTexelCentresEqualTheDefinition) {
  const uint32_t level = test::small_scale() ? 4 : 5, side = 1u << level, n = side / 2 + 1;
  for (const char* sun : {kSuns[0], kSuns[1]}) {
    Scene box = make_procedural("procedural:cube");
    const LightSpace light = LightSpace::fit(LightSpec::parse(sun), box.bounds());
    Scene s;
    s.name = "texel_ray_grid";
    uint64_t rng = 7;
    for (uint32_t y = 0; y < n; ++y)
      for (uint32_t x = 0; x < n; ++x) {
        const LightRay r = light.texel_ray(level, std::min(2 * x, side - 1), std::min(2 * y, side - 1));
        const double t = 0.3 + 0.4 * double(splitmix64(rng) >> 11) * 0x1p-53;
        s.vertices.push_back(r.origin + r.dir * t);
      }
    Mesh grid;
    grid.name = "grid";
    grid.closed = (level & 1) != 0;  // closed-flagged open grid: counting falls back
    for (uint32_t y = 0; y + 1 < n; ++y)
      for (uint32_t x = 0; x + 1 < n; ++x) {
        const uint32_t a = y * n + x, b = a + 1, c = a + n, d = c + 1;
        s.triangles.push_back({a, b, d});
        s.triangles.push_back({a, d, c});
      }
    grid.triangle_count = uint32_t(s.triangles.size());
    s.meshes.push_back(grid);
    const RasterBounds rb(s, light);
    const IntervalTile whole = rb.trace(TraceRegion{level, 0, 0, side, side});
    uint64_t hits = 0;
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) {
        const Interval ref = rb.brute_force_texel(level, x, y);
        ASSERT_TRUE(same_bits(ref, whole.at(x, y))) << sun << " texel " << x << "," << y;
        hits += ref.lo < kLitDepth;
      }
    EXPECT_GT(hits, uint64_t(side) * side / 2) << sun;
  }
}

TEST(RasterBounds, ClosedSceneGetsExitDepths) {
  const Scene s = make_procedural("procedural:cube");
  const LightSpace light = LightSpace::fit(LightSpec::parse(kSuns[0]), s.bounds());
  const IntervalTile t = RasterBounds(s, light).trace(TraceRegion{6, 0, 0, 64, 64});
  uint64_t hit = 0, thick = 0;
  for (const Interval& iv : t.data) {
    EXPECT_LE(iv.lo, iv.hi);
    hit += iv.lo < kLitDepth;
    thick += iv.hi > iv.lo;
  }
  EXPECT_GT(hit, 0u);
  // Watertight: every texel that meets the cube enters and leaves it (no fallback).
  EXPECT_EQ(thick, hit);
}

TEST(RasterBounds, RefusesSpotLights) {
  const Scene s = make_procedural("procedural:cube");
  const LightSpace light =
      LightSpace::fit(LightSpec::parse("spot:pos=3,6,2,target=0,0.5,0,fov=50"), s.bounds());
  EXPECT_THROW({ const RasterBounds rb(s, light); }, Error);
}

}  // namespace
}  // namespace st

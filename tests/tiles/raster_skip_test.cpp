// The rasterizer's per-tile skip (RasterSkip, tiles/bake/raster_bounds.hpp): on closed
// scenes (city, sphere, hairball), open soups, terrain and under a grazing sun, the exact
// skip gives the same bits as the full coverage path on every texel; the narrow skip gives
// sub-intervals of the true ones; and a pack built with narrowed intervals records it and
// keeps the lossless invariant against the true intervals on every texel. Whole regions
// (RasterSkip::regions): an interval a region's corners prove lies inside every texel's
// true interval, and a pack built top-down over such regions is lossless on every texel.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <optional>

#include "interval_fields.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace raster_skip_test {

bool same_bits(const Interval& a, const Interval& b) {
  return std::memcmp(&a.lo, &b.lo, sizeof(float)) == 0 && std::memcmp(&a.hi, &b.hi, sizeof(float)) == 0;
}

// Closed boxes with every face split into n x n quads (so that surfaces are many
// triangles): a ground slab, a slab floating above it (an overhang: the ground shows
// beside and under it), a tower standing on the ground (its floor touches the slab's top),
// and two boxes intersecting each other. Coordinates are multiples of 1/8, so shared
// corners and edges have exactly equal positions.
Scene closed_stack() {
  test::HazardBuilder b("closed_stack");
  auto box = [&](const std::string& name, Vec3d lo, Vec3d hi, int n) {
    b.mesh(name, true);
    const Vec3d d = hi - lo;
    const Vec3d X{d.x, 0, 0}, Y{0, d.y, 0}, Z{0, 0, d.z};
    // (origin, U, V) with U x V outwards.
    const Vec3d faces[6][3] = {{lo, Z, Y},
                               {{hi.x, lo.y, lo.z}, Y, Z},
                               {lo, X, Z},
                               {{lo.x, hi.y, lo.z}, Z, X},
                               {lo, Y, X},
                               {{lo.x, lo.y, hi.z}, X, Y}};
    for (const auto& f : faces) {
      auto at = [&](int i, int j) { return f[0] + f[1] * (double(i) / n) + f[2] * (double(j) / n); };
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) b.quad(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
    }
  };
  box("ground", {0, -0.5, 0}, {8, 0, 8}, 4);
  box("floating", {2, 2, 2}, {5, 2.5, 5}, 4);
  box("tower", {5.5, 0, 5.5}, {7, 3, 7}, 2);
  box("cross_a", {0.5, 0, 5}, {2.5, 1, 6.5}, 2);
  box("cross_b", {2, 0, 5.5}, {3, 1.5, 7}, 2);
  return b.take();
}

struct SkipCase {
  Scene scene;
  const char* sun;
};

std::vector<SkipCase> cases() {
  return {{make_procedural("procedural:city,size=2"), "sun:azimuth=30,elevation=50"},
          {make_procedural("procedural:city,size=2"), "sun:azimuth=77,elevation=0.5"},  // grazing
          {make_procedural("procedural:sphere,segments=24"), "sun:azimuth=200,elevation=70"},
          {make_procedural("procedural:cube"), "sun:azimuth=200,elevation=89.99"},  // narrowed
          {make_procedural("procedural:hairball,count=8,segments=12"), "sun:azimuth=30,elevation=50"},
          {test::rotated_terrain(), "sun:azimuth=120,elevation=20"},
          {test::all_open(test::hazard_town()), "sun:azimuth=30,elevation=50"},
          {closed_stack(), "sun:azimuth=150,elevation=35"},
          {closed_stack(), "sun:azimuth=20,elevation=70"},
          {closed_stack(), "sun:azimuth=250,elevation=8"}};
}

TEST(RasterSkip, ExactEqualsTheFullPathAndNarrowLiesInside) {
  const uint32_t L = fields::small_test_scale() ? 7 : 9, side = 1u << L;
  uint64_t skipped_closed = 0, narrowed_closed = 0;
  for (const SkipCase& c : cases()) {
    const LightSpace light = LightSpace::fit(LightSpec::parse(c.sun), c.scene.bounds());
    const TraceRegion all{L, 0, 0, side, side};
    const RasterBounds off(c.scene, light, RasterSkip::off), exact(c.scene, light, RasterSkip::exact),
        narrow(c.scene, light, RasterSkip::narrow);
    const IntervalTile truth = off.trace(all), e = exact.trace(all), n = narrow.trace(all);
    EXPECT_EQ(off.skipped_texels(), 0u);
    uint64_t narrowed = 0;
    for (size_t k = 0; k < truth.data.size(); ++k) {
      ASSERT_TRUE(same_bits(truth.data[k], e.data[k]))
          << c.scene.name << " " << c.sun << " texel " << k % side << "," << k / side;
      const Interval t = truth.data[k], v = n.data[k];
      ASSERT_TRUE(t.lo <= v.lo && v.lo <= v.hi && v.hi <= t.hi)
          << c.scene.name << " " << c.sun << " texel " << k % side << "," << k / side << ": narrow [" << v.lo
          << ", " << v.hi << "] true [" << t.lo << ", " << t.hi << "]";
      narrowed += !same_bits(t, v);
    }
    // Open geometry (hi = lo) is never narrowed.
    if (!exact.traces_exit_depths()) {
      EXPECT_EQ(narrowed, 0u) << c.scene.name;
    } else {
      skipped_closed += exact.skipped_texels(), narrowed_closed += narrowed;
    }
  }
  EXPECT_GT(skipped_closed, 0u) << "the skip never applied";
  EXPECT_GT(narrowed_closed, 0u) << "narrowing never applied";
}

// Builds case `c` at level L with the rasterizer's `skip`, checks that the pack records
// narrowed intervals and that every texel's value lies in its true interval (what
// `verify --all` checks); returns the build's report.
MapBuildReport build_and_check_lossless(const SkipCase& c, uint32_t L, uint32_t skip_level, Encoding enc,
                                        RasterSkip skip, const std::string& name) {
  const LightSpace light = LightSpace::fit(LightSpec::parse(c.sun), c.scene.bounds());
  MapBuildOptions o;
  o.map_level = L;
  o.skip_level = skip_level;
  o.encoding = enc;
  o.builder = BoundsBuilder::raster;
  o.raster_skip = skip;
  std::filesystem::create_directories(SHADOWTILE_TEST_TMP);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/" + name + ".pack";
  const MapBuildReport rep = build_map(c.scene, light, o, path);
  const IntervalTile truth =
      RasterBounds(c.scene, light, RasterSkip::off).trace(TraceRegion{L, 0, 0, 1u << L, 1u << L});
  std::shared_ptr<const PackReader> reader = PackReader::open(path);
  bool recorded = false;
  for (const auto& [key, v] : reader->params()) recorded |= key == "intervals_narrowed" && v == "yes";
  EXPECT_TRUE(recorded) << c.scene.name;
  PackEvaluator eval(reader);
  EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }), "")
      << c.scene.name << " " << c.sun;
  std::filesystem::remove(path);
  return rep;
}

// A pack built with --raster-skip narrow is lossless against the true intervals.
TEST(RasterSkip, NarrowedPackIsLosslessAgainstTheTrueIntervals) {
  const uint32_t L = fields::small_test_scale() ? 7 : 9;
  int k = 0;
  for (const SkipCase& c : cases())
    build_and_check_lossless(c, L, L - 4, Encoding::dagmh, RasterSkip::narrow, "raster_skip_" + std::to_string(k++));
}

// Every aligned square of every size (down to 4 texels) whose corners prove an interval:
// it lies inside the true interval of every texel of the square.
TEST(RasterSkip, ProvenRegionsLieInsideEveryTexelsInterval) {
  const uint32_t L = fields::small_test_scale() ? 7 : 8, side = 1u << L;
  uint64_t proven_closed = 0, proven_lit = 0;
  for (const SkipCase& c : cases()) {
    const LightSpace light = LightSpace::fit(LightSpec::parse(c.sun), c.scene.bounds());
    const RasterBounds off(c.scene, light, RasterSkip::off), regions(c.scene, light, RasterSkip::regions);
    const IntervalTile truth = off.trace(TraceRegion{L, 0, 0, side, side});
    for (uint32_t s = side; s >= 4; s /= 2)
      for (uint32_t y0 = 0; y0 < side; y0 += s)
        for (uint32_t x0 = 0; x0 < side; x0 += s) {
          const std::optional<Interval> iv = regions.region_interval(L, x0, y0, s);
          if (!iv) continue;
          (iv->lo == kLitDepth && iv->hi == kLitDepth ? proven_lit : proven_closed) += uint64_t(s) * s;
          for (uint32_t y = y0; y < y0 + s; ++y)
            for (uint32_t x = x0; x < x0 + s; ++x) {
              const Interval t = truth.at(x, y);
              ASSERT_TRUE(t.lo <= iv->lo && iv->lo <= iv->hi && iv->hi <= t.hi)
                  << c.scene.name << " " << c.sun << " region " << x0 << "," << y0 << " side " << s << " texel "
                  << x << "," << y << ": proven [" << iv->lo << ", " << iv->hi << "] true [" << t.lo << ", " << t.hi
                  << "]";
            }
        }
  }
  EXPECT_GT(proven_closed, 0u) << "no closed region was ever proven";
  EXPECT_GT(proven_lit, 0u) << "no empty region was ever proven";
  EXPECT_THROW(RasterBounds(cases()[0].scene,
                            LightSpace::fit(LightSpec::parse(cases()[0].sun), cases()[0].scene.bounds()))
                   .region_interval(4, 8, 0, 16),
               Error);
}

// A pack built top-down over proven regions (cells of 128^2 texels: regions split from
// 128 down to 64 before tracing) is lossless on every texel and records narrowed intervals.
TEST(RasterSkip, RegionsPackIsLosslessOnEveryTexel) {
  const uint32_t L = fields::small_test_scale() ? 8 : 9;
  int k = 0;
  uint64_t in_regions = 0;
  for (const SkipCase& c : cases()) {
    const MapBuildReport rep = build_and_check_lossless(c, L, L - 7, k % 2 ? Encoding::mh : Encoding::dagmh,
                                                        RasterSkip::regions, "raster_regions_" + std::to_string(k));
    ++k;
    in_regions += rep.texels_in_regions;
    EXPECT_EQ(rep.texels_in_regions + rep.texels_traced, uint64_t(1) << (2 * L)) << c.scene.name;
  }
  EXPECT_GT(in_regions, 0u) << "no region was ever proven during a build";
}

}  // namespace raster_skip_test
}  // namespace st

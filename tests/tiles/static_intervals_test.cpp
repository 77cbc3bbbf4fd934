// The static-geometry interval (voxel paper §6.1; TraceMode::static_bounds): where the
// first hit is open, hi reaches to just below the next surface along the texel ray (1 if
// none); lo never changes, closed first hits keep their exit depth, the result is as
// canonical as the default, and packs built with it are lossless under their contract
// and smaller on open scenes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>

#include "interval_fields.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/vsdag_format.hpp"

namespace st {
namespace {

namespace fs = std::filesystem;

bool same_float(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(StaticIntervals, ReachJustBelowTheNextSurface) {
  // An open plate over an open floor, seen from straight above (almost: 89.99 degrees).
  test::HazardBuilder b("plates");
  b.mesh("floor");
  b.quad({0, 0, 0}, {0, 0, 4}, {4, 0, 4}, {4, 0, 0});
  b.mesh("plate");
  b.quad({1, 1, 1}, {1, 1, 3}, {3, 1, 3}, {3, 1, 1});
  const Scene s = b.take();
  const LightSpace l = LightSpace::fit(LightSpec::parse("sun:azimuth=0,elevation=89.99"), s.bounds());
  DepthBoundsTracer tracer(s, l);
  const uint32_t L = 6, side = 1u << L;
  const IntervalTile d = tracer.trace({L, 0, 0, side, side});
  const IntervalTile sv = tracer.trace({L, 0, 0, side, side}, TraceMode::static_bounds);
  // Depths of the floor along each ray: a floor-only trace.
  test::HazardBuilder fb("floor");
  fb.mesh("floor");
  fb.quad({0, 0, 0}, {0, 0, 4}, {4, 0, 4}, {4, 0, 0});
  fb.mesh("marker");  // keeps the scene's bounds (and so the light box) the same
  fb.tri({1, 1, 1}, {1, 1, 1.0000001}, {1.0000001, 1, 1});
  const Scene floor_only = fb.take();
  ASSERT_EQ(floor_only.bounds().lo.y, s.bounds().lo.y);
  ASSERT_EQ(floor_only.bounds().hi.y, s.bounds().hi.y);
  DepthBoundsTracer ft(floor_only, l);
  const IntervalTile f = ft.trace({L, 0, 0, side, side});
  uint32_t on_plate = 0, on_floor = 0;
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      const Interval a = d.at(i, j), c = sv.at(i, j);
      ASSERT_TRUE(same_float(a.lo, c.lo)) << i << "," << j;
      ASSERT_EQ(a.lo, a.hi);
      if (a.lo == kLitDepth) continue;
      if (a.lo < f.at(i, j).lo) {  // the plate: just below the floor
        ++on_plate;
        ASSERT_EQ(c.hi, std::nextafter(f.at(i, j).lo, -INFINITY)) << i << "," << j;
      } else {  // the floor: nothing behind it
        ++on_floor;
        ASSERT_EQ(c.hi, kLitDepth) << i << "," << j;
      }
    }
  EXPECT_GT(on_plate, side * side / 8);
  EXPECT_GT(on_floor, side * side / 8);
}

TEST(StaticIntervals, ClosedFirstHitsKeepTheirExitDepth) {
  const Scene s = load_scene("procedural:city,size=2,seed=5");
  const LightSpace l = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  DepthBoundsTracer tracer(s, l);
  const uint32_t L = fields::small_test_scale() ? 7 : 8, side = 1u << L;
  const IntervalTile d = tracer.trace({L, 0, 0, side, side});
  const IntervalTile sv = tracer.trace({L, 0, 0, side, side}, TraceMode::static_bounds);
  uint32_t closed = 0;
  for (size_t k = 0; k < d.data.size(); ++k) {
    ASSERT_TRUE(same_float(d.data[k].lo, sv.data[k].lo));
    ASSERT_GE(sv.data[k].hi, d.data[k].hi);
    if (d.data[k].hi > d.data[k].lo) {
      ++closed;
      ASSERT_TRUE(same_float(d.data[k].hi, sv.data[k].hi));
    }
  }
  EXPECT_GT(closed, d.data.size() / 4);
}

TEST(StaticIntervals, BitIdenticalWhateverTheBatching) {
  const Scene s = test::hazard_town();
  const uint32_t L = fields::small_test_scale() ? 7 : 8, side = 1u << L;
  for (const char* spec : {"sun:azimuth=30,elevation=50", "sun:azimuth=77,elevation=0.5"}) {
    SCOPED_TRACE(spec);
    const LightSpace l = LightSpace::fit(LightSpec::parse(spec), s.bounds());
    DepthBoundsTracer tracer(s, l);
    const IntervalTile whole = tracer.trace({L, 0, 0, side, side}, TraceMode::static_bounds);
    for (PacketShape shape : {PacketShape::single, PacketShape::x4y4, PacketShape::x16y1}) {
      const IntervalTile t = tracer.trace({L, 0, 0, side, side}, TraceMode::static_bounds, nullptr,
                                          nullptr, shape);
      for (size_t k = 0; k < t.data.size(); ++k) {
        ASSERT_TRUE(same_float(whole.data[k].lo, t.data[k].lo)) << "shape " << int(shape) << " texel " << k;
        ASSERT_TRUE(same_float(whole.data[k].hi, t.data[k].hi)) << "shape " << int(shape) << " texel " << k;
      }
    }
    const IntervalTile part = tracer.trace({L, 3, 5, side - 9, 31}, TraceMode::static_bounds);
    for (uint32_t j = 0; j < part.height; ++j)
      for (uint32_t i = 0; i < part.width; ++i) {
        ASSERT_TRUE(same_float(part.at(i, j).lo, whole.at(i + 3, j + 5).lo));
        ASSERT_TRUE(same_float(part.at(i, j).hi, whole.at(i + 3, j + 5).hi));
      }
  }
}

TEST(StaticIntervals, PacksAreLosslessUnderTheirContractAndSmaller) {
  const Scene s = test::hazard_town();
  const LightSpace l = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  const uint32_t L = fields::small_test_scale() ? 8 : 10;
  fs::create_directories(SHADOWTILE_TEST_TMP);
  uint64_t bytes[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    MapBuildOptions o;
    o.map_level = L;
    o.encoding = Encoding::mh;
    o.skip_level = 4;
    o.intervals = k ? IntervalRule::static_geometry : IntervalRule::closed_objects;
    const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/static_" + std::to_string(k) + ".pack";
    const MapBuildReport r = build_map(s, l, o, path);
    bytes[k] = r.pack_bytes;
    std::shared_ptr<const PackReader> reader = PackReader::open(path);
    EXPECT_EQ((reader->header().flags & kFeatureStaticIntervals) != 0, k == 1);
    DepthBoundsTracer tracer(s, l);
    const IntervalTile truth = tracer.trace({L, 0, 0, 1u << L, 1u << L}, trace_mode_of(o.intervals));
    PackEvaluator eval(reader);
    EXPECT_EQ(fields::first_violation(truth, [&](uint32_t i, uint32_t j) { return eval.depth(L, i, j); }), "");
    fs::remove(path);
  }
  EXPECT_LT(bytes[1], bytes[0]) << "static intervals merge more on open geometry";
}

// The voxel shadow DAG on an open soup (procedural:soup: duplicate, sliver and
// overlapping faces) under both rules: every texel's depth keeps the slab contract
// (VSDAG.md) against that rule's intervals, and the static rule's undefined region
// behind open first hits makes the pack smaller.
TEST(StaticIntervals, VsdagPacksOnOpenSoupKeepTheirContractAndShrink) {
  const Scene s = load_scene("procedural:soup,count=60,size=120");
  ASSERT_EQ(s.closed_triangle_count(), 0u);
  const LightSpace l = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  const uint32_t L = fields::small_test_scale() ? 8 : 9, z = 12;
  fs::create_directories(SHADOWTILE_TEST_TMP);
  uint64_t bytes[2] = {0, 0};
  DepthBoundsTracer tracer(s, l);
  for (int k = 0; k < 2; ++k) {
    MapBuildOptions o;
    o.map_level = L;
    o.encoding = Encoding::vsdag;
    o.vsdag_z_bits = z;
    o.skip_level = 4;
    o.intervals = k ? IntervalRule::static_geometry : IntervalRule::closed_objects;
    const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/static_vsdag_" + std::to_string(k) + ".pack";
    bytes[k] = build_map(s, l, o, path).pack_bytes;
    PackEvaluator eval(std::shared_ptr<const PackReader>(PackReader::open(path)));
    const IntervalTile truth = tracer.trace({L, 0, 0, 1u << L, 1u << L}, trace_mode_of(o.intervals));
    uint64_t bad = 0, wider = 0, hits = 0;
    for (uint32_t j = 0; j < truth.height; ++j)
      for (uint32_t i = 0; i < truth.width; ++i) {
        const Interval& iv = truth.at(i, j);
        bad += !vsdag::depth_within_contract(iv.lo, iv.hi, eval.depth(L, i, j), z);
        wider += iv.hi > iv.lo;
        hits += iv.lo < kLitDepth;
      }
    EXPECT_EQ(bad, 0u) << (k ? "static" : "default") << " rule";
    if (k) EXPECT_GT(wider, hits * 9 / 10) << "the static rule opens most open first hits";
    else EXPECT_EQ(wider, 0u) << "open geometry has hi = lo";
    fs::remove(path);
  }
  EXPECT_LT(bytes[1], bytes[0]) << "static intervals need fewer voxels on open geometry";
}

}  // namespace
}  // namespace st

// Dual depth bounds against an independent double-precision reference (MH §3, voxel
// §6.1): analytic shapes, nested/intersecting/touching closed boxes, open geometry,
// grazing light, huge offsets, degenerate and inverted input, regions and level 20.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <thread>

#include "tests/tiles/depth_bounds_reference.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "common/error.hpp"

namespace st {
namespace {

using test::add_box;
using test::add_plane;
using test::add_sphere;
using test::compare_with_reference;
using test::kUlp;
using test::reference_ray;

uint32_t test_level(uint32_t full) { return test::small_scale() ? full - 2 : full; }

LightSpace sun(const Scene& s, double az, double el) {
  LightSpec spec;
  spec.azimuth_deg = az, spec.elevation_deg = el;
  return LightSpace::fit(spec, s.bounds());
}

IntervalTile trace_all(const Scene& s, const LightSpace& l, uint32_t level,
                       DepthBoundsStats* stats = nullptr) {
  DepthBoundsTracer tracer(s, l);
  return tracer.trace({level, 0, 0, 1u << level, 1u << level}, TraceMode::bounds, stats);
}

TEST(DepthBounds, CubeUnderStraightAndObliqueSunMatchesDoubleReference) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 1, 1});
  for (auto [az, el] : {std::pair{0.0, 90.0}, {30.0, 40.0}}) {
    LightSpace l = sun(s, az, el);
    DepthBoundsStats st;
    auto tile = trace_all(s, l, test_level(7), &st);
    auto c = compare_with_reference(s, l, tile);
    EXPECT_GT(c.closed, c.compared / 4) << "the cube should cover much of the map";
    EXPECT_EQ(st.texels, uint64_t(tile.width) * tile.height);
    EXPECT_EQ(st.fallbacks, 0u);
    EXPECT_GE(st.traversals, st.rays);
  }
}

TEST(DepthBounds, SphereUnderStraightAndObliqueSunMatchesDoubleReference) {
  Scene s;
  add_sphere(s, {0.5, 2, -1}, 1.5);
  for (auto [az, el] : {std::pair{0.0, 90.0}, {200.0, 25.0}}) {
    LightSpace l = sun(s, az, el);
    auto tile = trace_all(s, l, test_level(7));
    auto c = compare_with_reference(s, l, tile);
    EXPECT_GT(c.closed, c.compared / 4);
  }
}

TEST(DepthBounds, SpotLightMatchesDoubleReference) {
  Scene s;
  add_box(s, {-1, 0, -1}, {1, 1, 1});
  add_sphere(s, {0, 2, 0}, 0.5);
  LightSpec spec = LightSpec::parse("spot:pos=3,6,2,target=0,0.5,0,fov=50");
  LightSpace l = LightSpace::fit(spec, s.bounds());
  auto tile = trace_all(s, l, test_level(7));
  auto c = compare_with_reference(s, l, tile);
  EXPECT_GT(c.closed, 0u);
}

// Union of axis-aligned boxes along a straight-down ray, computed analytically.
TEST(DepthBounds, IntersectingNestedAndTouchingBoxesExitTheUnion) {
  Scene s;
  std::vector<std::pair<Vec3d, Vec3d>> boxes = {
      {{-1, -1, -1}, {1, 0, 1}},              // ground slab
      {{-0.5, 0, -0.5}, {0.5, 1, 0.5}},       // stands on the slab (coplanar faces)
      {{0.2, 0.5, 0.2}, {0.8, 1.5, 0.8}},     // intersects the previous one
      {{-0.8, -0.8, -0.8}, {-0.6, -0.2, -0.6}},  // nested inside the slab
      {{-0.9, 0.5, 0.6}, {-0.7, 0.7, 0.9}},   // floating: its exit is air
  };
  for (auto& [lo, hi] : boxes) add_box(s, lo, hi);
  LightSpace l = sun(s, 0, 90);
  const uint32_t level = test_level(7);
  auto tile = trace_all(s, l, level);
  uint64_t checked = 0, floating = 0, stacked = 0;
  for (uint32_t j = 0; j < tile.height; ++j)
    for (uint32_t i = 0; i < tile.width; ++i) {
      LightRay ray = l.texel_ray(level, i, j);
      const double x = ray.origin.x, z = ray.origin.z;
      std::vector<std::pair<double, double>> spans;  // (top, bottom)
      bool near_edge = false;
      for (auto& [lo, hi] : boxes) {
        if (std::fabs(x - lo.x) < 1e-6 || std::fabs(x - hi.x) < 1e-6 ||
            std::fabs(z - lo.z) < 1e-6 || std::fabs(z - hi.z) < 1e-6)
          near_edge = true;
        if (x > lo.x && x < hi.x && z > lo.z && z < hi.z) spans.push_back({hi.y, lo.y});
      }
      if (near_edge) continue;
      const Interval iv = tile.at(i, j);
      if (spans.empty()) {
        EXPECT_EQ(iv, (Interval{kLitDepth, kLitDepth}));
        continue;
      }
      std::sort(spans.begin(), spans.end(), std::greater<>());
      double top = spans[0].first, bottom = spans[0].second;
      for (size_t k = 1; k < spans.size() && spans[k].first >= bottom; ++k)
        bottom = std::min(bottom, spans[k].second);
      floating += bottom == 0.5;
      stacked += top == 1 && bottom == -1;
      double lo = l.to_light({x, top, z}).d, hi = l.to_light({x, bottom, z}).d;
      EXPECT_NEAR(iv.lo, lo, 16 * kUlp) << i << "," << j;
      EXPECT_NEAR(iv.hi, hi, 16 * kUlp) << i << "," << j;
      ++checked;
    }
  EXPECT_GT(checked, uint64_t(tile.width) * tile.height / 2);
  EXPECT_GT(floating, 0u);
  EXPECT_GT(stacked, 0u) << "rays through the touching faces must reach the slab bottom";
}

// A real gap thinner than the look-ahead window but far above float precision must not
// be bridged: hi stops at the upper box; with no gap, hi reaches the lower box's bottom.
TEST(DepthBounds, NearlyTouchingBoxesKeepARealGap) {
  for (double gap : {0.0, 1e-4, 1e-3}) {
    SCOPED_TRACE(gap);
    Scene s;
    add_box(s, {-1, -1, -1}, {1, 0, 1});
    add_box(s, {-0.5, gap, -0.5}, {0.5, 1 + gap, 0.5});
    LightSpace l = sun(s, 0, 90);
    const uint32_t level = test_level(6);
    auto tile = trace_all(s, l, level);
    uint64_t on_top = 0;
    for (uint32_t j = 0; j < tile.height; ++j)
      for (uint32_t i = 0; i < tile.width; ++i) {
        LightRay ray = l.texel_ray(level, i, j);
        const double x = ray.origin.x, z = ray.origin.z;
        if (!(std::fabs(x) < 0.49 && std::fabs(z) < 0.49)) continue;
        ++on_top;
        const double bottom = gap == 0 ? -1 : gap;
        EXPECT_NEAR(tile.at(i, j).hi, l.to_light({x, bottom, z}).d, 16 * kUlp) << i << "," << j;
        EXPECT_NEAR(tile.at(i, j).lo, l.to_light({x, 1 + gap, z}).d, 16 * kUlp) << i << "," << j;
      }
    EXPECT_GT(on_top, 0u);
  }
}

TEST(DepthBounds, OpenPlaneHasZeroWidthIntervals) {
  Scene s;
  add_plane(s, 0, 2);
  add_box(s, {-0.5, 0.5, -0.5}, {0.5, 1.5, 0.5});
  LightSpace l = sun(s, 20, 60);
  DepthBoundsTracer tracer(s, l);
  EXPECT_TRUE(tracer.traces_exit_depths());
  const uint32_t level = test_level(7);
  auto tile = tracer.trace({level, 0, 0, 1u << level, 1u << level});
  compare_with_reference(s, l, tile);
  uint64_t plane_texels = 0;
  for (uint32_t j = 0; j < tile.height; ++j)
    for (uint32_t i = 0; i < tile.width; ++i) {
      auto ref = reference_ray(s, l, l.texel_ray(level, i, j), 0);
      if (ref.hit && ref.hi == ref.lo) {
        EXPECT_EQ(tile.at(i, j).lo, tile.at(i, j).hi);
        ++plane_texels;
      }
    }
  EXPECT_GT(plane_texels, 0u);

  Scene open_only;
  add_plane(open_only, 0, 2);
  add_plane(open_only, 1, 1);
  LightSpace lo = sun(open_only, 10, 50);
  DepthBoundsTracer open_tracer(open_only, lo);
  EXPECT_FALSE(open_tracer.traces_exit_depths());
  DepthBoundsStats st;
  auto t2 = open_tracer.trace({level, 0, 0, 1u << level, 1u << level}, TraceMode::bounds, &st);
  for (auto& iv : t2.data) EXPECT_EQ(iv.lo, iv.hi);
  // One traversal of the whole ray gathers every candidate (canonical coverage).
  EXPECT_EQ(st.traversals, st.rays);
  compare_with_reference(open_only, lo, t2);
}

TEST(DepthBounds, GrazingSunKeepsLoBelowHiAndMatchesReference) {
  Scene s;
  add_box(s, {-2, -0.2, -2}, {2, 0, 2});
  add_box(s, {-0.5, 0, -0.5}, {0.5, 1, 0.5});
  add_sphere(s, {1, 0.4, 1}, 0.4);
  for (double el : {0.5, 2.0}) {
    LightSpace l = sun(s, 35, el);
    auto tile = trace_all(s, l, test_level(7));
    for (auto& iv : tile.data) ASSERT_LE(iv.lo, iv.hi);
    compare_with_reference(s, l, tile, 32);
  }
}

TEST(DepthBounds, OffsetAndScaledScenesGiveTheSameDepths) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 0, 1});
  add_sphere(s, {0.3, 0.6, 0.2}, 0.6);
  add_plane(s, 0.01, 1.5);
  const uint32_t level = test_level(6);
  LightSpace l = sun(s, 40, 55);
  auto base = trace_all(s, l, level);
  for (auto [scale, offset] : {std::pair{1.0, Vec3d{1e7, -3e6, 1e7}}, {1e-5, Vec3d{}},
                               {1e4, Vec3d{-2e5, 0, 0}}}) {
    Scene t = test::transformed(s, scale, offset);
    LightSpace lt = sun(t, 40, 55);
    auto moved = trace_all(t, lt, level);
    uint64_t differ = 0;
    for (size_t k = 0; k < base.data.size(); ++k) {
      const Interval a = base.data[k], b = moved.data[k];
      // Silhouette texels may flip between hit and miss; everything else agrees.
      if ((a.lo == kLitDepth) != (b.lo == kLitDepth) || (a.hi > a.lo) != (b.hi > b.lo)) {
        ++differ;
        continue;
      }
      EXPECT_NEAR(a.lo, b.lo, 8 * kUlp) << "scale " << scale << " texel " << k;
      EXPECT_NEAR(a.hi, b.hi, 8 * kUlp) << "scale " << scale << " texel " << k;
    }
    EXPECT_LT(differ, base.data.size() / 100 + 2) << "scale " << scale;
  }
}

TEST(DepthBounds, DegenerateTrianglesChangeNothing) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 1, 1});
  add_plane(s, -1.5, 2);
  LightSpace l = sun(s, 15, 70);
  const uint32_t level = test_level(6);
  auto clean = trace_all(s, l, level);
  Scene d = s;
  // Zero-area triangles inside the closed cube's range and in an open mesh of their own.
  d.vertices.push_back({0, 1, 0});
  d.vertices.push_back({0.5, 1, 0.5});
  d.vertices.push_back({1, 1, 1});  // collinear with the two above
  const uint32_t v = uint32_t(d.vertices.size()) - 3;
  d.triangles.insert(d.triangles.begin() + d.meshes[0].triangle_count,
                     {{v, v + 1, v + 2}, {v, v, v + 1}});
  d.meshes[0].triangle_count += 2;
  for (size_t m = 1; m < d.meshes.size(); ++m) d.meshes[m].first_triangle += 2;
  test::add_mesh(d, "degenerate", {{0, 0.5, 0}, {0, 0.5, 0}, {1, 0.5, 0}}, {{0, 1, 2}, {0, 0, 0}},
                 false);
  auto dirty = trace_all(d, l, level);
  EXPECT_EQ(clean.data, dirty.data);
}

TEST(DepthBounds, EmptySceneIsAllLit) {
  // Documented: a scene without triangles traces to the lit sentinel everywhere.
  Scene s;
  Aabb box;
  box.extend({-1, -1, -1});
  box.extend({1, 1, 1});
  LightSpec spec;
  LightSpace l = LightSpace::fit(spec, box);
  DepthBoundsTracer tracer(s, l);
  EXPECT_FALSE(tracer.traces_exit_depths());
  auto tile = tracer.trace({5, 0, 0, 32, 32});
  for (auto& iv : tile.data) EXPECT_EQ(iv, (Interval{kLitDepth, kLitDepth}));
}

TEST(DepthBounds, InvertedWindingNeverProducesNegativeCounterGarbage) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 1, 1}, true, /*invert=*/true);
  LightSpace l = sun(s, 30, 45);
  DepthBoundsStats st;
  auto tile = trace_all(s, l, test_level(6), &st);
  uint64_t hits = 0;
  for (uint32_t j = 0; j < tile.height; ++j)
    for (uint32_t i = 0; i < tile.width; ++i) {
      const Interval iv = tile.at(i, j);
      EXPECT_EQ(iv.lo, iv.hi);
      hits += iv.lo < kLitDepth;
    }
  EXPECT_GT(hits, 0u);
  EXPECT_GT(st.fallbacks, 0u);

  // Inverted box nested in a proper one: never extends hi past the outer exit.
  Scene n;
  add_box(n, {-1, -1, -1}, {1, 1, 1});
  add_box(n, {-0.5, -0.5, -0.5}, {0.5, 0.5, 0.5}, true, true);
  Scene outer;
  add_box(outer, {-1, -1, -1}, {1, 1, 1});
  LightSpace ln = sun(n, 30, 45);
  auto nested = trace_all(n, ln, test_level(6));
  auto plain = trace_all(outer, ln, test_level(6));
  for (size_t k = 0; k < nested.data.size(); ++k) {
    EXPECT_EQ(nested.data[k].lo, plain.data[k].lo);
    EXPECT_LE(nested.data[k].hi, plain.data[k].hi);
  }
}

TEST(DepthBounds, RegionEqualsTheSameTexelsOfAFullTrace) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 0, 1});
  add_sphere(s, {0, 0.5, 0}, 0.7);
  add_plane(s, 0.2, 1.2);
  LightSpace l = sun(s, 70, 35);
  const uint32_t level = test_level(7);
  DepthBoundsTracer tracer(s, l);
  auto full = tracer.trace({level, 0, 0, 1u << level, 1u << level});
  const uint32_t side = 1u << level;
  for (TraceRegion r : {TraceRegion{level, side / 8 + 1, side / 16 - 1, side / 4 + 5, 9},
                        TraceRegion{level, 1, 2, 3, 5},
                        TraceRegion{level, side - 17, side - 1, 17, 1}}) {
    auto part = tracer.trace(r);
    ASSERT_EQ(part.width, r.width);
    for (uint32_t j = 0; j < r.height; ++j)
      for (uint32_t i = 0; i < r.width; ++i)
        ASSERT_EQ(part.at(i, j), full.at(uint32_t(r.x0) + i, uint32_t(r.y0) + j))
            << "region texel " << i << "," << j;
  }
  // The plain first-hit mode gives the tracer's lo (not canonical: within a few ulps).
  auto first = tracer.trace({level, 0, 0, 1u << level, 1u << level}, TraceMode::first_hit);
  auto tracer_t = tracer.trace({level, 0, 0, 1u << level, 1u << level}, TraceMode::bounds_tracer_t);
  for (size_t k = 0; k < full.data.size(); ++k) {
    ASSERT_EQ(first.data[k].lo, tracer_t.data[k].lo);
    ASSERT_EQ(first.data[k].hi, first.data[k].lo);
    ASSERT_NEAR(first.data[k].lo, full.data[k].lo, 1e-6);
  }
}

TEST(DepthBounds, Level20RegionsAreAddressedExactly) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 1, 1});
  add_sphere(s, {0, 1, 0}, 0.8);
  LightSpace l = sun(s, 25, 65);
  DepthBoundsTracer tracer(s, l);
  const uint64_t mid = uint64_t(1) << 19, last = (uint64_t(1) << 20) - 40;
  for (auto [x0, y0] : {std::pair{mid - 20, mid - 20}, {last, last}, {0ul, mid}}) {
    auto tile = tracer.trace({20, x0, y0, 40, 40});
    compare_with_reference(s, l, tile);
  }
  // The centre texel of level 10 texel (x, y) is a corner at level 20; its four level-20
  // neighbours straddle it: the level-10 value lies within their lo range when the
  // surface is smooth there (the sphere top).
  auto coarse = tracer.trace({10, 512, 512, 1, 1});
  const uint64_t corner = (uint64_t(512) << 10) + (1 << 9);  // u = 512.5 / 1024
  auto fine = tracer.trace({20, corner - 1, corner - 1, 2, 2});
  float mn = 2, mx = -1;
  for (auto& iv : fine.data) mn = std::min(mn, iv.lo), mx = std::max(mx, iv.lo);
  EXPECT_GE(coarse.data[0].lo, mn - 4 * kUlp);
  EXPECT_LE(coarse.data[0].lo, mx + 4 * kUlp);
}

TEST(DepthBounds, ConcurrentCallsAgreeWithSerialOnes) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 0, 1});
  add_sphere(s, {0, 0.5, 0}, 0.7);
  LightSpace l = sun(s, 10, 50);
  DepthBoundsTracer tracer(s, l);
  const uint32_t level = test_level(7), half = 1u << (level - 1);
  TraceRegion a{level, 0, 0, 1u << level, half}, b{level, 0, half, 1u << level, half};
  auto sa = tracer.trace(a), sb = tracer.trace(b);
  IntervalTile ca, cb;
  std::thread ta([&] { ca = tracer.trace(a); }), tb([&] { cb = tracer.trace(b); });
  ta.join(), tb.join();
  EXPECT_EQ(sa.data, ca.data);
  EXPECT_EQ(sb.data, cb.data);
}

TEST(DepthBounds, RejectsBadRegionsAndBadScenes) {
  Scene s;
  add_box(s, {-1, -1, -1}, {1, 1, 1});
  LightSpace l = sun(s, 0, 60);
  DepthBoundsTracer tracer(s, l);
  EXPECT_THROW(tracer.trace({21, 0, 0, 1, 1}), Error);
  EXPECT_THROW(tracer.trace({4, 0, 0, 0, 1}), Error);
  EXPECT_THROW(tracer.trace({4, 10, 0, 7, 1}), Error);
  EXPECT_THROW(tracer.trace({4, 16, 0, 1, 1}), Error);
  EXPECT_THROW(tracer.trace({14, 0, 0, 16384, 16384}), Error);
  EXPECT_THROW(tracer.trace({20, (1ull << 20) - 1, 0, 2, 1}), Error);
  Scene bad = s;
  bad.vertices[3].y = NAN;
  EXPECT_THROW(DepthBoundsTracer(bad, l), Error);
  Scene bad_index = s;
  bad_index.triangles[0][1] = 1000;
  EXPECT_THROW(DepthBoundsTracer(bad_index, l), Error);
}

// Property: random boxes (overlapping, nested, stacked), random sun. Every texel has
// lo <= hi, matches the reference where unambiguous, and points between lo and hi lie
// inside some box (the lossless contract of the intervals).
TEST(DepthBounds, RandomBoxesKeepTheLosslessContract) {
  std::mt19937 rng(1234);
  std::uniform_real_distribution<double> pos(-1, 1), size(0.1, 0.8), ang(0, 360), elev(10, 89);
  const int scenes = test::small_scale() ? 2 : 6;
  for (int n = 0; n < scenes; ++n) {
    Scene s;
    std::vector<std::pair<Vec3d, Vec3d>> boxes;
    for (int b = 0; b < 8; ++b) {
      Vec3d c{pos(rng), pos(rng) * 0.5, pos(rng)}, h{size(rng), size(rng), size(rng)};
      if (b % 4 == 3 && !boxes.empty()) {  // stack on the previous box
        c.y = boxes.back().second.y + h.y;
        c.x = (boxes.back().first.x + boxes.back().second.x) / 2;
      }
      boxes.push_back({c - h, c + h});
      add_box(s, c - h, c + h);
    }
    add_plane(s, -1.2, 2);
    LightSpace l = sun(s, ang(rng), elev(rng));
    const uint32_t level = test_level(6);
    auto tile = trace_all(s, l, level);
    compare_with_reference(s, l, tile);
    uint64_t inside_checked = 0;
    for (uint32_t j = 0; j < tile.height; ++j)
      for (uint32_t i = 0; i < tile.width; ++i) {
        const Interval iv = tile.at(i, j);
        if (!(iv.hi > iv.lo)) continue;
        LightRay ray = l.texel_ray(level, i, j);
        for (double f : {0.01, 0.25, 0.5, 0.75, 0.99}) {
          double t = iv.lo + f * (iv.hi - iv.lo);
          Vec3d p = ray.origin + ray.dir * t;
          bool inside = false;
          for (auto& [lo, hi] : boxes)
            inside |= p.x >= lo.x - 1e-5 && p.x <= hi.x + 1e-5 && p.y >= lo.y - 1e-5 &&
                      p.y <= hi.y + 1e-5 && p.z >= lo.z - 1e-5 && p.z <= hi.z + 1e-5;
          EXPECT_TRUE(inside) << "scene " << n << " texel " << i << "," << j << " f " << f;
          ++inside_checked;
        }
      }
    EXPECT_GT(inside_checked, 0u);
  }
}

}  // namespace
}  // namespace st

// The canonical depth (tiles/bake/canonical_depth.hpp): the bounds of a texel are a
// function of (scene, light, level, x, y) alone. The same texels traced with every packet
// shape (single rays, 4, 8 and 16 lanes in rows or squares), and in regions of odd sizes
// and alignments, give bit-identical (lo, hi), on open and hazardous geometry under
// oblique, grazing, steep and spot lights.
#include <gtest/gtest.h>

#include <cstring>

#include "tests/tiles/depth_bounds_reference.hpp"
#include "tests/tiles/hazard_scenes.hpp"
#include "tiles/bake/canonical_depth.hpp"
#include "tiles/bake/depth_bounds.hpp"

namespace st {
namespace canonical_depth_test {

bool same_bits(const Interval& a, const Interval& b) {
  return std::memcmp(&a.lo, &b.lo, sizeof(float)) == 0 &&
         std::memcmp(&a.hi, &b.hi, sizeof(float)) == 0;
}

// The first texel where `part` (a sub-region) differs from `whole` at the same texel, or "".
std::string first_difference(const IntervalTile& whole, const IntervalTile& part) {
  for (uint32_t j = 0; j < part.height; ++j)
    for (uint32_t i = 0; i < part.width; ++i) {
      const Interval a = whole.at(uint32_t(part.x0 - whole.x0) + i, uint32_t(part.y0 - whole.y0) + j);
      const Interval b = part.at(i, j);
      if (!same_bits(a, b)) {
        char buf[200];
        std::snprintf(buf, sizeof buf, "texel (%llu, %llu): [%.9g, %.9g] vs [%.9g, %.9g]",
                      (unsigned long long)(part.x0 + i), (unsigned long long)(part.y0 + j), a.lo,
                      a.hi, b.lo, b.hi);
        return buf;
      }
    }
  return "";
}

struct SceneCase {
  std::string name;
  Scene scene;
};

std::vector<SceneCase> scenes() {
  std::vector<SceneCase> v;
  v.push_back({"hazards", test::hazard_town()});
  v.push_back({"rotated_terrain", test::rotated_terrain()});
  {
    test::HazardBuilder b("soup");
    test::add_soup(b, 99, 2000, {0, 0, 0}, 1.0);
    v.push_back({"soup", b.take()});
  }
  v.push_back({"open_terrain", test::all_open(load_scene("procedural:terrain,size=32"))});
  v.push_back({"open_city", test::all_open(load_scene("procedural:city,size=2,seed=5"))});
  v.push_back({"closed_city", load_scene("procedural:city,size=2,seed=5")});
  return v;
}

const char* const kLights[] = {
    "sun:azimuth=30,elevation=50",
    "sun:azimuth=77,elevation=0.5",     // grazing
    "sun:azimuth=200,elevation=89.99",  // steep
};

void expect_batch_independent(const Scene& scene, const LightSpace& light, uint32_t level) {
  DepthBoundsTracer tracer(scene, light);
  const uint32_t side = 1u << level;
  const IntervalTile whole = tracer.trace({level, 0, 0, side, side});
  uint64_t hits = 0;
  for (const Interval& iv : whole.data) hits += iv.lo < kLitDepth;
  EXPECT_GT(hits, uint64_t(side) * side / 20) << "the scene should cover the map";
  for (PacketShape shape : {PacketShape::single, PacketShape::x4y1, PacketShape::x8y1,
                            PacketShape::x4y4, PacketShape::x16y1}) {
    const IntervalTile t = tracer.trace({level, 0, 0, side, side}, TraceMode::bounds, nullptr,
                                        nullptr, shape);
    EXPECT_EQ(first_difference(whole, t), "") << "packet shape " << int(shape);
  }
  // Odd sizes and alignments: the same texels fall in other lanes and packets.
  const uint32_t regions[][4] = {{1, 1, side - 2, side - 3}, {3, 5, 37, 29},
                                 {side / 2 - 1, side / 3, 1, 1}, {side - 7, 2, 7, side - 2},
                                 {13, side / 2 + 1, side / 2 - 13, 3}};
  for (const auto& r : regions) {
    const IntervalTile t = tracer.trace({level, r[0], r[1], r[2], r[3]});
    EXPECT_EQ(first_difference(whole, t), "") << "region " << r[0] << "," << r[1] << " " << r[2]
                                              << "x" << r[3];
    const IntervalTile s = tracer.trace({level, r[0], r[1], r[2], r[3]}, TraceMode::bounds,
                                        nullptr, nullptr, PacketShape::single);
    EXPECT_EQ(first_difference(whole, s), "") << "single rays, region " << r[0] << "," << r[1];
  }
}

TEST(CanonicalDepth, BitIdenticalWhateverTheBatching) {
  const uint32_t level = test::small_scale() ? 7 : 8;
  for (SceneCase& c : scenes()) {
    for (const char* spec : kLights) {
      SCOPED_TRACE(c.name + " " + spec);
      expect_batch_independent(c.scene, LightSpace::fit(LightSpec::parse(spec), c.scene.bounds()),
                               level);
    }
  }
}

TEST(CanonicalDepth, BitIdenticalUnderSpotLights) {
  const uint32_t level = test::small_scale() ? 7 : 8;
  for (SceneCase& c : scenes()) {
    SCOPED_TRACE(c.name);
    const Aabb b = c.scene.bounds();
    const Vec3d ctr = b.center(), e = b.extent();
    LightSpec spec;
    spec.kind = LightKind::spot;
    spec.pos = ctr + Vec3d{0.3 * e.x, 1.5 * std::max({e.x, e.y, e.z}), -0.2 * e.z};
    spec.target = ctr;
    spec.fov_deg = 70;
    expect_batch_independent(c.scene, LightSpace::fit(spec, b), level);
  }
}

// The definition's plane does not depend on how a triangle is written: a duplicate,
// re-indexed, rotated or flipped copy has the bit-identical plane parameter.
TEST(CanonicalDepth, PlaneIgnoresVertexOrderAndWinding) {
  uint64_t rng = 5;
  for (int k = 0; k < 2000; ++k) {
    Vec3d p[3];
    for (Vec3d& q : p) q = {unit_random(rng) - 0.5, unit_random(rng) - 0.5, unit_random(rng) - 0.5};
    const Vec3d o{unit_random(rng), 2.0, unit_random(rng)}, d{0.1, -1.0, 0.05};
    const double t = CanonicalPlane::of(p[0], p[1], p[2]).t(o, d, -1);
    const int perm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
    for (const auto& q : perm) {
      const double u = CanonicalPlane::of(p[q[0]], p[q[1]], p[q[2]]).t(o, d, -1);
      ASSERT_EQ(std::memcmp(&t, &u, sizeof t), 0);
    }
  }
  // A ray in the plane falls back to the tracer's t.
  const CanonicalPlane flat = CanonicalPlane::of({0, 0, 0}, {1, 0, 0}, {0, 0, 1});
  EXPECT_EQ(flat.t({0, 0, 0}, {1, 0, 0}, 0.25), 0.25);
}

// The canonical depths stay within the double reference tracer's (tests/tiles) of the
// same scenes: canonical, and still the depths of the scene.
TEST(CanonicalDepth, AgreesWithTheDoubleReference) {
  const uint32_t level = 6;
  for (SceneCase& c : scenes()) {
    if (c.scene.triangles.size() > 3000) continue;  // the reference tests every triangle
    SCOPED_TRACE(c.name);
    const LightSpace l = LightSpace::fit(LightSpec::parse(kLights[0]), c.scene.bounds());
    DepthBoundsTracer tracer(c.scene, l);
    const IntervalTile t = tracer.trace({level, 0, 0, 1u << level, 1u << level});
    const auto r = test::compare_with_reference(c.scene, l, t, 16, test::small_scale() ? 8 : 2);
    EXPECT_GT(r.compared, 100u);
  }
}

}  // namespace canonical_depth_test
}  // namespace st

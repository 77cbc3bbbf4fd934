// Procedural scenes and the mesh rules every scene obeys (closedness from the triangles,
// orientation, degenerate removal, welding), independent of any file format.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <numbers>

#include "scene/scene.hpp"
#include "scene/scene_mesh.hpp"
#include "common/error.hpp"

namespace st {
namespace {

bool small_scale() {
  const char* s = std::getenv("SHADOWTILE_TEST_SCALE");
  return s && std::strcmp(s, "small") == 0;
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

// The scenes at test sizes: every generator, including its tessellation paths.
std::vector<std::string> closed_specs() {
  return {"procedural:cube",
          "procedural:cube,size=3",
          "procedural:sphere",
          "procedural:sphere,segments=3",
          "procedural:sphere,segments=7,radius=2",
          "procedural:boxes",
          "procedural:city,size=3",
          "procedural:city,size=4,seed=7",
          "procedural:terrain,size=16",
          "procedural:terrain,size=1",
          "procedural:hairball,count=8,segments=20",
          "procedural:hairball,count=3,segments=1,sides=3"};
}

TEST(ProceduralScene, ClosedScenesAreDetectedClosedAndOutwardFacing) {
  for (const auto& spec : closed_specs()) {
    SCOPED_TRACE(spec);
    Scene s = load_scene(spec);
    ASSERT_FALSE(s.meshes.empty());
    ASSERT_FALSE(s.triangles.empty());
    EXPECT_EQ(s.name, spec);
    // Generators must emit closed, outward, non-degenerate solids by construction: a
    // flip or a drop here is a generator bug that append_mesh would have hidden.
    EXPECT_EQ(s.stats.meshes_flipped, 0u);
    EXPECT_EQ(s.stats.degenerate_dropped, 0u);
    uint32_t next = 0;
    for (size_t i = 0; i < s.meshes.size(); ++i) {
      const Mesh& m = s.meshes[i];
      EXPECT_TRUE(m.closed) << m.name;
      EXPECT_EQ(m.first_triangle, next) << m.name;
      next += m.triangle_count;
      EXPECT_GT(mesh_signed_volume(s, i), 0.0) << m.name;
    }
    EXPECT_EQ(next, s.triangles.size());
    EXPECT_EQ(s.closed_triangle_count(), s.triangles.size());
    EXPECT_TRUE(s.any_closed());
  }
}

// Property over seeds and extreme keys: generators never emit an open, inverted or
// degenerate solid, whatever the random layout.
TEST(ProceduralScene, EverySeedGivesClosedOutwardSolids) {
  const int seeds = small_scale() ? 3 : 12;
  for (int seed = 1; seed <= seeds; ++seed)
    for (const std::string base : {"procedural:city,size=2", "procedural:city,size=2,block=30",
                                   "procedural:city,size=1,block=300", "procedural:hairball,count=6,segments=40",
                                   "procedural:terrain,size=6,height=0"}) {
      const std::string spec = base + ",seed=" + std::to_string(seed);
      SCOPED_TRACE(spec);
      const Scene s = load_scene(spec);
      EXPECT_EQ(s.closed_triangle_count(), s.triangles.size());
      EXPECT_EQ(s.stats.meshes_flipped, 0u);
      EXPECT_EQ(s.stats.degenerate_dropped, 0u);
    }
}

TEST(ProceduralScene, SameSpecSameHashOtherSeedOtherHash) {
  for (const std::string base : {"procedural:city,size=3", "procedural:terrain,size=12",
                                 "procedural:hairball,count=5,segments=10"}) {
    SCOPED_TRACE(base);
    const uint64_t h1 = load_scene(base).content_hash();
    EXPECT_EQ(h1, load_scene(base).content_hash());
    EXPECT_EQ(h1, load_scene(base + ",seed=1").content_hash());  // 1 is the default
    EXPECT_NE(h1, load_scene(base + ",seed=2").content_hash());
  }
  for (const std::string spec : {"procedural:cube", "procedural:sphere", "procedural:plane", "procedural:boxes"})
    EXPECT_EQ(load_scene(spec).content_hash(), load_scene(spec).content_hash()) << spec;
  EXPECT_NE(load_scene("procedural:cube").content_hash(), load_scene("procedural:cube,size=2").content_hash());
}

TEST(ProceduralScene, PlaneIsOpen) {
  Scene s = load_scene("procedural:plane,size=4");
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_FALSE(s.meshes[0].closed);
  EXPECT_EQ(s.triangles.size(), 2u);
  EXPECT_FALSE(s.any_closed());
  EXPECT_EQ(s.closed_triangle_count(), 0u);
  const Aabb b = s.bounds();
  EXPECT_EQ(b.lo, (Vec3d{-2, 0, -2}));
  EXPECT_EQ(b.hi, (Vec3d{2, 0, 2}));
  // Facing +Y.
  const auto& t = s.triangles[0];
  const Vec3d n = cross(s.vertices[t[1]] - s.vertices[t[0]], s.vertices[t[2]] - s.vertices[t[0]]);
  EXPECT_GT(n.y, 0);
}

// procedural:soup is one open mesh carrying the hazards of merged real assets.
TEST(ProceduralScene, SoupIsOpenWithDuplicateSliverAndOverlappingFaces) {
  const Scene s = load_scene("procedural:soup,count=40,size=100");
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_FALSE(s.any_closed());
  EXPECT_EQ(s.stats.degenerate_dropped, 0u);
  std::map<std::array<uint32_t, 3>, int> seen;
  size_t duplicates = 0, slivers = 0, patches = 0;
  for (const auto& t : s.triangles) {
    std::array<uint32_t, 3> k = t;
    std::sort(k.begin(), k.end());
    duplicates += seen[k]++ > 0;
    const Vec3d a = s.vertices[t[0]], b = s.vertices[t[1]], c = s.vertices[t[2]];
    const double area2 = length(cross(b - a, c - a));
    const double longest = std::max({length(b - a), length(c - b), length(a - c)});
    slivers += area2 / (longest * longest) < 1e-3;  // height under 0.1% of the longest edge
    patches += a.y == 5e-4 && b.y == 5e-4 && c.y == 5e-4;  // just above the ground quad
  }
  EXPECT_EQ(duplicates, 2u * 6 * 14) << "every third building's 6 roof faces twice more";
  EXPECT_GE(slivers, 40u);
  EXPECT_GT(patches, 0u);
  EXPECT_EQ(s.content_hash(), load_scene("procedural:soup,count=40,size=100").content_hash());
  EXPECT_NE(s.content_hash(), load_scene("procedural:soup,count=40,size=100,seed=2").content_hash());
  EXPECT_NE(error_of([] { load_scene("procedural:soup,leaves=3"); }).find("unknown key 'leaves'"), std::string::npos);
}

TEST(ProceduralScene, CubeGeometryAndVolume) {
  Scene s = load_scene("procedural:cube,size=2");
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_EQ(s.triangles.size(), 12u);
  EXPECT_EQ(s.vertices.size(), 8u);
  EXPECT_EQ(s.bounds().lo, (Vec3d{-1, -1, -1}));
  EXPECT_EQ(s.bounds().hi, (Vec3d{1, 1, 1}));
  EXPECT_DOUBLE_EQ(mesh_signed_volume(s, 0), 8.0);
}

TEST(ProceduralScene, SphereFollowsItsDocumentedGeometry) {
  const int segments = 12, stacks = 6;
  const double r = 2.5;
  Scene s = load_scene("procedural:sphere,radius=2.5,segments=12");
  EXPECT_EQ(s.triangles.size(), size_t(2 * segments * (stacks - 1)));
  EXPECT_EQ(s.vertices.size(), size_t(2 + segments * (stacks - 1)));
  for (auto& v : s.vertices) EXPECT_NEAR(length(v), r, 1e-12);
  // Every documented vertex is present.
  for (int j = 1; j < stacks; ++j)
    for (int i = 0; i < segments; ++i) {
      const double t = std::numbers::pi * j / stacks, p = 2 * std::numbers::pi * i / segments;
      const Vec3d want = Vec3d{std::sin(t) * std::cos(p), std::cos(t), std::sin(t) * std::sin(p)} * r;
      bool found = false;
      for (auto& v : s.vertices) found = found || v == want;
      EXPECT_TRUE(found) << j << "," << i;
    }
  const double vol = mesh_signed_volume(s, 0), ball = 4.0 / 3.0 * std::numbers::pi * r * r * r;
  EXPECT_LT(vol, ball);
  EXPECT_GT(vol, 0.8 * ball);
}

TEST(ProceduralScene, BoxesIntersectAndNest) {
  Scene s = load_scene("procedural:boxes");
  ASSERT_EQ(s.meshes.size(), 4u);
  auto box = [&](const char* name) {
    for (const Mesh& m : s.meshes)
      if (m.name == name) {
        Aabb b;
        for (uint32_t t = m.first_triangle; t < m.first_triangle + m.triangle_count; ++t)
          for (uint32_t v : s.triangles[t]) b.extend(s.vertices[v]);
        return b;
      }
    ADD_FAILURE() << "no mesh " << name;
    return Aabb{};
  };
  const Aabb a = box("box_a"), b = box("box_b"), outer = box("outer"), inner = box("inner");
  for (int k = 0; k < 3; ++k) {
    EXPECT_LT(a.lo[k], b.hi[k]);  // overlap on every axis = intersecting solids
    EXPECT_LT(b.lo[k], a.hi[k]);
    EXPECT_LT(outer.lo[k], inner.lo[k]);  // strictly nested
    EXPECT_LT(inner.hi[k], outer.hi[k]);
  }
}

TEST(ProceduralScene, ScaleAndOffsetAreAppliedInDouble) {
  Scene s = load_scene("procedural:cube,ox=1e7,oy=1e7,oz=1e7,scale=1e-5");
  ASSERT_EQ(s.triangles.size(), 12u);
  EXPECT_TRUE(s.meshes[0].closed);
  EXPECT_EQ(s.stats.degenerate_dropped, 0u);
  const double lo = -0.5 * 1e-5 + 1e7, hi = 0.5 * 1e-5 + 1e7;
  EXPECT_EQ(s.bounds().lo, (Vec3d{lo, lo, lo}));
  EXPECT_EQ(s.bounds().hi, (Vec3d{hi, hi, hi}));
  EXPECT_NEAR(mesh_signed_volume(s, 0), (hi - lo) * (hi - lo) * (hi - lo), 1e-18);

  Scene t = load_scene("procedural:boxes,scale=2,ox=-1,oy=10,oz=0.5");
  Scene u = load_scene("procedural:boxes");
  ASSERT_EQ(t.vertices.size(), u.vertices.size());
  for (size_t i = 0; i < t.vertices.size(); ++i) EXPECT_EQ(t.vertices[i], (u.vertices[i] * 2 + Vec3d{-1, 10, 0.5}));
}

TEST(ProceduralScene, BadSpecsGiveClearErrors) {
  auto expect_error = [](const std::string& spec, const std::string& needle) {
    const std::string msg = error_of([&] { load_scene(spec); });
    EXPECT_NE(msg.find(needle), std::string::npos) << spec << " -> " << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  };
  expect_error("procedural:teapot", "unknown name 'teapot'");
  expect_error("procedural:", "missing scene name");
  expect_error("procedural:cube,colour=red", "unknown key 'colour'");
  expect_error("procedural:city,sides=3", "unknown key 'sides'");
  expect_error("procedural:cube,size=abc", "key 'size'");
  expect_error("procedural:cube,size=-1", "key 'size'");
  expect_error("procedural:cube,size=0", "key 'size'");
  expect_error("procedural:cube,size=nan", "key 'size'");
  expect_error("procedural:cube,size=1x", "key 'size'");
  expect_error("procedural:sphere,segments=2", "key 'segments'");
  expect_error("procedural:sphere,segments=7.5", "key 'segments'");
  expect_error("procedural:city,seed=-3", "key 'seed'");
  expect_error("procedural:cube,size=1,size=2", "given twice");
  expect_error("procedural:cube,size", "expected key=value");
  expect_error("procedural:cube,=3", "expected key=value");
  expect_error("procedural:cube,scale=0", "key 'scale'");
  expect_error("procedural:cube,ox=inf", "key 'ox'");
  // make_procedural takes the spec with or without the prefix.
  EXPECT_EQ(make_procedural("cube,size=2").content_hash(), load_scene("procedural:cube,size=2").content_hash());
}

// The default city is the benchmark scene: a few hundred thousand triangles, all closed,
// generated in well under a second (release build).
TEST(ProceduralScene, DefaultCitySizeAndTime) {
  const std::string spec = small_scale() ? "procedural:city,size=5" : "procedural:city";
  const auto t0 = std::chrono::steady_clock::now();
  Scene s = load_scene(spec);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%s\n  generated in %.3f s\n", summary(s).c_str(), seconds);
  EXPECT_EQ(s.closed_triangle_count(), s.triangles.size());
  EXPECT_EQ(s.stats.meshes_flipped, 0u);
  if (!small_scale()) {
    EXPECT_GE(s.triangles.size(), 200000u);
    EXPECT_LE(s.triangles.size(), 800000u);
  }
  // Every kind of building appears (courtyards, towers, L-shapes, bridges, ...).
  for (const char* kind : {"ground", "building", "lshape", "tower", "courtyard", "bridge", "canopy", "wall"}) {
    if (small_scale()) break;
    bool found = false;
    for (auto& m : s.meshes) found = found || m.name.rfind(kind, 0) == 0;
    EXPECT_TRUE(found) << kind;
  }
}

TEST(ProceduralScene, SummaryNamesTheCounts) {
  Scene s = load_scene("procedural:boxes");
  const std::string text = summary(s);
  EXPECT_NE(text.find("48 triangles"), std::string::npos) << text;
  EXPECT_NE(text.find("4 meshes (4 closed"), std::string::npos) << text;
  EXPECT_NE(text.find("0 degenerate"), std::string::npos) << text;
  EXPECT_NE(text.find("bounds [-3, 0, -2] - [5, 4, 2]"), std::string::npos) << text;
  EXPECT_EQ(text.find('\n'), std::string::npos);
  EXPECT_NE(summary(Scene{}).find("empty bounds"), std::string::npos);
}

}  // namespace
}  // namespace st

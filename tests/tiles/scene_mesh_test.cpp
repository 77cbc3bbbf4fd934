// append_mesh(): the rules every loaded or generated mesh goes through.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "scene/scene.hpp"
#include "scene/scene_mesh.hpp"
#include "common/error.hpp"

namespace st {
namespace {

// Unit cube [0,1]^3, outward, 8 shared vertices.
MeshSoup cube(const std::string& name = "cube", Vec3d at = {}) {
  MeshSoup m{name, {}, {}};
  for (int i = 0; i < 8; ++i) m.vertices.push_back(at + Vec3d{double(i & 1), double(i >> 1 & 1), double(i >> 2 & 1)});
  // Faces as quads (outward, counter-clockwise seen from outside).
  const int quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (auto& q : quads) {
    m.triangles.push_back({uint32_t(q[0]), uint32_t(q[1]), uint32_t(q[2])});
    m.triangles.push_back({uint32_t(q[0]), uint32_t(q[2]), uint32_t(q[3])});
  }
  return m;
}

// The same cube with every triangle owning its own three vertices (as OBJ/glTF deliver
// when normals split vertices).
MeshSoup split(const MeshSoup& in) {
  MeshSoup out{in.name, {}, {}};
  for (auto& t : in.triangles) {
    const uint32_t b = static_cast<uint32_t>(out.vertices.size());
    for (uint32_t v : t) out.vertices.push_back(in.vertices[v]);
    out.triangles.push_back({b, b + 1, b + 2});
  }
  return out;
}

Scene scene_of(std::vector<MeshSoup> meshes) {
  Scene s;
  s.name = "test";
  for (auto& m : meshes) append_mesh(s, std::move(m));
  return s;
}

TEST(SceneMesh, CubeIsClosedWithUnitVolume) {
  Scene s = scene_of({cube()});
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_TRUE(s.meshes[0].closed);
  EXPECT_EQ(s.stats.meshes_flipped, 0u);
  EXPECT_DOUBLE_EQ(mesh_signed_volume(s, 0), 1.0);
}

TEST(SceneMesh, InvertedCubeIsFlippedOutwards) {
  MeshSoup m = cube();
  for (auto& t : m.triangles) std::swap(t[0], t[1]);
  EXPECT_DOUBLE_EQ(signed_volume(m.vertices, m.triangles), -1.0);
  Scene s = scene_of({cube("a"), m});
  EXPECT_TRUE(s.meshes[1].closed);
  EXPECT_EQ(s.stats.meshes_flipped, 1u);
  EXPECT_DOUBLE_EQ(mesh_signed_volume(s, 1), 1.0);
  EXPECT_DOUBLE_EQ(mesh_signed_volume(s, 0), 1.0);
}

TEST(SceneMesh, SplitVerticesAreWeldedBeforeTheClosednessTest) {
  MeshSoup m = split(cube());
  EXPECT_EQ(m.vertices.size(), 36u);
  EXPECT_FALSE(is_closed_surface(m.triangles));
  // -0.0 and +0.0 are the same position.
  for (auto& v : m.vertices)
    if (v.x == 0) v.x = -0.0;
  m.vertices[0].x = 0.0;
  Scene s = scene_of({m});
  EXPECT_EQ(s.vertices.size(), 8u);
  EXPECT_TRUE(s.meshes[0].closed);
  EXPECT_EQ(s.triangles.size(), 12u);
}

TEST(SceneMesh, WeldingIsPerMesh) {
  // Two cubes sharing a face position stay two closed meshes with their own vertices.
  Scene s = scene_of({cube("a"), cube("b", {1, 0, 0})});
  EXPECT_EQ(s.vertices.size(), 16u);
  EXPECT_TRUE(s.meshes[0].closed);
  EXPECT_TRUE(s.meshes[1].closed);
}

TEST(SceneMesh, SeveralClosedComponentsAreClosed) {
  MeshSoup a = cube("pair"), b = cube("x", {3, 0, 0});
  const uint32_t base = static_cast<uint32_t>(a.vertices.size());
  a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (auto t : b.triangles) a.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  Scene s = scene_of({a});
  EXPECT_TRUE(s.meshes[0].closed);
  EXPECT_DOUBLE_EQ(mesh_signed_volume(s, 0), 2.0);
}

TEST(SceneMesh, OpenInconsistentAndNonManifoldMeshesAreNotClosed) {
  MeshSoup open = cube("open");
  open.triangles.resize(10);  // one face missing: boundary edges
  MeshSoup flipped_face = cube("inconsistent");
  std::swap(flipped_face.triangles[0][1], flipped_face.triangles[0][2]);
  std::swap(flipped_face.triangles[1][1], flipped_face.triangles[1][2]);
  MeshSoup fin = cube("fin");  // a third face on an edge of the cube (0-4)
  fin.vertices.push_back({-1, 0, 0});
  fin.triangles.push_back({0, 4, 8});
  fin.triangles.push_back({4, 0, 8});  // also closes the fin's own edges both ways
  MeshSoup doubled = cube("doubled");  // every triangle twice
  auto copy = doubled.triangles;
  doubled.triangles.insert(doubled.triangles.end(), copy.begin(), copy.end());
  Scene s = scene_of({open, flipped_face, fin, doubled});
  for (auto& m : s.meshes) EXPECT_FALSE(m.closed) << m.name;
  // An open mesh's winding is never touched.
  EXPECT_EQ(s.stats.meshes_flipped, 0u);
  EXPECT_FALSE(is_closed_surface({}));
}

TEST(SceneMesh, DegenerateTrianglesAreDroppedAndCounted) {
  MeshSoup m = cube("with_degenerates");
  m.vertices.push_back({0.5, 0.5, 0.5});
  m.vertices.push_back({1.5, 1.5, 1.5});
  m.vertices.push_back({2.5, 2.5, 2.5});
  m.vertices.push_back({0, 0, 0});                 // duplicate of vertex 0: welds onto it
  m.triangles.push_back({0, 0, 1});                // repeated index
  m.triangles.push_back({8, 9, 10});               // collinear: zero area in double
  m.triangles.push_back({0, 11, 3});               // repeated after welding
  m.triangles.push_back({3, 3, 3});                // all three equal
  Scene s = scene_of({m});
  EXPECT_EQ(s.stats.degenerate_dropped, 4u);
  EXPECT_EQ(s.triangles.size(), 12u);
  EXPECT_TRUE(s.meshes[0].closed);
  // Unreferenced vertices are not kept.
  EXPECT_EQ(s.vertices.size(), 8u);
  // A sliver that is tiny but not zero stays.
  MeshSoup sliver{"sliver", {{0, 0, 0}, {1, 0, 0}, {0.5, 1e-300, 0}}, {{0, 1, 2}}};
  Scene t = scene_of({sliver});
  EXPECT_EQ(t.stats.degenerate_dropped, 0u);
  EXPECT_EQ(t.triangles.size(), 1u);
}

TEST(SceneMesh, NonFiniteVertexNamesTheMesh) {
  for (double bad : {std::nan(""), double(INFINITY), -double(INFINITY)}) {
    MeshSoup m = cube("lamp_post_3");
    m.vertices[5].y = bad;
    try {
      scene_of({m});
      ADD_FAILURE() << "no error for " << bad;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("lamp_post_3"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("non-finite"), std::string::npos) << e.what();
    }
  }
  // An unreferenced NaN vertex is harmless and dropped.
  MeshSoup m = cube("ok");
  m.vertices.push_back({NAN, 0, 0});
  EXPECT_EQ(scene_of({m}).vertices.size(), 8u);
}

TEST(SceneMesh, IndexPastTheVerticesNamesTheMesh) {
  MeshSoup m = cube("bad_index");
  m.triangles.push_back({0, 1, 8});
  try {
    scene_of({m});
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad_index"), std::string::npos) << e.what();
  }
}

TEST(SceneMesh, EmptyMeshesAndScenes) {
  Scene s = scene_of({MeshSoup{"nothing", {}, {}}, MeshSoup{"points_only", {{1, 2, 3}}, {}}});
  ASSERT_EQ(s.meshes.size(), 2u);
  for (auto& m : s.meshes) {
    EXPECT_EQ(m.triangle_count, 0u);
    EXPECT_FALSE(m.closed);
  }
  EXPECT_TRUE(s.triangles.empty());
  EXPECT_TRUE(s.vertices.empty());
  EXPECT_TRUE(s.bounds().empty());
  EXPECT_FALSE(s.any_closed());
  EXPECT_EQ(Scene{}.content_hash(), Scene{}.content_hash());
  // A mesh whose only triangle is degenerate ends up empty and open.
  Scene d = scene_of({MeshSoup{"flat", {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}, {{0, 1, 2}}}});
  EXPECT_EQ(d.stats.degenerate_dropped, 1u);
  EXPECT_EQ(d.meshes[0].triangle_count, 0u);
}

TEST(SceneMesh, VolumeStaysAccurateFarFromTheOrigin) {
  MeshSoup m = cube("far");
  for (auto& v : m.vertices) v = v * 1e-3 + Vec3d{1e8, -1e8, 1e8};
  // 1e-3 at 1e8 is ~67k ulps: the volume survives because it is taken about the centroid.
  EXPECT_NEAR(signed_volume(m.vertices, m.triangles), 1e-9, 1e-12);
}

}  // namespace
}  // namespace st

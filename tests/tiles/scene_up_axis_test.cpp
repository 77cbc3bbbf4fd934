// Up axes a user does not have to know: a file whose format fixes or records its up axis
// loads upright without SceneOptions::up (FBX GlobalSettings metadata, COLLADA
// <up_axis>; Quake 3 maps in scene_quake3_test.cpp), a given axis overrides the file's,
// and the scene says which axis it used and why. Files are written by assimp's own
// exporters and then given another axis by editing their text.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "common/error.hpp"
#include "scene/scene.hpp"
#include "scene/scene_mesh.hpp"
#include "tests/tiles/scene_export.hpp"

namespace st {
namespace scene_up_axis_test {

std::string tmp(const std::string& name) {
  std::filesystem::create_directories(SHADOWTILE_TEST_TMP);
  return std::string(SHADOWTILE_TEST_TMP) + "/scene_up_axis_" + name;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  ASSERT_TRUE(out.good()) << path;
}

// A closed 1 x 2 x 10 box, tall along +Z: as a Z-up tool writes a tower.
Scene z_up_tower() {
  MeshSoup box{"tower", {}, {}};
  for (int i = 0; i < 8; ++i) box.vertices.push_back({double(i & 1), 2.0 * (i >> 1 & 1), 10.0 * (i >> 2 & 1)});
  box.triangles = {{0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}, {0, 1, 5}, {0, 5, 4},
                   {2, 6, 7}, {2, 7, 3}, {0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}};
  Scene s;
  append_mesh(s, std::move(box));
  return s;
}

// Upright: (x, y, z) -> (x, z, -y), the tower's height along +Y.
const Aabb kUpright{{0, 0, -2}, {1, 10, 0}};
const Aabb kAsWritten{{0, 0, 0}, {1, 2, 10}};

void expect_bounds(const Scene& s, const Aabb& want) {
  const Aabb b = s.bounds();
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(b.lo[k], want.lo[k], 1e-5) << "axis " << k << ", scene " << s.name;
    EXPECT_NEAR(b.hi[k], want.hi[k], 1e-5) << "axis " << k << ", scene " << s.name;
  }
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_TRUE(s.meshes[0].closed);
  EXPECT_NEAR(mesh_signed_volume(s, 0), 20.0, 1e-4);  // a rotation: still outwards
}

// Replaces the value after `key` up to the end of its line (ASCII FBX: `P: "UpAxis",
// "int", "Integer", "",1`) or up to `end` (XML).
std::string with_value(std::string text, const std::string& key, const std::string& end, const std::string& value) {
  const size_t at = text.find(key);
  EXPECT_NE(at, std::string::npos) << key;
  if (at == std::string::npos) return text;
  size_t from = at + key.size(), to = text.find(end, from);
  if (end == "\n") {
    while (to > from && (text[to - 1] == '\r' || text[to - 1] == ' ')) --to;
    from = text.rfind(',', to) + 1;
  }
  return text.replace(from, to - from, value);
}

TEST(SceneUpAxis, FbxUpAxisMetadataTurnsTheFileUnlessGiven) {
  const std::string written = tmp("tower_y.fbx");
  write_scene(z_up_tower(), written, "fbxa");
  const std::string y_text = read_text(written);
  // assimp's exporter records +Y up: read as written, and the scene says why.
  const Scene as_y = load_scene(written);
  expect_bounds(as_y, kAsWritten);
  EXPECT_EQ(up_axis_text(as_y), "y (from the file's metadata)");

  const std::string z_path = tmp("tower_z.fbx");
  write_text(z_path, with_value(y_text, "\"UpAxis\"", "\n", "2"));
  const Scene upright = load_scene(z_path);
  expect_bounds(upright, kUpright);
  EXPECT_EQ(upright.up, UpAxis::z);
  EXPECT_EQ(up_axis_text(upright), "z (from the file's metadata)");
  EXPECT_NE(summary(upright).find("up axis z (from the file's metadata)"), std::string::npos) << summary(upright);
  // A given axis overrides the metadata.
  const Scene given = load_scene(z_path, SceneOptions{UpAxis::y});
  expect_bounds(given, kAsWritten);
  EXPECT_EQ(up_axis_text(given), "y (given)");

  // An axis we do not turn (X up) is read as y and the reason says so.
  const std::string x_path = tmp("tower_x.fbx");
  write_text(x_path, with_value(y_text, "\"UpAxis\"", "\n", "0"));
  const Scene x = load_scene(x_path);
  expect_bounds(x, kAsWritten);
  EXPECT_NE(x.up_reason.find("+X"), std::string::npos) << x.up_reason;
  EXPECT_NE(x.up_reason.find("--up"), std::string::npos) << x.up_reason;
}

TEST(SceneUpAxis, ColladaUpAxisIsAppliedOnceAndAGivenAxisOverridesIt) {
  const std::string written = tmp("tower_y.dae");
  write_scene(z_up_tower(), written, "collada");
  const std::string y_text = read_text(written);
  ASSERT_NE(y_text.find("<up_axis>Y_UP</up_axis>"), std::string::npos);
  EXPECT_EQ(up_axis_text(load_scene(written)), "y (from the file's <up_axis>)");

  const std::string z_path = tmp("tower_z.dae");
  write_text(z_path, with_value(y_text, "<up_axis>", "</up_axis>", "Z_UP"));
  const Scene upright = load_scene(z_path);  // turned by assimp, not a second time by us
  expect_bounds(upright, kUpright);
  EXPECT_EQ(up_axis_text(upright), "z (from the file's <up_axis>, turned by assimp)");
  // Given axes replace the file's: y reads it as written, z turns it once.
  expect_bounds(load_scene(z_path, SceneOptions{UpAxis::y}), kAsWritten);
  expect_bounds(load_scene(z_path, SceneOptions{UpAxis::z}), kUpright);
  expect_bounds(load_scene(written, SceneOptions{UpAxis::z}), kUpright);
}

TEST(SceneUpAxis, FormatsWithoutAnAxisReadYAndProceduralScenesSayNothing) {
  const std::string obj = tmp("tower.obj");
  write_scene(z_up_tower(), obj, "obj");
  const Scene s = load_scene(obj);
  expect_bounds(s, kAsWritten);
  EXPECT_EQ(up_axis_text(s), "y (the file records none)");
  expect_bounds(load_scene(obj, SceneOptions{UpAxis::z}), kUpright);
  const Scene city = load_scene("procedural:cube");
  EXPECT_TRUE(city.up_reason.empty());
  EXPECT_EQ(summary(city).find("up axis"), std::string::npos);
  EXPECT_EQ(parse_up_axis(""), std::nullopt);
  EXPECT_EQ(parse_up_axis("z"), UpAxis::z);
  EXPECT_THROW(parse_up_axis("x"), Error);
}

}  // namespace scene_up_axis_test
}  // namespace st

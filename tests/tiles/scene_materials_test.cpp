// Partial occluders from scene files' materials (scene_materials.hpp): OBJ/MTL opacity
// (d, Tr), transmission colour (Tf) and opacity maps (map_d, a PNG written here), glTF
// alphaMode OPAQUE/MASK/BLEND with alphaCutoff, opaque materials leaving a scene exactly
// as before, and one clear error for a texture format we do not read.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/error.hpp"
#include "image/png_io.hpp"
#include "scene/scene.hpp"

namespace st {
namespace {

std::string dir_of(const std::string& name) {
  const std::string d = std::string(SHADOWTILE_TEST_TMP) + "/" + name;
  std::filesystem::create_directories(d + "/tex");
  return d;
}

void write_text(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

// 8 x 8, grey 200: the top four rows (v > 0.5 in assimp's convention) solid, the rest clear.
void write_leaf_png(const std::string& path) {
  std::vector<uint8_t> ga;
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x) ga.insert(ga.end(), {200, uint8_t(y < 4 ? 255 : 0)});
  write_png_grey_alpha(path, 8, 8, ga);
}

// One unit quad per material at heights 1, 2, ... above a ground quad (no material).
std::string quads_obj(const std::vector<std::string>& materials, const std::string& mtllib) {
  std::string s = mtllib.empty() ? "" : "mtllib " + mtllib + "\n";
  s += "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n";
  s += "v -3 0 -3\nv -3 0 3\nv 3 0 3\nv 3 0 -3\nf 1 2 3 4\n";
  for (size_t i = 0; i < materials.size(); ++i) {
    const std::string y = std::to_string(i + 1);
    s += "v -1 " + y + " -1\nv 1 " + y + " -1\nv 1 " + y + " 1\nv -1 " + y + " 1\n";
    const size_t b = 5 + 4 * i;
    s += "usemtl " + materials[i] + "\n";
    s += "f " + std::to_string(b) + "/1 " + std::to_string(b + 3) + "/4 " + std::to_string(b + 2) + "/3 " +
         std::to_string(b + 1) + "/2\n";
  }
  return s;
}

const Mesh& mesh_at_height(const Scene& s, int y) {
  for (const Mesh& m : s.meshes)
    if (m.triangle_count && s.vertices[s.triangles[m.first_triangle][0]].y == y) return m;
  throw Error("no mesh at height " + std::to_string(y));
}

TEST(SceneMaterials, ObjOpacityTransmissionColourAndOpacityMap) {
  const std::string d = dir_of("mtl_obj");
  write_leaf_png(d + "/tex/leaf.png");
  write_text(d + "/m.mtl",
             "newmtl glass\nd 0.25\nTf 1 0.5 0.25\n"
             "newmtl tr\nTr 0.4\n"
             "newmtl leaf\nmap_d tex\\leaf.png\n"  // a Windows separator, read as '/'
             "newmtl plain\nKd 1 1 1\n");
  write_text(d + "/m.obj", quads_obj({"glass", "tr", "leaf", "plain"}, "m.mtl"));
  const Scene s = load_scene(d + "/m.obj");
  const Mesh &glass = mesh_at_height(s, 1), &tr = mesh_at_height(s, 2), &leaf = mesh_at_height(s, 3);
  EXPECT_EQ(glass.transmit, (Rgb{0.75f, 0.375f, 0.1875f}));  // (1 - d) x Tf / max(Tf)
  EXPECT_EQ(glass.alpha_texture, -1);
  EXPECT_NEAR(tr.transmit[0], 0.4f, 1e-6f);  // Tr is 1 - d
  EXPECT_EQ(tr.transmit[0], tr.transmit[2]);
  EXPECT_FALSE(mesh_at_height(s, 4).partial());
  EXPECT_FALSE(mesh_at_height(s, 0).partial());  // the ground: no material
  // The opacity map: opaque where solid (d = 1), rows flipped so v = 1 is the image's top.
  EXPECT_EQ(leaf.transmit, (Rgb{0, 0, 0}));
  ASSERT_EQ(leaf.alpha_texture, 0);
  ASSERT_EQ(s.alpha_textures.size(), 1u);
  const AlphaTexture& t = s.alpha_textures[0];
  EXPECT_NE(t.name.find("leaf.png"), std::string::npos);
  EXPECT_TRUE(t.solid(0.5f, 0.9f));
  EXPECT_FALSE(t.solid(0.5f, 0.1f));
  // UVs carried per corner: the leaf's first triangle is the file's (0,0) (0,1) (1,1).
  ASSERT_EQ(s.triangle_uv.size(), s.triangles.size());
  const auto& uv = s.triangle_uv[leaf.first_triangle];
  for (int k = 0; k < 3; ++k) {
    const Vec3d& p = s.vertices[s.triangles[leaf.first_triangle][k]];
    EXPECT_EQ(uv[k], (Vec2f{float((p.x + 1) / 2), float((p.z + 1) / 2)})) << k;
  }
  const Scene o = opaque_part(s);
  EXPECT_EQ(o.meshes.size(), 2u);
  EXPECT_FALSE(o.any_partial());
}

TEST(SceneMaterials, OpaqueMaterialsLeaveTheSceneAsItWas) {
  const std::string d = dir_of("mtl_opaque");
  write_text(d + "/o.mtl", "newmtl a\nd 1\nTf 0.5 0.5 0.5\nnewmtl b\nKd 1 0 0\nTr 0\n");
  write_text(d + "/o.obj", quads_obj({"a", "b"}, "o.mtl"));
  write_text(d + "/bare.mtl", "newmtl a\nnewmtl b\n");  // materials that say nothing
  write_text(d + "/bare.obj", quads_obj({"a", "b"}, "bare.mtl"));
  const Scene s = load_scene(d + "/o.obj"), bare = load_scene(d + "/bare.obj");
  EXPECT_FALSE(s.any_partial());
  EXPECT_TRUE(s.triangle_uv.empty() && s.alpha_textures.empty());
  EXPECT_EQ(s.content_hash(), bare.content_hash());  // the same pack as before
}

void write_gltf(const std::string& dir, const std::string& materials, int mesh_count) {
  // One triangle per mesh (positions, UVs, indices in quads.bin), mesh i at height i + 1.
  std::vector<float> f;
  for (int i = 0; i < mesh_count; ++i) {
    const float y = float(i + 1);
    f.insert(f.end(), {0, y, 0, 1, y, 0, 1, y, 1});
  }
  const float uv[6] = {0, 0, 1, 0, 1, 1};
  const uint16_t idx[4] = {0, 1, 2, 0};
  std::ofstream b(dir + "/quads.bin", std::ios::binary);
  b.write(reinterpret_cast<const char*>(f.data()), std::streamsize(f.size() * 4));
  b.write(reinterpret_cast<const char*>(uv), sizeof uv);
  b.write(reinterpret_cast<const char*>(idx), sizeof idx);
  const size_t pos = f.size() * 4;
  std::string nodes, meshes, accessors;
  for (int i = 0; i < mesh_count; ++i) {
    nodes += std::string(i ? "," : "") + "{\"mesh\":" + std::to_string(i) + "}";
    meshes += std::string(i ? "," : "") + "{\"primitives\":[{\"attributes\":{\"POSITION\":" + std::to_string(i + 2) +
              ",\"TEXCOORD_0\":0},\"indices\":1,\"material\":" + std::to_string(i) + "}]}";
    accessors += ",{\"bufferView\":0,\"byteOffset\":" + std::to_string(36 * i) +
                 ",\"componentType\":5126,\"count\":3,\"type\":\"VEC3\",\"min\":[0," + std::to_string(i + 1) +
                 ",0],\"max\":[1," + std::to_string(i + 1) + ",1]}";
  }
  std::string scene_nodes;
  for (int i = 0; i < mesh_count; ++i) scene_nodes += std::string(i ? "," : "") + std::to_string(i);
  write_text(dir + "/m.gltf",
             "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,\"scenes\":[{\"nodes\":[" + scene_nodes + "]}],"
             "\"nodes\":[" + nodes + "],\"meshes\":[" + meshes + "],"
             "\"buffers\":[{\"byteLength\":" + std::to_string(pos + 32) + ",\"uri\":\"quads.bin\"}],"
             "\"bufferViews\":[{\"buffer\":0,\"byteLength\":" + std::to_string(pos) + "},"
             "{\"buffer\":0,\"byteOffset\":" + std::to_string(pos) + ",\"byteLength\":24},"
             "{\"buffer\":0,\"byteOffset\":" + std::to_string(pos + 24) + ",\"byteLength\":8}],"
             "\"accessors\":[{\"bufferView\":1,\"componentType\":5126,\"count\":3,\"type\":\"VEC2\"},"
             "{\"bufferView\":2,\"componentType\":5123,\"count\":3,\"type\":\"SCALAR\"}" + accessors + "],"
             "\"images\":[{\"uri\":\"tex/leaf.png\"}],\"textures\":[{\"source\":0}],"
             "\"materials\":[" + materials + "]}");
}

TEST(SceneMaterials, GltfAlphaModes) {
  const std::string d = dir_of("mtl_gltf");
  write_leaf_png(d + "/tex/leaf.png");
  auto base = [](const std::string& a, bool tex) {
    return std::string("\"pbrMetallicRoughness\":{\"baseColorFactor\":[1,1,1,") + a + "]" +
           (tex ? ",\"baseColorTexture\":{\"index\":0}" : "") + "}";
  };
  write_gltf(d,
             "{\"alphaMode\":\"BLEND\"," + base("0.3", false) + "},"
             "{\"alphaMode\":\"MASK\",\"alphaCutoff\":0.7," + base("1", true) + "},"
             "{\"alphaMode\":\"MASK\",\"alphaCutoff\":0.7," + base("0.6", true) + "},"
             "{\"alphaMode\":\"MASK\"," + base("0.2", false) + "},"
             "{\"alphaMode\":\"OPAQUE\"," + base("0.2", true) + "}",
             5);
  const Scene s = load_scene(d + "/m.gltf");
  const Mesh &blend = mesh_at_height(s, 1), &mask = mesh_at_height(s, 2), &faint = mesh_at_height(s, 3);
  EXPECT_NEAR(blend.transmit[0], 0.7f, 1e-6f);
  EXPECT_EQ(blend.transmit[1], blend.transmit[0]);
  EXPECT_EQ(blend.alpha_texture, -1);
  ASSERT_GE(mask.alpha_texture, 0);
  EXPECT_EQ(mask.transmit, (Rgb{0, 0, 0}));
  const AlphaTexture& t = s.alpha_textures[size_t(mask.alpha_texture)];
  EXPECT_FLOAT_EQ(t.cutoff, 0.7f);
  EXPECT_TRUE(t.solid(0.5f, 0.9f));
  EXPECT_FALSE(t.solid(0.5f, 0.1f));
  // baseColorFactor.a = 0.6 scales the texture's alpha: 0.6 < 0.7, nothing is solid.
  ASSERT_GE(faint.alpha_texture, 0);
  EXPECT_NE(faint.alpha_texture, mask.alpha_texture);
  EXPECT_FALSE(s.alpha_textures[size_t(faint.alpha_texture)].solid(0.5f, 0.9f));
  EXPECT_EQ(mesh_at_height(s, 4).transmit, (Rgb{1, 1, 1}));  // MASK, 0.2 < 0.5: clear
  EXPECT_FALSE(mesh_at_height(s, 5).partial());              // OPAQUE ignores alpha
}

TEST(SceneMaterials, UnreadableTexturesAreOneClearError) {
  const std::string d = dir_of("mtl_bad");
  std::ofstream(d + "/tex/leaf.jpg", std::ios::binary) << "\xFF\xD8\xFF\xE0 not really";
  write_text(d + "/j.mtl", "newmtl leaf\nmap_d tex/leaf.jpg\n");
  write_text(d + "/j.obj", quads_obj({"leaf"}, "j.mtl"));
  write_text(d + "/n.mtl", "newmtl leaf\nmap_d tex/none.png\n");
  write_text(d + "/n.obj", quads_obj({"leaf"}, "n.mtl"));
  auto message = [](const std::string& path) -> std::string {
    try {
      load_scene(path);
    } catch (const Error& e) {
      return e.what();
    }
    return "no error";
  };
  const std::string jpeg = message(d + "/j.obj"), none = message(d + "/n.obj");
  for (const std::string& m : {jpeg, none}) {
    EXPECT_NE(m.find("material 'leaf'"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
  EXPECT_NE(jpeg.find("leaf.jpg' is JPEG; only PNG"), std::string::npos) << jpeg;
  EXPECT_NE(none.find("none.png' not found"), std::string::npos) << none;
}

}  // namespace
}  // namespace st

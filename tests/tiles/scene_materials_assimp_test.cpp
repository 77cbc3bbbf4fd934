// Material properties no text format we write by hand carries, through assimp's own
// binary format (assbin keeps every material property verbatim): the transparency factor
// alone, the opacity winning over a factor, a transparent colour reduced to its hue, and
// opacity maps embedded in the file (PNG read, JPEG one clear error).
#include <gtest/gtest.h>

#include <assimp/Exporter.hpp>
#include <assimp/material.h>
#include <assimp/scene.h>

#include <cstring>
#include <fstream>
#include <iterator>

#include "common/error.hpp"
#include "image/png_io.hpp"
#include "scene/scene.hpp"

namespace st {
namespace {

aiTexture* embedded(const std::vector<char>& bytes, const char* hint) {
  auto* t = new aiTexture();
  t->mWidth = unsigned(bytes.size());
  t->mHeight = 0;  // compressed: mWidth bytes
  std::strncpy(t->achFormatHint, hint, sizeof t->achFormatHint - 1);
  t->pcData = new aiTexel[(bytes.size() + 3) / 4];
  std::memcpy(t->pcData, bytes.data(), bytes.size());
  return t;
}

// One unit quad per material, mesh i at height i + 1, UVs (x, z).
std::string write_assbin(const std::string& path, std::vector<aiMaterial*> materials,
                         std::vector<aiTexture*> textures) {
  aiScene s;
  const unsigned n = unsigned(materials.size());
  s.mNumMaterials = n;
  s.mMaterials = new aiMaterial*[n];
  s.mNumMeshes = n;
  s.mMeshes = new aiMesh*[n];
  s.mRootNode = new aiNode("root");
  s.mRootNode->mNumMeshes = n;
  s.mRootNode->mMeshes = new unsigned[n];
  for (unsigned i = 0; i < n; ++i) {
    s.mMaterials[i] = materials[i];
    auto* m = new aiMesh();
    m->mMaterialIndex = i;
    m->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
    m->mNumVertices = 4;
    m->mVertices = new aiVector3D[4];
    m->mTextureCoords[0] = new aiVector3D[4];
    m->mNumUVComponents[0] = 2;
    const float uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    for (int k = 0; k < 4; ++k) {
      m->mVertices[k] = aiVector3D(uv[k][0], float(i + 1), uv[k][1]);
      m->mTextureCoords[0][k] = aiVector3D(uv[k][0], uv[k][1], 0);
    }
    m->mNumFaces = 2;
    m->mFaces = new aiFace[2];
    const unsigned f[2][3] = {{0, 2, 1}, {0, 3, 2}};
    for (int k = 0; k < 2; ++k) {
      m->mFaces[k].mNumIndices = 3;
      m->mFaces[k].mIndices = new unsigned[3]{f[k][0], f[k][1], f[k][2]};
    }
    s.mMeshes[i] = m;
    s.mRootNode->mMeshes[i] = i;
  }
  s.mNumTextures = unsigned(textures.size());
  s.mTextures = new aiTexture*[textures.size() + 1];
  for (size_t i = 0; i < textures.size(); ++i) s.mTextures[i] = textures[i];
  Assimp::Exporter e;
  EXPECT_EQ(e.Export(&s, "assbin", path), AI_SUCCESS) << e.GetErrorString();
  return path;
}

aiMaterial* material(float opacity, float factor, const aiColor3D* transparent, const char* opacity_map) {
  auto* m = new aiMaterial();
  if (opacity >= 0) m->AddProperty(&opacity, 1, AI_MATKEY_OPACITY);
  if (factor >= 0) m->AddProperty(&factor, 1, AI_MATKEY_TRANSPARENCYFACTOR);
  if (transparent) m->AddProperty(transparent, 1, AI_MATKEY_COLOR_TRANSPARENT);
  if (opacity_map) {
    const aiString p(opacity_map);
    m->AddProperty(&p, AI_MATKEY_TEXTURE(aiTextureType_OPACITY, 0));
  }
  return m;
}

TEST(SceneMaterialsAssbin, FactorOpacityHueAndEmbeddedMaps) {
  const std::string dir = std::string(SHADOWTILE_TEST_TMP);
  std::vector<Rgb8> rgb;  // no alpha channel: the grey level is the opacity, white on top
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) rgb.push_back(y < 2 ? Rgb8{255, 255, 255} : Rgb8{0, 0, 0});
  write_png(dir + "/grey.png", 4, 4, rgb);
  std::ifstream in(dir + "/grey.png", std::ios::binary);
  const std::vector<char> png((std::istreambuf_iterator<char>(in)), {});
  const aiColor3D black(0, 0, 0), blue(0.2f, 0.4f, 0.8f);
  const std::string path = write_assbin(
      dir + "/m.assbin",
      {material(-1, 0.3f, &black, nullptr), material(0.5f, 1.0f, &blue, nullptr), material(1, -1, nullptr, "*0")},
      {embedded(png, "png")});
  const Scene s = load_scene(path);
  ASSERT_EQ(s.meshes.size(), 3u);
  for (float t : s.meshes[0].transmit) EXPECT_NEAR(t, 0.3f, 1e-6f);  // 1 - factor, black = white
  EXPECT_NEAR(s.meshes[1].transmit[0], 0.125f, 1e-6f);               // (1 - 0.5) x blue / 0.8
  EXPECT_NEAR(s.meshes[1].transmit[1], 0.25f, 1e-6f);
  EXPECT_NEAR(s.meshes[1].transmit[2], 0.5f, 1e-6f);
  ASSERT_EQ(s.meshes[2].alpha_texture, 0);
  EXPECT_TRUE(s.alpha_textures[0].solid(0.5f, 0.9f));
  EXPECT_FALSE(s.alpha_textures[0].solid(0.5f, 0.1f));
  EXPECT_EQ(s.meshes[2].transmit, (Rgb{0, 0, 0}));

  const std::string jpeg = write_assbin(dir + "/j.assbin", {material(1, -1, nullptr, "*0")},
                                        {embedded({'\xFF', '\xD8', '\xFF', '\xE0', 'x', 'y'}, "jpg")});
  try {
    load_scene(jpeg);
    ADD_FAILURE() << "an embedded JPEG opacity map was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("embedded texture '*0' is JPEG; only PNG"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace st

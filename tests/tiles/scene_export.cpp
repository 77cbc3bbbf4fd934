#include "tests/tiles/scene_export.hpp"

#include <assimp/Exporter.hpp>
#include <assimp/material.h>
#include <assimp/scene.h>

#include <limits>
#include <memory>
#include <vector>

#include "common/error.hpp"

namespace st {
namespace {

// Builds an aiScene owned by the unique_ptr: aiScene's destructor frees meshes, materials
// and nodes with delete/delete[], so everything below is allocated with new/new[].
std::unique_ptr<aiScene> to_assimp(const Scene& scene) {
  auto out = std::make_unique<aiScene>();
  out->mNumMaterials = 1;
  out->mMaterials = new aiMaterial*[1];
  out->mMaterials[0] = new aiMaterial();
  const aiString material_name("default");
  out->mMaterials[0]->AddProperty(&material_name, AI_MATKEY_NAME);

  const unsigned count = static_cast<unsigned>(scene.meshes.size());
  out->mRootNode = new aiNode("root");
  out->mNumMeshes = count;
  out->mMeshes = new aiMesh*[count ? count : 1];
  out->mRootNode->mNumChildren = count;
  out->mRootNode->mChildren = new aiNode*[count ? count : 1];
  std::vector<uint32_t> remap(scene.vertices.size(), std::numeric_limits<uint32_t>::max());
  for (unsigned i = 0; i < count; ++i) {
    const Mesh& src = scene.meshes[i];
    auto* mesh = new aiMesh();
    out->mMeshes[i] = mesh;
    mesh->mName = aiString(src.name);
    mesh->mMaterialIndex = 0;
    mesh->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
    std::vector<uint32_t> used;
    for (uint32_t t = src.first_triangle; t < src.first_triangle + src.triangle_count; ++t)
      for (uint32_t v : scene.triangles[t])
        if (remap[v] == std::numeric_limits<uint32_t>::max()) {
          remap[v] = static_cast<uint32_t>(used.size());
          used.push_back(v);
        }
    mesh->mNumVertices = static_cast<unsigned>(used.size());
    mesh->mVertices = new aiVector3D[used.size() ? used.size() : 1];
    for (size_t k = 0; k < used.size(); ++k) {
      const Vec3d& p = scene.vertices[used[k]];
      mesh->mVertices[k] = aiVector3D(float(p.x), float(p.y), float(p.z));
    }
    mesh->mNumFaces = src.triangle_count;
    mesh->mFaces = new aiFace[src.triangle_count ? src.triangle_count : 1];
    for (uint32_t t = 0; t < src.triangle_count; ++t) {
      aiFace& face = mesh->mFaces[t];
      face.mNumIndices = 3;
      face.mIndices = new unsigned[3];
      for (int k = 0; k < 3; ++k) face.mIndices[k] = remap[scene.triangles[src.first_triangle + t][k]];
    }
    for (uint32_t v : used) remap[v] = std::numeric_limits<uint32_t>::max();

    auto* node = new aiNode(src.name);
    node->mParent = out->mRootNode;
    node->mNumMeshes = 1;
    node->mMeshes = new unsigned[1]{i};
    out->mRootNode->mChildren[i] = node;
  }
  return out;
}

}  // namespace

void write_scene(const Scene& scene, const std::string& path, const std::string& format_id) {
  Assimp::Exporter exporter;
  bool known = false;
  for (size_t i = 0; i < exporter.GetExportFormatCount(); ++i)
    known = known || format_id == exporter.GetExportFormatDescription(i)->id;
  if (!known) throw Error(path + ": unknown export format id '" + format_id + "'");
  auto as = to_assimp(scene);
  if (exporter.Export(as.get(), format_id, path) != aiReturn_SUCCESS)
    throw Error(path + ": export as '" + format_id + "' failed: " + exporter.GetErrorString());
}

}  // namespace st

// load_scene: "procedural:..." specs or any file assimp 5.2 reads, flattened into one
// world-space triangle soup in double (node transforms applied, +Y up). Every mesh goes
// through append_mesh() (scene_mesh.hpp), which decides closedness from the triangles
// themselves: nothing a file claims about its geometry is trusted. Materials that let
// light through (opacity, transparency, alpha maps) make partial meshes
// (scene_materials.hpp).
#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "scene/scene_gltf_check.hpp"
#include "scene/scene_grid.hpp"
#include "scene/scene_header_check.hpp"
#include "scene/scene_isolated.hpp"
#include "scene/scene_limits.hpp"
#include "scene/scene_materials.hpp"
#include "scene/scene_mesh.hpp"
#include "scene/scene_quake3.hpp"
#include "scene/scene_volumes.hpp"
#include "common/error.hpp"

namespace st {
namespace {

// Affine transform in double (assimp stores float matrices; products are taken in
// double so deep hierarchies do not accumulate float rounding).
struct Affine {
  double m[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};

  static Affine from(const aiMatrix4x4& a) {
    Affine r;
    const float* rows[3] = {&a.a1, &a.b1, &a.c1};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) r.m[i][j] = rows[i][j];
    return r;
  }
  Affine operator*(const Affine& o) const {
    Affine r;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 4; ++j) {
        double s = j == 3 ? m[i][3] : 0.0;
        for (int k = 0; k < 3; ++k) s += m[i][k] * o.m[k][j];
        r.m[i][j] = s;
      }
    return r;
  }
  Vec3d apply(const aiVector3D& p) const {
    const double x = p.x, y = p.y, z = p.z;
    return {m[0][0] * x + m[0][1] * y + m[0][2] * z + m[0][3],
            m[1][0] * x + m[1][1] * y + m[1][2] * z + m[1][3],
            m[2][0] * x + m[2][1] * y + m[2][2] * z + m[2][3]};
  }
  double determinant() const {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  }
};

// Z-up to Y-up: a -90 degree rotation about X, (x, y, z) -> (x, z, -y). A rotation
// (determinant +1), so handedness and winding are kept; a mirror (y <-> z) would not.
Affine z_up_to_y_up() {
  Affine r;
  r.m[1][1] = 0, r.m[1][2] = 1;
  r.m[2][1] = -1, r.m[2][2] = 0;
  return r;
}

std::string one_line(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

// The mesh's own name, else its node's; a mesh instanced by several nodes is named
// "node/mesh" so that error messages and stats tell the instances apart.
std::string mesh_name(const aiMesh& mesh, const aiNode& node, unsigned index, bool instanced) {
  const std::string m = mesh.mName.length ? mesh.mName.C_Str() : "mesh#" + std::to_string(index);
  if (!node.mName.length) return m;
  if (instanced) return std::string(node.mName.C_Str()) + "/" + m;
  return mesh.mName.length ? m : node.mName.C_Str();
}

bool has_triangles(const aiMesh& mesh) {
  for (unsigned f = 0; f < mesh.mNumFaces; ++f)
    if (mesh.mFaces[f].mNumIndices == 3) return true;
  return false;
}

MeshSoup instance(const aiMesh& mesh, const std::string& name, const Affine& world,
                  const MaterialPartial& material, const std::string& path) {
  MeshSoup soup;
  soup.name = name;
  soup.transmit = material.transmit;
  soup.alpha_texture = material.alpha_texture;
  const aiVector3D* uv = nullptr;
  if (material.alpha_texture >= 0) {
    if (material.uv_channel >= AI_MAX_NUMBER_OF_TEXTURECOORDS || !mesh.mTextureCoords[material.uv_channel])
      throw Error(path + ": mesh '" + name + "' is alpha-tested but has no texture coordinates (channel " +
                  std::to_string(material.uv_channel) + ")");
    uv = mesh.mTextureCoords[material.uv_channel];
  }
  soup.vertices.reserve(mesh.mNumVertices);
  for (unsigned v = 0; v < mesh.mNumVertices; ++v) soup.vertices.push_back(world.apply(mesh.mVertices[v]));
  // A mirroring transform turns the winding inside out; undo it so that front faces stay
  // front faces (closed meshes would be re-oriented anyway, open ones would not).
  const bool mirrored = world.determinant() < 0;
  soup.triangles.reserve(mesh.mNumFaces);
  for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
    const aiFace& face = mesh.mFaces[f];
    if (face.mNumIndices != 3) continue;  // points and lines (Triangulate split polygons)
    Triangle t{face.mIndices[0], face.mIndices[1], face.mIndices[2]};
    if (mirrored) std::swap(t[1], t[2]);
    soup.triangles.push_back(t);
    if (uv) {
      std::array<Vec2f, 3> c;
      for (int k = 0; k < 3; ++k)  // a bad index is refused by append_mesh()
        c[k] = t[k] < mesh.mNumVertices ? Vec2f{uv[t[k]].x, uv[t[k]].y} : Vec2f{};
      soup.uv.push_back(c);
    }
  }
  return soup;
}

// glTF (by content, as assimp picks its importer by content too when the extension is not
// its own): its nesting checked before assimp recurses over it (scene_gltf_check.hpp).
void check_gltf_file(const std::string& path, uint64_t memory_bytes) {
  std::ifstream in(path, std::ios::binary);
  char head[64] = {};
  in.read(head, sizeof head);
  const std::string_view prefix(head, size_t(in.gcount()));
  const size_t first = prefix.find_first_not_of(" \t\r\n\xEF\xBB\xBF");
  if (prefix.rfind("glTF", 0) != 0 && (first == std::string_view::npos || prefix[first] != '{')) return;
  in.clear();
  in.seekg(0);
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  check_gltf_structure(bytes, path, memory_bytes);
}

// The up axis a file records, when SceneOptions::up leaves it to the file. FBX keeps it
// in GlobalSettings, which assimp exposes as scene metadata (UpAxis 0/1/2 = X/Y/Z,
// UpAxisSign +1/-1) without applying it. COLLADA keeps it in <asset><up_axis>, which
// assimp applies itself to the root node: it is read here (from the file's head, where
// <asset> is) only to say which axis was used.
struct FileUp {
  UpAxis up = UpAxis::y;
  std::string reason;
};

FileUp collada_up(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string head(64 * 1024, '\0');
  in.read(head.data(), std::streamsize(head.size()));
  head.resize(size_t(in.gcount()));
  const size_t open = head.find("<up_axis>");
  if (open == std::string::npos) return {UpAxis::y, "the file records none"};
  const size_t from = open + 9, close = head.find("</up_axis>", from);
  std::string axis = head.substr(from, close == std::string::npos ? 0 : close - from);
  axis.erase(0, axis.find_first_not_of(" \t\r\n"));
  axis.erase(axis.find_last_not_of(" \t\r\n") + 1);
  if (axis == "Z_UP") return {UpAxis::z, "from the file's <up_axis>, turned by assimp"};
  if (axis == "Y_UP") return {UpAxis::y, "from the file's <up_axis>"};
  return {UpAxis::y, "the file's <up_axis> says " + axis.substr(0, 16) + ", turned by assimp"};
}

FileUp file_up(const aiScene& as, const std::string& path, const std::string& ext) {
  int32_t axis = -1, sign = 1;
  if (as.mMetaData && as.mMetaData->Get("UpAxis", axis)) {
    as.mMetaData->Get("UpAxisSign", sign);
    if (axis == 2 && sign == 1) return {UpAxis::z, "from the file's metadata"};
    if (axis == 1 && sign == 1) return {UpAxis::y, "from the file's metadata"};
    std::string why = "the file's metadata says up is ";
    why.push_back(sign < 0 ? '-' : '+');
    why.push_back(axis >= 0 && axis < 3 ? "XYZ"[axis] : '?');
    why += ", which is not supported: read as y (pass --up)";
    return {UpAxis::y, why};
  }
  if (ext == ".dae") return collada_up(path);
  if (ext == ".zae") return {UpAxis::y, "COLLADA's <up_axis>, if any, turned by assimp"};
  return {UpAxis::y, "the file records none"};
}

// An FBX file's unit (its GlobalSettings UnitScaleFactor: centimetres per file unit,
// which assimp 5.2 reports in the scene's metadata and does not apply): coordinates are
// multiplied by it, so every FBX scene is in centimetres whatever unit it was saved in.
// 1 where the file records none (FBX's default unit is the centimetre); a factor that is
// not a positive finite number is refused in one line.
double fbx_unit_scale(const aiScene& as, const std::string& path, std::string& reason) {
  double factor = 1;
  float f32 = 1;
  if (!as.mMetaData) return 1;
  if (!as.mMetaData->Get("UnitScaleFactor", factor)) {
    if (!as.mMetaData->Get("UnitScaleFactor", f32)) return 1;
    factor = f32;
  }
  if (!(std::isfinite(factor) && factor > 0 && factor < 1e9))
    throw Error(path + ": the file's UnitScaleFactor " + std::to_string(factor) +
                " is not a positive finite number of centimetres per unit");
  char text[96];
  std::snprintf(text, sizeof text, "x%.9g (the file's UnitScaleFactor: coordinates in centimetres)", factor);
  reason = text;
  return factor;
}

Scene import_file(const std::string& path, const SceneOptions& options, const SceneLimits& limits) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (ec || !fs::exists(status)) throw Error("scene file not found: " + path);
  if (!fs::is_regular_file(status)) throw Error("scene path is not a regular file: " + path);

  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".pk3" || ext == ".bsp") return load_quake3(path, options, "", limits.max_triangles);

  check_gltf_file(path, limits.isolate ? limits.memory_bytes : 0);
  check_header_counts(path);  // PLY and OFF element counts against the file's size
  check_xml_nesting(path);    // COLLADA and the other XML formats
  Assimp::Importer importer;
  // A given axis overrides the file's: assimp must not turn a COLLADA file by its own.
  if (options.up) importer.SetPropertyBool(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, true);
  // Validation stays on: assimp 5.2.5 crashes on some inputs (Quake 3 .bsp) without it
  // (seen with assimp 5.2.5). No JoinIdenticalVertices/FindDegenerates: welding and degenerate
  // removal happen in append_mesh() so they are counted and identical for all sources.
  const unsigned flags = aiProcess_Triangulate | aiProcess_ValidateDataStructure;
  const aiScene* as = nullptr;
  try {
    as = importer.ReadFile(path, flags);
  } catch (const std::exception& e) {
    throw Error(path + ": assimp failed: " + one_line(e.what()));
  }
  if (!as) {
    const std::string why = one_line(importer.GetErrorString());
    if (why.find("bad_alloc") != std::string::npos || why.find("bad_array_new_length") != std::string::npos)
      throw std::bad_alloc();  // assimp caught it: the reader's memory limit (scene_isolated.cpp)
    if (!importer.IsExtensionSupported(ext))
      throw Error(path + ": unknown scene format '" + ext + "' (" + why + ")");
    if (why.find("mNumMeshes is 0") != std::string::npos)
      throw Error(path + ": scene contains no meshes");
    if (why.find("alidat") != std::string::npos)
      throw Error(path + ": invalid scene data, assimp validation failed: " + why);
    throw Error(path + ": cannot read scene: " + why);
  }
  if (!as->mRootNode) throw Error(path + ": scene has no node hierarchy");

  Scene scene;
  scene.name = path;
  FileMaterials materials(*as, path, limits.max_texels);  // partial occluders (scene_materials.hpp)
  if (options.up) {
    scene.up = *options.up;
    scene.up_reason = "given";
  } else {
    FileUp found = file_up(*as, path, ext);
    scene.up = found.up;
    scene.up_reason = std::move(found.reason);
  }
  // COLLADA's own axis was applied by assimp (unless a given one overrode it).
  const bool turned_by_assimp = !options.up && scene.up_reason.find("turned by assimp") != std::string::npos;
  Affine root = scene.up == UpAxis::z && !turned_by_assimp ? z_up_to_y_up() : Affine{};
  if (ext == ".fbx") {
    const double unit = fbx_unit_scale(*as, path, scene.unit_reason);
    for (auto& row : root.m)
      for (double& v : row) v *= unit;
  }
  std::vector<unsigned> uses(as->mNumMeshes, 0);
  {
    // The triangles the node tree emits, every instance counted, against the budget before
    // any of them is copied: a file of kilobytes can instance one mesh a million times.
    uint64_t emitted = 0;
    std::vector<const aiNode*> todo{as->mRootNode};
    while (!todo.empty()) {
      const aiNode* node = todo.back();
      todo.pop_back();
      for (unsigned i = 0; i < node->mNumMeshes; ++i)
        if (node->mMeshes[i] < as->mNumMeshes) {
          ++uses[node->mMeshes[i]];
          emitted += as->mMeshes[node->mMeshes[i]]->mNumFaces;
        }
      if (emitted > limits.max_triangles)
        throw Error(path + ": the scene's node tree instances more than " +
                    std::to_string(limits.max_triangles) +
                    " triangles, the limit (raise it with --scene-limits triangles=N)");
      for (unsigned c = 0; c < node->mNumChildren; ++c) todo.push_back(node->mChildren[c]);
    }
  }
  // Iterative walk (a hostile file may nest nodes deeper than the stack allows); children
  // are pushed in reverse so meshes come out in document order.
  std::vector<std::pair<const aiNode*, Affine>> stack{{as->mRootNode, root * Affine::from(as->mRootNode->mTransformation)}};
  while (!stack.empty()) {
    auto [node, world] = stack.back();
    stack.pop_back();
    for (unsigned i = 0; i < node->mNumMeshes; ++i) {
      const unsigned index = node->mMeshes[i];
      if (index >= as->mNumMeshes) throw Error(path + ": node '" + node->mName.C_Str() + "' references a missing mesh");
      const aiMesh& mesh = *as->mMeshes[index];
      if (!has_triangles(mesh)) continue;  // point clouds and line sets carry no surface
      const std::string name = mesh_name(mesh, *node, index, uses[index] > 1);
      append_mesh(scene, instance(mesh, name, world, materials.get(mesh.mMaterialIndex, scene), path));
    }
    for (unsigned c = node->mNumChildren; c-- > 0;)
      stack.push_back({node->mChildren[c], world * Affine::from(node->mChildren[c]->mTransformation)});
  }
  return scene;
}

// Every file is read in a child process under `limits` (scene_isolated.hpp): assimp
// allocates from header counts and recurses over what it parses, and a crash, a limit or a
// deadline there is one line of error here.
Scene load_file(const std::string& path, const SceneOptions& options, const SceneLimits& limits) {
  return read_scene_isolated(path, limits, [&] { return import_file(path, options, limits); });
}

}  // namespace

Scene load_scene(const std::string& spec, const SceneOptions& options) { return load_scene(spec, options, SceneLimits{}); }

Scene load_scene(const std::string& spec, const SceneOptions& options, const SceneLimits& limits) {
  // "BASE+vdb:...+fog:..." adds volumes to BASE; "vdb:..." and "*.vdb" are volumes alone
  // (scene_volumes.hpp).
  if (const size_t plus = volume_suffix(spec); plus != std::string::npos) {
    Scene scene = load_scene(spec.substr(0, plus), options, limits);
    // Volumes follow the axis their scene was read with (a given one, else the file's).
    add_spec_volumes(scene, spec.substr(plus), options.up.value_or(scene.up));
    return scene;
  }
  if (spec.rfind("vdb:", 0) == 0) return load_vdb_scene(spec, options.up.value_or(UpAxis::y));
  if (is_grid_spec(spec)) return load_grid_scene(spec, options, limits);
  // Procedural scenes are generated +Y up; options.up only describes file sources.
  if (spec.rfind("procedural:", 0) == 0) return make_procedural(spec);
  // "ARCHIVE.pk3:maps/NAME.bsp" picks one map of a pack (when no file has that name).
  std::string lower = spec;
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (lower.size() > 4 && lower.compare(lower.size() - 4, 4, ".vdb") == 0) return load_vdb_scene(spec, options.up.value_or(UpAxis::y));
  const size_t pk3 = lower.find(".pk3:");
  if (pk3 != std::string::npos && !std::filesystem::exists(spec)) {
    const std::string archive = spec.substr(0, pk3 + 4), member = spec.substr(pk3 + 5);
    if (!std::filesystem::is_regular_file(archive)) throw Error("scene file not found: " + archive);
    return read_scene_isolated(spec, limits, [&] { return load_quake3(archive, options, member, limits.max_triangles); });
  }
  return load_file(spec, options, limits);
}

}  // namespace st

#include "scene/scene_quake3.hpp"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "scene/scene_mesh.hpp"
#include "scene/scene_zip.hpp"
#include "common/error.hpp"

namespace st {
namespace {

// IBSP version 46 (little-endian):
//   0  char[4] "IBSP"   4  int32 version = 46   8  17 lumps x {int32 offset, int32 size}
// Records used here:
//   texture  (lump 1)  72 bytes: char name[64] @0, int32 surface flags @64, contents @68
//   vertex   (lump 10) 44 bytes: float position[3] @0, uv[2] @12, lightmap uv[2] @20,
//                               float normal[3] @28, rgba @40
//   meshvert (lump 11)  4 bytes: int32 offset from the face's first vertex
//   face     (lump 13) 104 bytes: texture @0, effect @4, type @8, vertex @12, n_vertexes
//                               @16, meshvert @20, n_meshverts @24, lightmap @28, ...,
//                               patch size int32[2] @96
constexpr size_t kHeaderSize = 8 + 17 * 8;
constexpr int kLumps = 17;
// Lightmap indices are not checked: they are never read here, and maps compiled with
// external lightmaps (q3map2 -external) or vertex lighting (-3) store indices outside
// the lightmap lump.
enum Lump { kTextures = 1, kVertices = 10, kMeshVerts = 11, kFaces = 13 };
// Record sizes of the lumps read here; the others are only checked to lie in the file.
constexpr size_t kRecord[kLumps] = {1, 72, 1, 1, 1, 1, 1, 1, 1, 1, 44, 4, 1, 104, 1, 1, 1};
enum FaceType { kPolygon = 1, kPatch = 2, kMeshFace = 3, kBillboard = 4 };
constexpr int32_t kSurfSky = 0x4, kSurfNodraw = 0x80;

struct Bsp {
  const std::vector<uint8_t>& data;
  size_t offset[kLumps] = {}, count[kLumps] = {};

  int32_t i32(size_t at) const {
    int32_t v;
    std::memcpy(&v, data.data() + at, sizeof v);  // every caller's range was checked
    return v;
  }
  float f32(size_t at) const {
    float v;
    std::memcpy(&v, data.data() + at, sizeof v);
    return v;
  }
  size_t face(size_t f) const { return offset[kFaces] + f * kRecord[kFaces]; }
  size_t vertex(size_t v) const { return offset[kVertices] + v * kRecord[kVertices]; }
  Vec3d position(size_t v) const { return {f32(vertex(v)), f32(vertex(v) + 4), f32(vertex(v) + 8)}; }
  Vec3d normal(size_t v) const { return {f32(vertex(v) + 28), f32(vertex(v) + 32), f32(vertex(v) + 36)}; }
  int32_t meshvert(size_t m) const { return i32(offset[kMeshVerts] + m * kRecord[kMeshVerts]); }
};

// Checks everything the mesh builder below reads, so it can index without further tests.
void validate(Bsp& bsp, const std::string& where) {
  const auto& data = bsp.data;
  auto fail = [&](const std::string& what) { throw Error(where + ": malformed Quake 3 map: " + what); };
  if (data.size() < kHeaderSize) fail("file of " + std::to_string(data.size()) + " bytes is shorter than the 144-byte header");
  if (std::memcmp(data.data(), "IBSP", 4) != 0) fail("magic is not IBSP");
  if (bsp.i32(4) != 46) fail("version " + std::to_string(bsp.i32(4)) + " is not 46");
  for (int l = 0; l < kLumps; ++l) {
    const int32_t off = bsp.i32(8 + 8 * l), size = bsp.i32(12 + 8 * l);
    if (off < 0 || size < 0 || size_t(off) + size_t(size) > data.size())
      fail("lump " + std::to_string(l) + " (offset " + std::to_string(off) + ", size " + std::to_string(size) +
           ") lies outside the file of " + std::to_string(data.size()) + " bytes");
    if (size_t(size) % kRecord[l] != 0)
      fail("lump " + std::to_string(l) + " size " + std::to_string(size) + " is not a multiple of its record size " +
           std::to_string(kRecord[l]));
    bsp.offset[l] = size_t(off);
    bsp.count[l] = size_t(size) / kRecord[l];
  }
  for (size_t f = 0; f < bsp.count[kFaces]; ++f) {
    const size_t at = bsp.face(f);
    const int32_t texture = bsp.i32(at), type = bsp.i32(at + 8), vertex = bsp.i32(at + 12), nvert = bsp.i32(at + 16);
    const int32_t meshvert = bsp.i32(at + 20), nmeshvert = bsp.i32(at + 24);
    const std::string face = "face " + std::to_string(f) + ": ";
    if (type < kPolygon || type > kBillboard) fail(face + "unknown type " + std::to_string(type));
    if (texture < -1 || (texture >= 0 && size_t(texture) >= bsp.count[kTextures])) fail(face + "texture index out of range");
    if (vertex < 0 || nvert < 0 || size_t(vertex) + size_t(nvert) > bsp.count[kVertices])
      fail(face + "vertex range out of range");
    if (meshvert < 0 || nmeshvert < 0 || size_t(meshvert) + size_t(nmeshvert) > bsp.count[kMeshVerts])
      fail(face + "mesh-vertex range out of range");
    if (type == kPolygon || type == kMeshFace) {
      if (nmeshvert % 3 != 0) fail(face + "mesh-vertex count " + std::to_string(nmeshvert) + " is not a multiple of 3");
      for (int32_t k = 0; k < nmeshvert; ++k) {
        const int32_t index = bsp.meshvert(size_t(meshvert) + k);
        if (index < 0 || index >= nvert) fail(face + "mesh vertex " + std::to_string(index) + " outside the face's vertices");
      }
    } else if (type == kPatch) {
      const int32_t w = bsp.i32(at + 96), h = bsp.i32(at + 100);
      if (w < 3 || h < 3 || w % 2 == 0 || h % 2 == 0 || int64_t(w) * h > nvert)
        fail(face + "patch size " + std::to_string(w) + "x" + std::to_string(h) + " is not odd >= 3 within " +
             std::to_string(nvert) + " vertices");
    }
  }
}

std::string texture_name(const Bsp& bsp, int32_t texture) {
  if (texture < 0) return "untextured";
  const char* name = reinterpret_cast<const char*>(bsp.data.data() + bsp.offset[kTextures] + size_t(texture) * 72);
  std::string out(name, strnlen(name, 64));
  for (char& c : out)
    if (!std::isprint(static_cast<unsigned char>(c))) c = '?';
  return out.empty() ? "texture#" + std::to_string(texture) : out;
}

bool casts_shadow(const Bsp& bsp, int32_t texture) {
  if (texture < 0) return true;
  const int32_t flags = bsp.i32(bsp.offset[kTextures] + size_t(texture) * 72 + 64);
  return (flags & (kSurfSky | kSurfNodraw)) == 0;
}

// Biquadratic Bezier patch (the Quake 3 curved surface): each 3x3 block of the w x h
// control grid becomes a (level+1)^2 vertex grid.
void tessellate_patch(const Bsp& bsp, size_t first, int w, int h, MeshSoup& m) {
  constexpr int level = kQuake3PatchLevel;
  auto basis = [](double t, double b[3]) {
    b[0] = (1 - t) * (1 - t), b[1] = 2 * t * (1 - t), b[2] = t * t;
  };
  for (int py = 0; py + 2 < h; py += 2)
    for (int px = 0; px + 2 < w; px += 2) {
      const uint32_t base = static_cast<uint32_t>(m.vertices.size());
      for (int j = 0; j <= level; ++j)
        for (int i = 0; i <= level; ++i) {
          double bu[3], bv[3];
          basis(double(i) / level, bu);
          basis(double(j) / level, bv);
          Vec3d p;
          for (int r = 0; r < 3; ++r)
            for (int s = 0; s < 3; ++s) p = p + bsp.position(first + size_t(py + r) * w + size_t(px + s)) * (bv[r] * bu[s]);
          m.vertices.push_back(p);
        }
      const uint32_t row = level + 1;
      for (uint32_t j = 0; j < uint32_t(level); ++j)
        for (uint32_t i = 0; i < uint32_t(level); ++i) {
          const uint32_t a = base + j * row + i;
          m.triangles.push_back({a, a + 1, a + row + 1});
          m.triangles.push_back({a, a + row + 1, a + row});
        }
    }
}

// Makes the face's triangles [from, end) agree with its stored vertex normals.
void orient_face(const Bsp& bsp, size_t first, size_t count, MeshSoup& m, size_t from) {
  Vec3d stored;
  for (size_t v = first; v < first + count; ++v) stored = stored + bsp.normal(v);
  Vec3d geometric;
  for (size_t t = from; t < m.triangles.size(); ++t) {
    const auto& tri = m.triangles[t];
    geometric = geometric + cross(m.vertices[tri[1]] - m.vertices[tri[0]], m.vertices[tri[2]] - m.vertices[tri[0]]);
  }
  if (dot(stored, geometric) < 0)
    for (size_t t = from; t < m.triangles.size(); ++t) std::swap(m.triangles[t][1], m.triangles[t][2]);
}

// Faces may share vertex and mesh-vertex ranges, and a patch's control grid is small
// against its tessellation (81 vertices, 128 triangles per 3x3 block), so a small file
// can describe a huge mesh. Counts what the loop in load_quake3_bytes() will emit, before
// anything is allocated, and refuses maps past `max_output` triangles or vertices.
void check_output_size(const Bsp& bsp, const std::string& where, uint64_t max_output) {
  constexpr uint64_t level = kQuake3PatchLevel;
  uint64_t vertices = 0, triangles = 0;
  for (size_t f = 0; f < bsp.count[kFaces]; ++f) {
    const size_t at = bsp.face(f);
    const int32_t texture = bsp.i32(at), type = bsp.i32(at + 8);
    if (type == kBillboard || !casts_shadow(bsp, texture)) continue;
    if (type == kPatch) {  // validate(): w, h odd >= 3
      const uint64_t blocks = uint64_t((bsp.i32(at + 96) - 1) / 2) * uint64_t((bsp.i32(at + 100) - 1) / 2);
      vertices += blocks * (level + 1) * (level + 1);
      triangles += blocks * 2 * level * level;
    } else {
      vertices += uint64_t(bsp.i32(at + 16));
      triangles += uint64_t(bsp.i32(at + 24)) / 3;
    }
    if (triangles > max_output || vertices > max_output)
      throw Error(where + ": Quake 3 map too large: faces 0.." + std::to_string(f) + " already make " +
                  std::to_string(triangles) + " triangles and " + std::to_string(vertices) +
                  " vertices (patches tessellated " + std::to_string(level) + "x" + std::to_string(level) +
                  " per 3x3 block), more than the limit of " + std::to_string(max_output) + " triangles and " +
                  std::to_string(max_output) + " vertices");
  }
}

std::vector<uint8_t> read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error("cannot open scene file: " + path);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace

Scene load_quake3(const std::string& path, const SceneOptions& options, const std::string& member,
                  uint64_t max_output) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext != ".pk3") {
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    if (!ec && size > kQuake3MaxBspBytes)
      throw Error(path + ": map of " + std::to_string(size) + " bytes, more than the " +
                  std::to_string(kQuake3MaxBspBytes >> 20) + " MiB a Quake 3 map may take");
  }
  return load_quake3_bytes(read_all(path), path, ext == ".pk3", options, member,
                           std::min(max_output, uint64_t(UINT32_MAX)));
}

Scene load_quake3_bytes(std::vector<uint8_t> bytes, const std::string& path, bool is_pk3,
                        const SceneOptions& options, const std::string& member, uint64_t max_output) {
  std::string where = path;
  if (is_pk3) {
    const auto entries = list_zip(bytes, path, ".bsp");
    if (!entries) throw Error(path + ": not a zip archive (a .pk3 must be one)");
    if (entries->empty()) throw Error(path + ": no .bsp map in the archive");
    size_t pick = 0;
    if (!member.empty()) {
      pick = entries->size();
      for (size_t i = 0; i < entries->size() && pick == entries->size(); ++i)
        if ((*entries)[i].name == member) pick = i;
      if (pick == entries->size()) throw Error(path + ": no map '" + member + "' in the archive");
    } else {
      for (size_t i = entries->size(); i-- > 0;)
        if ((*entries)[i].name.rfind("maps/", 0) == 0) pick = i;
    }
    where = path + ": " + (*entries)[pick].name;
    if ((*entries)[pick].size > kQuake3MaxBspBytes)
      throw Error(where + ": map of " + std::to_string((*entries)[pick].size) + " bytes, more than the " +
                  std::to_string(kQuake3MaxBspBytes >> 20) + " MiB a Quake 3 map may take");
    bytes = extract_zip(bytes, path, (*entries)[pick], "IBSP");
  }
  Bsp bsp{bytes};
  validate(bsp, where);
  check_output_size(bsp, where, max_output);

  std::map<int32_t, MeshSoup> by_texture;  // ordered: deterministic mesh order
  for (size_t f = 0; f < bsp.count[kFaces]; ++f) {
    const size_t at = bsp.face(f);
    const int32_t texture = bsp.i32(at), type = bsp.i32(at + 8);
    if (type == kBillboard || !casts_shadow(bsp, texture)) continue;
    const size_t first = size_t(bsp.i32(at + 12)), nvert = size_t(bsp.i32(at + 16));
    MeshSoup& m = by_texture[texture];
    const size_t from = m.triangles.size();
    if (type == kPatch) {
      tessellate_patch(bsp, first, bsp.i32(at + 96), bsp.i32(at + 100), m);
    } else {
      const uint32_t base = static_cast<uint32_t>(m.vertices.size());
      for (size_t v = first; v < first + nvert; ++v) m.vertices.push_back(bsp.position(v));
      const size_t mv = size_t(bsp.i32(at + 20)), nmv = size_t(bsp.i32(at + 24));
      for (size_t k = 0; k < nmv; k += 3)
        m.triangles.push_back({base + uint32_t(bsp.meshvert(mv + k)), base + uint32_t(bsp.meshvert(mv + k + 1)),
                               base + uint32_t(bsp.meshvert(mv + k + 2))});
    }
    orient_face(bsp, first, nvert, m, from);
  }
  Scene scene;
  scene.name = member.empty() ? path : path + ":" + member;
  scene.up = options.up.value_or(UpAxis::z);
  scene.up_reason = options.up ? "given" : "Quake 3 maps are Z-up";
  for (auto& [texture, soup] : by_texture) {
    soup.name = texture_name(bsp, texture);
    if (scene.up == UpAxis::z)  // (x, y, z) -> (x, z, -y), a rotation: winding kept
      for (auto& v : soup.vertices) v = {v.x, v.z, -v.y};
    append_mesh(scene, std::move(soup));
  }
  if (scene.triangles.empty()) throw Error(where + ": map has no shadow-casting surfaces");
  return scene;
}

}  // namespace st

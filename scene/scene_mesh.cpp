#include "scene/scene_mesh.hpp"

#include <algorithm>
#include <cstring>
#include <limits>
#include <numeric>

#include "common/error.hpp"

namespace st {
namespace {

// Sort key for welding: the bit patterns of the coordinates with -0.0 folded onto +0.0
// (x + 0.0 does that) so that the two zeros weld, NaN never reaches here.
struct PosKey {
  uint64_t b[3];
  bool operator<(const PosKey& o) const {
    return b[0] != o.b[0] ? b[0] < o.b[0] : (b[1] != o.b[1] ? b[1] < o.b[1] : b[2] < o.b[2]);
  }
  bool operator==(const PosKey& o) const {
    return b[0] == o.b[0] && b[1] == o.b[1] && b[2] == o.b[2];
  }
};

PosKey key_of(const Vec3d& p) {
  PosKey k;
  const double c[3] = {p.x + 0.0, p.y + 0.0, p.z + 0.0};
  for (int i = 0; i < 3; ++i) std::memcpy(&k.b[i], &c[i], sizeof(double));
  return k;
}

// Welds referenced vertices by exact position; rewrites the triangle indices in place and
// returns the compacted vertex list.
std::vector<Vec3d> weld(const std::vector<Vec3d>& in, std::vector<Triangle>& triangles) {
  constexpr uint32_t kUnused = std::numeric_limits<uint32_t>::max();
  std::vector<uint8_t> used(in.size(), 0);
  for (auto& t : triangles)
    for (uint32_t i : t) used[i] = 1;
  std::vector<std::pair<PosKey, uint32_t>> order;
  order.reserve(in.size());
  for (uint32_t i = 0; i < in.size(); ++i)
    if (used[i]) order.push_back({key_of(in[i]), i});
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) {
    return a.first < b.first || (a.first == b.first && a.second < b.second);
  });
  // New index = rank of the first occurrence of the position in original order, so
  // the output order follows the input (stable output for hashing).
  std::vector<uint32_t> remap(in.size(), kUnused);
  std::vector<uint32_t> representative(in.size(), kUnused);
  for (size_t s = 0; s < order.size();) {
    size_t e = s;
    while (e < order.size() && order[e].first == order[s].first) ++e;
    for (size_t j = s; j < e; ++j) representative[order[j].second] = order[s].second;
    s = e;
  }
  std::vector<Vec3d> out;
  out.reserve(order.size());
  for (uint32_t i = 0; i < in.size(); ++i) {
    if (!used[i]) continue;
    uint32_t r = representative[i];
    if (remap[r] == kUnused) {
      remap[r] = static_cast<uint32_t>(out.size());
      out.push_back(in[r]);
    }
    remap[i] = remap[r];
  }
  for (auto& t : triangles)
    for (uint32_t& i : t) i = remap[i];
  return out;
}

bool degenerate(const std::vector<Vec3d>& v, const Triangle& t) {
  if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) return true;
  Vec3d n = cross(v[t[1]] - v[t[0]], v[t[2]] - v[t[0]]);
  return n.x == 0.0 && n.y == 0.0 && n.z == 0.0;
}

}  // namespace

bool is_closed_surface(const std::vector<Triangle>& triangles) {
  if (triangles.empty()) return false;
  // Directed edges as (from << 32 | to). Closed iff no directed edge repeats (each
  // undirected edge then has at most one use per direction) and every directed edge has
  // its reverse (so exactly two faces per edge, with opposite directions).
  std::vector<uint64_t> edges;
  edges.reserve(triangles.size() * 3);
  for (auto& t : triangles)
    for (int k = 0; k < 3; ++k)
      edges.push_back(uint64_t(t[k]) << 32 | t[(k + 1) % 3]);
  std::sort(edges.begin(), edges.end());
  if (std::adjacent_find(edges.begin(), edges.end()) != edges.end()) return false;
  for (uint64_t e : edges) {
    uint64_t rev = (e << 32) | (e >> 32);
    if (!std::binary_search(edges.begin(), edges.end(), rev)) return false;
  }
  return true;
}

double signed_volume(const std::vector<Vec3d>& vertices, const std::vector<Triangle>& triangles) {
  if (triangles.empty()) return 0.0;
  // Tetrahedra against a reference point inside the vertex cloud: the sum is the same
  // for any reference on a closed surface, but a nearby one keeps the products small
  // when the scene sits at 1e7 with 1e-5 features.
  Vec3d ref;
  for (auto& v : vertices) ref = ref + v;
  ref = ref / double(vertices.size());
  double vol = 0.0;
  for (auto& t : triangles) {
    Vec3d a = vertices[t[0]] - ref, b = vertices[t[1]] - ref, c = vertices[t[2]] - ref;
    vol += dot(a, cross(b, c));
  }
  return vol / 6.0;
}

double mesh_signed_volume(const Scene& scene, size_t mesh_index) {
  const Mesh& m = scene.meshes.at(mesh_index);
  std::vector<Triangle> tris(scene.triangles.begin() + m.first_triangle,
                             scene.triangles.begin() + m.first_triangle + m.triangle_count);
  // Compact the vertices so the reference point is this mesh's own centroid.
  std::vector<Vec3d> verts;
  std::vector<uint32_t> remap(scene.vertices.size(), std::numeric_limits<uint32_t>::max());
  for (auto& t : tris)
    for (uint32_t& i : t) {
      if (remap[i] == std::numeric_limits<uint32_t>::max()) {
        remap[i] = static_cast<uint32_t>(verts.size());
        verts.push_back(scene.vertices[i]);
      }
      i = remap[i];
    }
  return signed_volume(verts, tris);
}

void append_mesh(Scene& scene, MeshSoup mesh) {
  for (auto& t : mesh.triangles)
    for (uint32_t i : t) {
      if (i >= mesh.vertices.size())
        throw Error(scene.name + ": mesh '" + mesh.name + "' has a triangle index " + std::to_string(i) +
                    " past its " + std::to_string(mesh.vertices.size()) + " vertices");
      if (!is_finite(mesh.vertices[i]))
        throw Error(scene.name + ": mesh '" + mesh.name + "' has a non-finite (NaN or Inf) vertex " +
                    std::to_string(i));
    }
  if (!mesh.uv.empty() && mesh.uv.size() != mesh.triangles.size())
    throw Error(scene.name + ": mesh '" + mesh.name + "' has " + std::to_string(mesh.uv.size()) +
                " UV triangles for " + std::to_string(mesh.triangles.size()) + " triangles");
  std::vector<Vec3d> verts = weld(mesh.vertices, mesh.triangles);
  size_t before = mesh.triangles.size();
  if (!mesh.uv.empty()) {  // drop the UVs of degenerate triangles in lockstep
    size_t k = 0;
    for (size_t i = 0; i < mesh.triangles.size(); ++i)
      if (!degenerate(verts, mesh.triangles[i])) mesh.uv[k++] = mesh.uv[i];
    mesh.uv.resize(k);
  }
  std::erase_if(mesh.triangles, [&](const Triangle& t) { return degenerate(verts, t); });
  scene.stats.degenerate_dropped += before - mesh.triangles.size();
  if (mesh.triangles.size() != before) verts = weld(verts, mesh.triangles);  // drop orphans

  Mesh out;
  out.name = mesh.name;
  out.closed = is_closed_surface(mesh.triangles);
  if (out.closed && signed_volume(verts, mesh.triangles) < 0.0) {
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
    for (auto& uv : mesh.uv) std::swap(uv[1], uv[2]);
    ++scene.stats.meshes_flipped;
  }
  constexpr size_t kMax = std::numeric_limits<uint32_t>::max();
  if (scene.vertices.size() + verts.size() > kMax || scene.triangles.size() + mesh.triangles.size() > kMax)
    throw Error(scene.name + ": more than 2^32-1 vertices or triangles (at mesh '" + mesh.name + "')");
  const uint32_t base = static_cast<uint32_t>(scene.vertices.size());
  out.first_triangle = static_cast<uint32_t>(scene.triangles.size());
  out.triangle_count = static_cast<uint32_t>(mesh.triangles.size());
  out.transmit = mesh.transmit;
  out.alpha_texture = mesh.alpha_texture;
  if (!mesh.uv.empty() || !scene.triangle_uv.empty()) {
    scene.triangle_uv.resize(scene.triangles.size());
    if (mesh.uv.empty()) mesh.uv.resize(mesh.triangles.size());
    scene.triangle_uv.insert(scene.triangle_uv.end(), mesh.uv.begin(), mesh.uv.end());
  }
  scene.vertices.insert(scene.vertices.end(), verts.begin(), verts.end());
  for (auto& t : mesh.triangles) scene.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  scene.meshes.push_back(std::move(out));
}

}  // namespace st

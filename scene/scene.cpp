#include "scene/scene.hpp"

#include <cstring>

namespace st {

Aabb Scene::bounds() const {
  Aabb b;
  for (auto& t : triangles)
    for (uint32_t i : t) b.extend(vertices[i]);
  for (auto& v : volumes)
    if (!v.bounds.empty()) {
      b.extend(v.bounds.lo);
      b.extend(v.bounds.hi);
    }
  return b;
}

size_t Scene::closed_triangle_count() const {
  size_t n = 0;
  for (auto& m : meshes) n += m.closed ? m.triangle_count : 0;
  return n;
}

bool Scene::any_partial() const {
  if (!volumes.empty()) return true;
  for (auto& m : meshes)
    if (m.partial() && m.triangle_count) return true;
  return false;
}

Scene opaque_part(const Scene& scene) {
  if (!scene.any_partial()) return scene;
  Scene out;
  out.name = scene.name;
  out.stats = scene.stats;
  out.vertices = scene.vertices;
  for (auto& m : scene.meshes) {
    if (m.partial()) continue;
    Mesh o = m;
    o.first_triangle = uint32_t(out.triangles.size());
    for (uint32_t i = 0; i < m.triangle_count; ++i)
      out.triangles.push_back(scene.triangles[m.first_triangle + i]);
    out.meshes.push_back(std::move(o));
  }
  return out;
}

bool Scene::any_closed() const {
  for (auto& m : meshes)
    if (m.closed && m.triangle_count) return true;
  return false;
}

uint64_t Scene::content_hash() const {
  // FNV-1a over the vertex bits, the indices and the closed flags: stable across runs.
  uint64_t h = 1469598103934665603ull;
  auto mix = [&](const void* p, size_t n) {
    auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  for (auto& v : vertices) mix(&v, sizeof v);
  for (auto& t : triangles) mix(t.data(), sizeof t);
  for (auto& m : meshes) {
    uint8_t c = m.closed;
    mix(&c, 1);
    mix(&m.triangle_count, sizeof m.triangle_count);
    if (m.partial()) {
      mix(m.transmit.data(), sizeof m.transmit);
      mix(&m.alpha_texture, sizeof m.alpha_texture);
    }
  }
  for (auto& uv : triangle_uv) mix(uv.data(), sizeof uv);
  for (auto& t : alpha_textures) {
    mix(&t.width, sizeof t.width);
    mix(&t.height, sizeof t.height);
    mix(&t.cutoff, sizeof t.cutoff);
    mix(t.alpha.data(), t.alpha.size());
  }
  for (auto& v : volumes) {
    mix(&v.bounds, sizeof v.bounds);
    mix(&v.nx, sizeof v.nx);
    mix(&v.ny, sizeof v.ny);
    mix(&v.nz, sizeof v.nz);
    mix(v.sigma.data(), sizeof v.sigma);
    mix(v.density.data(), v.density.size() * sizeof(float));
  }
  return h;
}

}  // namespace st

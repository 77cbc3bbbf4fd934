#include "tiles/bake/scene.hpp"

#include <cstring>

namespace st {

Aabb Scene::bounds() const {
  Aabb b;
  for (auto& t : triangles)
    for (uint32_t i : t) b.extend(vertices[i]);
  return b;
}

size_t Scene::closed_triangle_count() const {
  size_t n = 0;
  for (auto& m : meshes) n += m.closed ? m.triangle_count : 0;
  return n;
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
  }
  return h;
}

}  // namespace st

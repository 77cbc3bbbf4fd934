// A scene's triangles as the rasterizer draws them (raster.hpp): flat-shaded, 6 floats a
// corner (position, the triangle's normal), zero-area triangles dropped.
#pragma once
#include <vector>

#include "scene/scene.hpp"

namespace st::raster {

inline std::vector<float> flat_triangles(const Scene& scene) {
  std::vector<float> out;
  out.reserve(scene.triangles.size() * 18);
  for (const auto& t : scene.triangles) {
    const Vec3d p0 = scene.vertices[t[0]], p1 = scene.vertices[t[1]], p2 = scene.vertices[t[2]];
    const Vec3d c = cross(p1 - p0, p2 - p0);
    const double l = length(c);
    if (!(l > 0)) continue;
    const Vec3d n = c / l;
    for (const Vec3d& p : {p0, p1, p2})
      for (double v : {p.x, p.y, p.z, n.x, n.y, n.z}) out.push_back(float(v));
  }
  return out;
}

}  // namespace st::raster

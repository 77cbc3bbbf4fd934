#include "tiles/bake/raster_bounds.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "common/error.hpp"
#include "tiles/bake/canonical_coverage.hpp"

namespace st {

RasterBounds::RasterBounds(const Scene& scene, const LightSpace& light) : light_(light) {
  if (light.kind() != LightKind::sun)
    throw Error("raster builder: only sun lights are supported (use the tracer)");
  const Aabb b = scene.bounds();
  centre_ = b.empty() ? Vec3d{0, 0, 0}
                      : Vec3d{(b.lo.x + b.hi.x) / 2, (b.lo.y + b.hi.y) / 2, (b.lo.z + b.hi.z) / 2};
  v_.reserve(scene.vertices.size());
  for (const Vec3d& p : scene.vertices) v_.push_back(p - centre_);
  tri_ = scene.triangles;
  mesh_.assign(tri_.size(), 0);
  closed_.assign(tri_.size(), 0);
  for (uint32_t m = 0; m < scene.meshes.size(); ++m) {
    const Mesh& mesh = scene.meshes[m];
    for (uint32_t t = mesh.first_triangle; t < mesh.first_triangle + mesh.triangle_count; ++t) {
      mesh_[t] = m;
      closed_[t] = mesh.closed ? 1 : 0;
    }
  }
  box_.resize(tri_.size());
  for (size_t t = 0; t < tri_.size(); ++t) {
    std::array<double, 4> bx{INFINITY, INFINITY, -INFINITY, -INFINITY};
    for (uint32_t k = 0; k < 3; ++k) {
      const LightPoint lp = light.to_light(scene.vertices[tri_[t][k]]);
      bx[0] = std::min(bx[0], lp.u);
      bx[1] = std::min(bx[1], lp.v);
      bx[2] = std::max(bx[2], lp.u);
      bx[3] = std::max(bx[3], lp.v);
    }
    box_[t] = bx;
  }
}

Interval RasterBounds::texel(uint32_t level, uint64_t x, uint64_t y, const uint32_t* cand,
                             size_t n) const {
  const LightRay ray = light_.texel_ray(level, x, y);
  const Vec3d o = ray.origin - centre_;
  const CoverageRay r = CoverageRay::of(o, ray.dir);
  std::vector<CanonicalHit> hits;
  for (size_t k = 0; k < n; ++k) {
    const uint32_t t = cand[k];
    const Vec3d& a = v_[tri_[t][0]];
    const Vec3d& b = v_[tri_[t][1]];
    const Vec3d& c = v_[tri_[t][2]];
    const int f = canonical_cover(r, a, b, c);
    if (f == 0) continue;
    const double tp = CanonicalPlane::of(a, b, c).t(o, ray.dir, NAN);
    if (!std::isfinite(tp) || tp < 0 || tp > 1) continue;
    hits.push_back(CanonicalHit{tp, t, mesh_[t], int8_t(f), closed_[t] != 0});
  }
  std::sort(hits.begin(), hits.end());
  return canonical_depths(light_, canonical_interval(hits, 1.0));
}

Interval RasterBounds::brute_force_texel(uint32_t level, uint64_t x, uint64_t y) const {
  std::vector<uint32_t> all(tri_.size());
  for (uint32_t t = 0; t < all.size(); ++t) all[t] = t;
  return texel(level, x, y, all.data(), all.size());
}

IntervalTile RasterBounds::trace(const TraceRegion& region) const {
  DepthBoundsTracer::check_region(region);
  IntervalTile out;
  out.level = region.level;
  out.x0 = region.x0;
  out.y0 = region.y0;
  out.width = region.width;
  out.height = region.height;
  out.data.assign(size_t(region.width) * region.height, Interval{kLitDepth, kLitDepth});
  const double side = std::ldexp(1.0, int(region.level));
  const uint32_t tx = (region.width + kTile - 1) / kTile, ty = (region.height + kTile - 1) / kTile;
  // Bin: a triangle goes to every tile its box, grown by one texel, touches.
  std::vector<std::vector<uint32_t>> bins(size_t(tx) * ty);
  for (uint32_t t = 0; t < tri_.size(); ++t) {
    const auto& bx = box_[t];
    const double x0 = std::floor(bx[0] * side) - 1 - double(region.x0);
    const double y0 = std::floor(bx[1] * side) - 1 - double(region.y0);
    const double x1 = std::ceil(bx[2] * side) + 1 - double(region.x0);
    const double y1 = std::ceil(bx[3] * side) + 1 - double(region.y0);
    if (!(x1 >= 0 && y1 >= 0 && x0 < region.width && y0 < region.height)) continue;
    const uint32_t i0 = uint32_t(std::max(0.0, x0)) / kTile;
    const uint32_t j0 = uint32_t(std::max(0.0, y0)) / kTile;
    const uint32_t i1 = uint32_t(std::min(double(region.width - 1), x1)) / kTile;
    const uint32_t j1 = uint32_t(std::min(double(region.height - 1), y1)) / kTile;
    for (uint32_t j = j0; j <= j1; ++j)
      for (uint32_t i = i0; i <= i1; ++i) bins[size_t(j) * tx + i].push_back(t);
  }
  tbb::parallel_for(size_t(0), bins.size(), [&](size_t b) {
    const auto& bin = bins[b];
    if (bin.empty()) return;  // nothing in the tile's prism: lit, no per-texel work
    const uint32_t bi = uint32_t(b % tx) * kTile, bj = uint32_t(b / tx) * kTile;
    for (uint32_t j = bj; j < std::min(bj + kTile, region.height); ++j)
      for (uint32_t i = bi; i < std::min(bi + kTile, region.width); ++i)
        out.at(i, j) = texel(region.level, region.x0 + i, region.y0 + j, bin.data(), bin.size());
  });
  return out;
}

}  // namespace st

// procedural:forest and procedural:smoke — the partial occluders of the deep shadow map
// paper (DSM 2000 Figure 3 and §6): foliage whose cards cover part of a texel, and a
// volume whose extinction is ray-marched. The semi-transparent hairball is
// procedural:hairball,transmit=F (procedural_hairball.cpp).
//
// forest: keys seed (1), trees (9), leaves per tree (300), size (30, the ground side),
//   translucency (0). A ground quad at y = 0 facing +Y (opaque), per tree a closed box
//   trunk (opaque) and one open mesh of leaf cards (two triangles each, random
//   orientation, inside the crown's ball) alpha-tested through one procedural 32 x 32
//   leaf texture (an ellipse, cutoff 0.5). A solid leaf texel lets
//   (0.3, 1, 0.2) x translucency of the light through (coloured, DSM 2000 §5.2).
// smoke: keys seed (1), res (32: voxels a side), size (10), density (1), sigma (1). A
//   ground quad (3 size a side, opaque) under a plume: Gaussian puffs along a rising,
//   drifting path, widening with height, with seeded per-voxel noise; the grid spans
//   [-size/2, size/2] x [0.05 size, 1.05 size] x [-size/2, size/2].
#include <algorithm>
#include <cmath>

#include "scene/procedural.hpp"

namespace st::procedural {
namespace {

constexpr uint32_t kLeafTexels = 32;

MeshSoup ground(double side) {
  const double h = side / 2;
  MeshSoup m{"ground", {}, {}};
  const uint32_t a = add_vertex(m, {-h, 0, -h}), b = add_vertex(m, {-h, 0, h});
  const uint32_t c = add_vertex(m, {h, 0, h}), d = add_vertex(m, {h, 0, -h});
  add_quad(m, a, b, c, d);
  return m;
}

AlphaTexture leaf_texture() {
  AlphaTexture t;
  t.name = "procedural:leaf";
  t.width = t.height = kLeafTexels;
  t.alpha.resize(size_t(kLeafTexels) * kLeafTexels);
  for (uint32_t y = 0; y < kLeafTexels; ++y)
    for (uint32_t x = 0; x < kLeafTexels; ++x) {
      const double s = (x + 0.5) / kLeafTexels * 2 - 1, r = (y + 0.5) / kLeafTexels * 2 - 1;
      const double e = (s / 0.95) * (s / 0.95) + (r / 0.5) * (r / 0.5);
      // Soft edge: alpha falls from 1 to 0 across e in [0.8, 1.2]; the cutoff is at e = 1.
      const double a = std::clamp((1.2 - e) / 0.4, 0.0, 1.0);
      t.alpha[size_t(y) * kLeafTexels + x] = uint8_t(std::lround(a * 255));
    }
  return t;
}

Vec3d unit_vector(Rng& rng) {
  for (;;) {
    const Vec3d v{rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
    const double l = dot(v, v);
    if (l <= 1.0 && l > 1e-6) return v / std::sqrt(l);
  }
}

}  // namespace

std::vector<MeshSoup> make_forest(Params& p, PartialExtras& extras) {
  const uint64_t seed = static_cast<uint64_t>(p.integer("seed", 1, 0, INT64_MAX));
  const int trees = static_cast<int>(p.integer("trees", 9, 1, 10000));
  const int leaves = static_cast<int>(p.integer("leaves", 300, 1, 100000));
  const double side = p.real("size", 30.0, 4.0, 1e6);
  const float tl = float(p.real("translucency", 0.0, 0.0, 1.0));
  p.finish();

  Rng rng(seed);
  std::vector<MeshSoup> out;
  out.push_back(ground(side));
  extras.textures.push_back(leaf_texture());
  const double half = side / 2 - 2;
  for (int t = 0; t < trees; ++t) {
    const double x = rng.uniform(-half, half), z = rng.uniform(-half, half);
    const double height = rng.uniform(3, 5), crown = rng.uniform(1.5, 2.5);
    MeshSoup trunk{"trunk_" + std::to_string(t), {}, {}};
    add_box(trunk, {x - 0.15, 0, z - 0.15}, {x + 0.15, height, z + 0.15});
    out.push_back(std::move(trunk));
    MeshSoup cards{"leaves_" + std::to_string(t), {}, {}};
    cards.alpha_texture = 0;
    cards.transmit = {0.3f * tl, tl, 0.2f * tl};
    const Vec3d centre{x, height + crown * 0.6, z};
    for (int l = 0; l < leaves; ++l) {
      const Vec3d c = centre + unit_vector(rng) * (crown * std::cbrt(rng.uniform()));
      const Vec3d n = unit_vector(rng);
      // Two axes across the card, perpendicular to its normal.
      const Vec3d helper = std::fabs(n.y) < 0.9 ? Vec3d{0, 1, 0} : Vec3d{1, 0, 0};
      const Vec3d e1 = normalize(cross(n, helper)), e2 = cross(n, e1);
      const double a = rng.uniform(0.15, 0.25);
      const uint32_t v0 = add_vertex(cards, c - e1 * a - e2 * a);
      const uint32_t v1 = add_vertex(cards, c + e1 * a - e2 * a);
      const uint32_t v2 = add_vertex(cards, c + e1 * a + e2 * a);
      const uint32_t v3 = add_vertex(cards, c - e1 * a + e2 * a);
      cards.triangles.push_back({v0, v1, v2});
      cards.triangles.push_back({v0, v2, v3});
      cards.uv.push_back({Vec2f{0, 0}, Vec2f{1, 0}, Vec2f{1, 1}});
      cards.uv.push_back({Vec2f{0, 0}, Vec2f{1, 1}, Vec2f{0, 1}});
    }
    out.push_back(std::move(cards));
  }
  return out;
}

std::vector<MeshSoup> make_smoke(Params& p, PartialExtras& extras) {
  const uint64_t seed = static_cast<uint64_t>(p.integer("seed", 1, 0, INT64_MAX));
  const uint32_t res = static_cast<uint32_t>(p.integer("res", 32, 2, 256));
  const double size = p.real("size", 10.0, 1e-3, 1e6);
  const double density = p.real("density", 1.0, 0.0, 1e6);
  const float sigma = float(p.real("sigma", 1.0, 0.0, 1e6));
  p.finish();

  Rng rng(seed);
  Volume v;
  v.name = "smoke";
  v.bounds.extend({-size / 2, 0.05 * size, -size / 2});
  v.bounds.extend({size / 2, 1.05 * size, size / 2});
  v.nx = v.ny = v.nz = res;
  v.sigma = {sigma, sigma, sigma};
  // Puffs along the plume, in units of the grid ([0, 1]^3).
  struct Puff {
    Vec3d c;
    double r;
  };
  std::vector<Puff> puffs;
  Vec3d c{0.5, 0.1, 0.5};
  for (int k = 0; k < 12; ++k) {
    puffs.push_back({c, 0.08 + 0.12 * c.y});
    c = c + Vec3d{rng.uniform(-0.04, 0.06), 0.07, rng.uniform(-0.05, 0.05)};
  }
  v.density.resize(size_t(res) * res * res);
  for (uint32_t z = 0; z < res; ++z)
    for (uint32_t y = 0; y < res; ++y)
      for (uint32_t x = 0; x < res; ++x) {
        const Vec3d q{(x + 0.5) / res, (y + 0.5) / res, (z + 0.5) / res};
        double d = 0;
        for (const Puff& pf : puffs) {
          const Vec3d e = q - pf.c;
          d += std::exp(-dot(e, e) / (2 * pf.r * pf.r));
        }
        const double noise = 0.6 + 0.8 * rng.uniform();
        v.density[(size_t(z) * res + y) * res + x] = float(density * std::min(d, 1.5) * noise);
      }
  extras.volumes.push_back(std::move(v));
  std::vector<MeshSoup> out;
  out.push_back(ground(3 * size));
  return out;
}

}  // namespace st::procedural

// procedural:city — the default scene: a grid of blocks on a closed ground slab. Every
// mesh is a closed solid; together they cover the shapes that stress exit-depth tracing
// (ARCHITECTURE.md "Definitions"): boxes of many sizes, L-shapes (concave footprints),
// towers with setbacks (horizontal steps), thin walls, overhangs (balconies, a slab on
// pillars, bridges between towers), courtyards (genus-1 solids) and intersecting solids
// (balconies inside their building's mesh, bridges entering two towers).
//
// Keys: seed (default 1), size (blocks per side, default 14), block (block pitch in
// metres, default 60). Facades are split into floors (3.5 m) and window bays (about
// 4 m) so that the default reaches a few hundred thousand triangles.
#include <algorithm>
#include <cmath>

#include "scene/procedural.hpp"

namespace st::procedural {
namespace {

constexpr double kFloor = 3.5;  // storey height, metres
constexpr double kBay = 4.0;    // window bay width, metres
constexpr double kStreet = 12.0;
constexpr double kMinPlot = 8.0;  // narrowest building plot, metres

struct Rect {
  double x0, z0, x1, z1;
  double w() const { return x1 - x0; }
  double d() const { return z1 - z0; }
  Vec2 centre() const { return {(x0 + x1) / 2, (z0 + z1) / 2}; }
  std::vector<Vec2> polygon() const { return {{x0, z0}, {x1, z0}, {x1, z1}, {x0, z1}}; }
  Rect inset(double a) const { return {x0 + a, z0 + a, x1 - a, z1 - a}; }
};

class CityBuilder {
 public:
  explicit CityBuilder(uint64_t seed) : rng_(seed) {}
  std::vector<MeshSoup> meshes;

  MeshSoup& mesh(const std::string& kind) {
    meshes.push_back({kind + "_" + std::to_string(meshes.size()), {}, {}});
    return meshes.back();
  }

  int floors_for(double footprint) {
    // Mostly low and mid rise, some towers; slimmer plots get taller more rarely.
    const double r = rng_.uniform();
    if (r < 0.55) return rng_.range(2, 6);
    if (r < 0.85) return rng_.range(6, 14);
    return footprint > 200 ? rng_.range(18, 45) : rng_.range(10, 20);
  }

  // A box building with a gridded facade, sometimes with balconies (overhangs that
  // intersect the facade: still one closed mesh of several components).
  void block_building(const Rect& r) {
    const int floors = floors_for(r.w() * r.d());
    const double h = floors * kFloor;
    MeshSoup& m = mesh("building");
    add_grid_box(m, {r.x0, 0, r.z0}, {r.x1, h, r.z1}, bays(r.w()), floors, bays(r.d()));
    if (floors >= 3 && rng_.chance(0.4)) {
      const double depth = rng_.uniform(0.8, 1.6);
      const double a = r.x0 + r.w() * 0.2, b = r.x1 - r.w() * 0.2;
      for (int f = 1; f < floors; ++f) {
        const double y = f * kFloor;
        add_box(m, {a, y - 0.25, r.z0 - depth}, {b, y, r.z0 + 0.5});
      }
    }
  }

  // Concave footprint: the fan centre sits in the corner square both wings share.
  void l_building(const Rect& r) {
    const double w1 = r.w() * rng_.uniform(0.35, 0.6), d1 = r.d() * rng_.uniform(0.35, 0.6);
    std::vector<Vec2> poly = {{r.x0, r.z0},      {r.x1, r.z0},      {r.x1, r.z0 + d1},
                              {r.x0 + w1, r.z0 + d1}, {r.x0 + w1, r.z1}, {r.x0, r.z1}};
    // Mirror in x half of the time to vary the orientation; reversing the point order
    // afterwards keeps the winding counter-clockwise.
    const bool mirrored = rng_.chance(0.5);
    if (mirrored) {
      for (auto& p : poly) p.x = r.x0 + r.x1 - p.x;
      std::reverse(poly.begin(), poly.end());
    }
    const int floors = floors_for(r.w() * r.d() / 2);
    const auto ring = subdivide(poly, edge_counts(poly, kBay));
    std::vector<Ring> rings;
    for (int f = 0; f <= floors; ++f) rings.push_back({ring, f * kFloor});
    const double cx = mirrored ? r.x1 - w1 / 2 : r.x0 + w1 / 2;
    add_loft(mesh("lshape"), rings, {cx, r.z0 + d1 / 2});
  }

  // A tower whose footprint steps in at a few heights (horizontal roof rings).
  void setback_tower(const Rect& r, int floors) {
    const auto base = r.polygon();
    const auto counts = edge_counts(base, kBay);
    const Vec2 c = r.centre();
    const int levels = std::min(floors, rng_.range(2, 4));
    std::vector<Ring> rings;
    int floor = 0;
    for (int l = 0; l < levels; ++l) {
      const double shrink = 1.0 - 0.22 * l;  // every level stays around the centre
      std::vector<Vec2> poly;
      for (auto& p : base) poly.push_back({c.x + (p.x - c.x) * shrink, c.z + (p.z - c.z) * shrink});
      const auto ring = subdivide(poly, counts);
      const int top = l + 1 == levels ? floors : floor + std::max(1, floors / levels);
      for (int f = floor; f <= top; ++f) rings.push_back({ring, f * kFloor});
      floor = top;
    }
    add_loft(mesh("tower"), rings, c);
  }

  void courtyard(const Rect& r) {
    const Rect inner = r.inset(std::min(r.w(), r.d()) * rng_.uniform(0.22, 0.3));
    const auto outer_poly = r.polygon();
    const auto counts = edge_counts(outer_poly, kBay);
    const int floors = rng_.range(3, 8);
    add_courtyard(mesh("courtyard"), subdivide(outer_poly, counts), subdivide(inner.polygon(), counts),
                  0, floors * kFloor, floors);
  }

  // Two towers joined by a closed bridge slab that enters both (intersecting solids).
  void twin_towers(const Rect& r) {
    const double gap = r.w() * 0.3;
    const Rect a{r.x0, r.z0 + r.d() * 0.2, r.x0 + (r.w() - gap) / 2, r.z1 - r.d() * 0.2};
    const Rect b{r.x1 - (r.w() - gap) / 2, a.z0, r.x1, a.z1};
    const int floors = rng_.range(16, 40);
    setback_tower(a, floors);
    setback_tower(b, floors);
    const double y = kFloor * rng_.range(6, floors / 2 + 4);
    const Vec2 c = r.centre();
    const double half = std::min(a.d(), b.d()) * 0.15;
    MeshSoup& bridge = mesh("bridge");
    add_grid_box(bridge, {a.x1 - 2, y, c.z - half}, {b.x0 + 2, y + kFloor, c.z + half},
                 bays(b.x0 - a.x1), 1, 1);
  }

  // A plaza: a roof slab on pillars (overhang), a kiosk and thin walls.
  void plaza(const Rect& r) {
    MeshSoup& canopy = mesh("canopy");
    const Rect roof = r.inset(r.w() * 0.2);
    const double y = rng_.uniform(4, 8);
    add_grid_box(canopy, {roof.x0, y, roof.z0}, {roof.x1, y + 0.6, roof.z1}, bays(roof.w()), 1,
                 bays(roof.d()));
    for (double fx : {0.1, 0.9})
      for (double fz : {0.1, 0.9}) {
        const double px = roof.x0 + roof.w() * fx, pz = roof.z0 + roof.d() * fz;
        add_box(canopy, {px - 0.4, 0, pz - 0.4}, {px + 0.4, y, pz + 0.4});
      }
    const Vec2 c = r.centre();
    add_grid_box(mesh("kiosk"), {c.x - 2, 0, c.z - 1.5}, {c.x + 2, 3, c.z + 1.5}, 2, 1, 2);
    thin_walls(r);
  }

  // Fences 0.2 m thick along a block's edges: thinner than a texel of most maps.
  void thin_walls(const Rect& r) {
    MeshSoup& m = mesh("wall");
    const double t = 0.2, h = rng_.uniform(1.5, 3.0);
    add_grid_box(m, {r.x0, 0, r.z0}, {r.x1, h, r.z0 + t}, bays(r.w()), 1, 1);
    add_grid_box(m, {r.x0, 0, r.z1 - t}, {r.x1, h, r.z1}, bays(r.w()), 1, 1);
  }

  void plots(const Rect& r) {
    const double gap = rng_.uniform(2, 5);
    // Plots at least kMinPlot wide, so small blocks never produce inverted boxes.
    auto most = [&](double len) { return std::clamp(static_cast<int>((len + gap) / (kMinPlot + gap)), 1, 3); };
    const int nx = rng_.range(1, most(r.w())), nz = rng_.range(1, most(r.d()));
    for (int i = 0; i < nx; ++i)
      for (int k = 0; k < nz; ++k) {
        const Rect p{r.x0 + r.w() * i / nx + (i ? gap / 2 : 0), r.z0 + r.d() * k / nz + (k ? gap / 2 : 0),
                     r.x0 + r.w() * (i + 1) / nx - (i + 1 < nx ? gap / 2 : 0),
                     r.z0 + r.d() * (k + 1) / nz - (k + 1 < nz ? gap / 2 : 0)};
        const double pick = rng_.uniform();
        if (pick < 0.55)
          block_building(p);
        else if (pick < 0.8)
          l_building(p);
        else
          setback_tower(p, floors_for(p.w() * p.d()));
      }
  }

  void block(const Rect& r) {
    const double pick = rng_.uniform();
    if (pick < 0.6)
      plots(r);
    else if (pick < 0.75)
      courtyard(r);
    else if (pick < 0.87)
      twin_towers(r);
    else
      plaza(r);
  }

 private:
  static int bays(double length) { return std::max(1, static_cast<int>(std::lround(length / kBay))); }
  Rng rng_;
};

}  // namespace

std::vector<MeshSoup> make_city(Params& p) {
  const uint64_t seed = static_cast<uint64_t>(p.integer("seed", 1, 0, INT64_MAX));
  const int size = static_cast<int>(p.integer("size", 14, 1, 256));
  const double pitch = p.real("block", 60.0, 30.0, 1000.0);
  p.finish();

  CityBuilder city(seed);
  const double half = size * pitch / 2;
  MeshSoup& ground = city.mesh("ground");
  add_box(ground, {-half - 10, -3, -half - 10}, {half + 10, 0, half + 10});
  for (int bx = 0; bx < size; ++bx)
    for (int bz = 0; bz < size; ++bz) {
      const double x0 = -half + bx * pitch + kStreet / 2, z0 = -half + bz * pitch + kStreet / 2;
      city.block({x0, z0, x0 + pitch - kStreet, z0 + pitch - kStreet});
    }
  return std::move(city.meshes);
}

}  // namespace st::procedural

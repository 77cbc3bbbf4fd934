// procedural:hairball — the stress case: many thin closed tubes winding randomly through
// a 10 m cube, crossing each other everywhere, so that texels see long runs of entries
// and exits (deep exit-depth loops) and the BVH has heavily overlapping boxes.
//
// Keys: seed (default 1), count (tubes, default 256), segments (steps per tube, default
// 96), sides (cross-section polygon, default 6). Each tube is its own closed mesh of
// 2 sides (segments + 1) triangles. transmit (default 0: opaque) makes every tube a
// partial occluder letting that fraction of the light through at each crossing (grey):
// the semi-transparent hair of the deep shadow map paper (DSM 2000 §6).
#include <cmath>

#include "scene/procedural.hpp"

namespace st::procedural {
namespace {

constexpr double kHalf = 5.0;   // the volume is [-5, 5]^3
constexpr double kStep = 0.12;  // path step, metres
// Direction jitter per step: turning radius >= kStep / kJitter ~ 0.34 m, several times
// the thickest tube, so a tube never folds through itself.
constexpr double kJitter = 0.35;

Vec3d random_in_ball(Rng& rng) {
  for (;;) {
    Vec3d v{rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)};
    const double l = dot(v, v);
    if (l <= 1.0 && l > 1e-6) return v;
  }
}

}  // namespace

std::vector<MeshSoup> make_hairball(Params& p) {
  const uint64_t seed = static_cast<uint64_t>(p.integer("seed", 1, 0, INT64_MAX));
  const int count = static_cast<int>(p.integer("count", 256, 1, 100000));
  const int segments = static_cast<int>(p.integer("segments", 96, 1, 100000));
  const int sides = static_cast<int>(p.integer("sides", 6, 3, 64));
  const float transmit = float(p.real("transmit", 0.0, 0.0, 1.0));
  p.finish();

  Rng rng(seed);
  std::vector<MeshSoup> out;
  out.reserve(count);
  for (int t = 0; t < count; ++t) {
    Vec3d pos{rng.uniform(-0.8, 0.8) * kHalf, rng.uniform(-0.8, 0.8) * kHalf,
              rng.uniform(-0.8, 0.8) * kHalf};
    Vec3d dir = normalize(random_in_ball(rng));
    std::vector<Vec3d> path{pos};
    for (int s = 0; s < segments; ++s) {
      Vec3d d = dir + random_in_ball(rng) * kJitter;
      // Near the walls, steer back towards the centre (smoothly, never a hairpin).
      if (length(pos) > 0.8 * kHalf) d = d - normalize(pos) * (0.5 * kJitter);
      dir = normalize(d);
      pos = pos + dir * kStep;
      path.push_back(pos);
    }
    const double radius = rng.uniform(0.02, 0.06);
    out.push_back({"tube_" + std::to_string(t), {}, {}});
    add_tube(out.back(), path, radius, sides);
    out.back().transmit = {transmit, transmit, transmit};
  }
  return out;
}

}  // namespace st::procedural

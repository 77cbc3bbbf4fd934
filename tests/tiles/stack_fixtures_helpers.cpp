#include <algorithm>
#include <cstdlib>

#include "common/hash.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "scene/scene.hpp"
#include "tiles/bake/stack_build.hpp"

namespace st::stacks {

IntervalStack random_stack(uint32_t level, uint32_t slices, uint64_t seed) {
  IntervalStack s{level, slices, {}};
  s.data.resize(size_t(s.side() * s.side()) * slices);
  Rng rng(seed);
  for (Interval& iv : s.data) {
    const double r = rng.uniform();
    const float a = float(rng.uniform()), b = float(rng.uniform());
    if (r < 0.1) iv = {1.0f, 1.0f};
    else if (r < 0.4) iv = {a, a};
    else iv = {std::min(a, b), std::max(a, b)};
  }
  return s;
}

IntervalStack coherent_stack(uint32_t level, uint32_t slices, uint64_t seed) {
  IntervalStack s{level, slices, {}};
  const double side = double(s.side());
  s.data.assign(size_t(s.side() * s.side()) * slices, Interval{0.8f, 0.8f});  // the ground, open
  Rng rng(seed);
  struct Box { double x0, y0, x1, y1; float top, bottom; double drift; };
  std::vector<Box> boxes;
  for (int i = 0; i < 6; ++i) {
    const double x = rng.uniform(0, 0.8) * side, y = rng.uniform(0, 0.8) * side;
    const float top = float(rng.uniform(0.2, 0.6));
    boxes.push_back({x, y, x + rng.uniform(0.05, 0.2) * side, y + rng.uniform(0.05, 0.2) * side, top,
                     top + float(rng.uniform(0.05, 0.15)), rng.uniform(0.1, 0.5)});
  }
  for (uint32_t w = 0; w < slices; ++w)
    for (const Box& b : boxes) {
      const double shift = b.drift * w;  // the shadow slides a fraction of a texel per slice
      for (uint64_t y = uint64_t(std::max(0.0, b.y0)); y < std::min<uint64_t>(s.side(), uint64_t(b.y1)); ++y)
        for (uint64_t x = uint64_t(std::max(0.0, b.x0 + shift)); x < std::min<uint64_t>(s.side(), uint64_t(b.x1 + shift)); ++x) {
          Interval& iv = s.at(x, y, w);
          if (b.top < iv.lo) iv = {b.top, b.bottom};
        }
    }
  return s;
}

LightSet fitted_set(const std::string& scene, const std::string& light_set) {
  return fit_light_set(load_scene(scene), LightSetSpec::parse(light_set));  // as a stack build fits
}

IntervalStack traced_stack(const std::string& scene_spec, const LightSet& set, uint32_t level) {
  const Scene scene = load_scene(scene_spec);
  IntervalStack s{level, set.size(), {}};
  s.data.reserve(size_t(s.side() * s.side()) * set.size());
  for (uint32_t w = 0; w < set.size(); ++w) {
    DepthBoundsTracer tracer(scene, set.samples[w]);
    const IntervalTile t = tracer.trace({level, 0, 0, uint32_t(s.side()), uint32_t(s.side())});
    s.data.insert(s.data.end(), t.data.begin(), t.data.end());
  }
  return s;
}

IntervalTile slice(const IntervalStack& s, uint32_t w) {
  IntervalTile t;
  t.level = s.level;
  t.width = t.height = uint32_t(s.side());
  const size_t area = size_t(s.side() * s.side());
  t.data.assign(s.data.begin() + ptrdiff_t(w * area), s.data.begin() + ptrdiff_t((w + 1) * area));
  return t;
}

bool small_scale() {
  const char* v = std::getenv("SHADOWTILE_TEST_SCALE");
  return v && std::string(v) == "small";
}

}  // namespace st::stacks

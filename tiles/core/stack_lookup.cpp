#include "tiles/core/stack_lookup.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "common/error.hpp"

namespace st {
namespace {

// Per-thread working set of one soft_visibility call: each sample's texel and receiver
// depth, and the sample order the shared walk partitions by child slot.
struct Scratch {
  uint32_t x[kMaxLightSamples], y[kMaxLightSamples];
  float r[kMaxLightSamples];
  uint16_t idx[kMaxLightSamples], tmp[kMaxLightSamples];
  uint64_t visited = 0;
};
thread_local Scratch t_scratch;

static_assert(kMaxLightSamples <= 65536, "sample indices are 16-bit");

uint32_t count_lit(const Scratch& s, uint32_t b, uint32_t e, float v) {
  uint32_t lit = 0;
  for (uint32_t i = b; i < e; ++i) lit += s.r[s.idx[i]] <= v;
  return lit;
}

// Samples idx[b..e) all lie under cursor c. Split them by the child slot each one's path
// takes; a slot without a child, or a leaf, answers its samples with the value in force.
uint32_t shared_walk(const MhOctree& t, const MhOctree::Cursor& c, Scratch& s, uint32_t b, uint32_t e) {
  ++s.visited;
  const moct::Geometry& g = t.geometry();
  if (c.code == moct::kCodeLeaf || c.level == g.depth()) return count_lit(s, b, e, t.value(c));
  const uint32_t l = c.level;
  const bool sxy = g.splits_xy(l), sw = g.splits_w(l);
  const uint32_t bxy = sxy ? g.n - g.xy_bits(l + 1) : 0, bw = sw ? g.k - g.w_bits(l + 1) : 0;
  auto slot = [&](uint32_t w) {
    uint32_t sl = sxy ? ((s.x[w] >> bxy) & 1u) | ((s.y[w] >> bxy) & 1u) << 1 : 0u;
    return sw ? sl | ((w >> bw) & 1u) << 2 : sl;
  };
  if (e - b == 1) {  // one sample left: its own walk, without partitioning
    const uint32_t w = s.idx[b];
    MhOctree::Cursor cur = c, next;
    while (cur.code != moct::kCodeLeaf && cur.level < g.depth()) {
      const uint32_t cl = cur.level;
      const uint32_t bb = g.splits_xy(cl) ? g.n - g.xy_bits(cl + 1) : 0;
      uint32_t sl = g.splits_xy(cl) ? ((s.x[w] >> bb) & 1u) | ((s.y[w] >> bb) & 1u) << 1 : 0u;
      if (g.splits_w(cl)) sl |= ((w >> (g.k - g.w_bits(cl + 1))) & 1u) << 2;
      if (!t.child(cur, sl, next)) break;
      cur = next;
      ++s.visited;
    }
    return s.r[w] <= t.value(cur) ? 1u : 0u;
  }
  uint32_t count[moct::kSlots] = {};
  for (uint32_t i = b; i < e; ++i) ++count[slot(s.idx[i])];
  uint32_t start[moct::kSlots], at = b;
  for (uint32_t c8 = 0; c8 < moct::kSlots; ++c8) start[c8] = at, at += count[c8];
  if (count[slot(s.idx[b])] != e - b) {  // more than one slot: partition (stable)
    uint32_t put[moct::kSlots];
    std::copy(start, start + moct::kSlots, put);
    for (uint32_t i = b; i < e; ++i) s.tmp[put[slot(s.idx[i])]++] = s.idx[i];
    std::copy(s.tmp + b, s.tmp + e, s.idx + b);
  }
  uint32_t lit = 0;
  for (uint32_t c8 = 0; c8 < moct::kSlots; ++c8) {
    if (!count[c8]) continue;
    MhOctree::Cursor next;
    if (t.child(c, c8, next))
      lit += shared_walk(t, next, s, start[c8], start[c8] + count[c8]);
    else
      lit += count_lit(s, start[c8], start[c8] + count[c8], t.value(c));
  }
  return lit;
}

}  // namespace

StackLookup::StackLookup(const MhOctree& octree, const LightSet& lights) : tree_(octree), lights_(lights) {
  if (lights.size() != octree.slices())
    throw Error("stack lookup: the light set has " + std::to_string(lights.size()) + " samples, the octree " +
                std::to_string(octree.slices()) + " slices");
}

bool StackLookup::lit(const Vec3d& p, uint32_t w) const noexcept {
  if (w >= tree_.slices()) return true;
  const LightPoint lp = lights_.samples[w].to_light(p);
  const auto t = LightSpace::texel_of(tree_.xy_level(), lp.u, lp.v);
  return float(lp.d) <= tree_.depth(t[0], t[1], w, tree_.xy_level());
}

float StackLookup::visibility(const Vec3d& p, double time) const noexcept {
  const uint32_t n = tree_.slices();
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(n - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) return lit(p, uint32_t(near)) ? 1.0f : 0.0f;
  const uint32_t a = uint32_t(std::floor(s));
  const float f = float(s - double(a));
  const float la = lit(p, a) ? 1.0f : 0.0f, lb = lit(p, a + 1) ? 1.0f : 0.0f;
  return la + f * (lb - la);
}

float StackLookup::soft_visibility(const Vec3d& p) const noexcept {
  Scratch& s = t_scratch;
  const uint32_t n = tree_.slices(), level = tree_.xy_level();
  for (uint32_t w = 0; w < n; ++w) {
    const LightPoint lp = lights_.samples[w].to_light(p);
    const auto t = LightSpace::texel_of(level, lp.u, lp.v);
    s.x[w] = uint32_t(t[0]), s.y[w] = uint32_t(t[1]), s.r[w] = float(lp.d), s.idx[w] = uint16_t(w);
  }
  s.visited = 0;
  const uint32_t lit = shared_walk(tree_, tree_.root(), s, 0, n);
  return float(lit) / float(n);
}

float StackLookup::soft_visibility_independent(const Vec3d& p) const noexcept {
  uint32_t lit_samples = 0;
  for (uint32_t w = 0; w < tree_.slices(); ++w) lit_samples += lit(p, w);
  return float(lit_samples) / float(tree_.slices());
}

uint64_t StackLookup::last_nodes_visited() noexcept { return t_scratch.visited; }

}  // namespace st

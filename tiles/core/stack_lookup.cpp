#include "tiles/core/stack_lookup.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

#include "common/error.hpp"
#include "tiles/core/walk_interleave.hpp"

namespace st {
namespace {

thread_local uint64_t t_visited = 0, t_prefetched = 0;

}  // namespace

namespace {

// Bounds of the values stored in a node's subtree (its own if valued, and every value
// below), once per stored node: a node reached twice (a shared block) has one answer, so
// the walk is linear in the tree's words whatever the sharing.
StackBounds::Range fill_bounds(const MhOctree& t, const MhOctree::Cursor& c, std::vector<StackBounds::Range>& out,
                               std::vector<uint8_t>& done) {
  if (done[c.pos]) return out[c.pos];
  StackBounds::Range r{std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};
  if (c.code != moct::kCodeEmpty) r.lo = r.hi = t.value(c);
  MhOctree::Cursor ch;
  for (uint32_t slot = 0; slot < moct::kSlots; ++slot)
    if (t.child(c, slot, ch)) {
      const StackBounds::Range b = fill_bounds(t, ch, out, done);
      r.lo = std::min(r.lo, b.lo), r.hi = std::max(r.hi, b.hi);
    }
  out[c.pos] = r;
  done[c.pos] = 1;
  return r;
}

}  // namespace

StackBounds::StackBounds(const MhOctree& octree) {
  const size_t words = (octree.byte_size() - moct::tree_offset(octree.geometry().levels())) / 4;
  range_.assign(std::max<size_t>(words, 1), {});
  std::vector<uint8_t> done(range_.size(), 0);
  fill_bounds(octree, octree.root(), range_, done);  // recursion depth <= kMaxLevels
}

StackLookup::StackLookup(const MhOctree& octree, const LightSet& lights)
    : tree_(octree), lights_(lights), texels_(lights.samples, octree.xy_level()) {
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
  // The samples' texels a run at a time (SampleTexels: to_light and texel_of of every
  // sample, bit for bit), then the shared walk sample after sample. A ground-frame sun
  // path's receiver on the ground reads one (x, y) in every slice, so consecutive walks
  // share all but the w steps, and a leaf that answers for a run of slices answers them
  // without a step.
  const uint32_t n = tree_.slices();
  MhOctree::Path path;
  SampleTexels::Run run;
  uint32_t lit_samples = 0;
  for (uint32_t w0 = 0; w0 < n; w0 += SampleTexels::kRun) {
    const uint32_t m = std::min(SampleTexels::kRun, n - w0);
    texels_.run(p, w0, m, run);
    for (uint32_t i = 0; i < m; ++i) lit_samples += run.d[i] <= tree_.depth_along(path, run.x[i], run.y[i], w0 + i);
  }
  t_visited = path.steps + 1;  // and the root
  return float(lit_samples) / float(n);
}

void StackLookup::soft_visibility(std::span<const Vec3d> points, std::span<float> out) const noexcept {
  const uint32_t n = tree_.slices();
  struct Lane {
    MhOctree::Path path;
    MhOctree::Walk walk;
    SampleTexels::Run run;  // samples w - w % kRun onward
    size_t i = 0;
    uint32_t w = 0, lit = 0;
    bool walking = false;
  };
  uint64_t visited = 0, prefetched = 0;
  auto start = [&](Lane& ln, size_t i) {
    ln.path.valid = false;
    ln.path.steps = 0;
    ln.i = i, ln.w = 0, ln.lit = 0, ln.walking = false;
  };
  // One point's soft_visibility (the loop above) as a resumable job: each sample begins a
  // shared walk, and a step into a node on another cache line prefetches it and yields.
  auto run = [&](Lane& ln) {
    // The lane's scalars live in registers while it runs and go back at a yield.
    MhOctree::Path& path = ln.path;
    uint32_t w = ln.w, lit = ln.lit;
    bool walking = ln.walking;
    MhOctree::Walk k = ln.walk;
    for (;;) {
      if (walking) {
        if (step_until_new_line(tree_, path, k)) {
          ++prefetched;
          ln.w = w, ln.lit = lit, ln.walking = true, ln.walk = k;
          return true;
        }
        lit += ln.run.d[w % SampleTexels::kRun] <= tree_.along_value(k);
        ++w;
      }
      if (w == n) {
        out[ln.i] = float(lit) / float(n);
        visited += path.steps + 1;
        return false;
      }
      const uint32_t j = w % SampleTexels::kRun;
      if (j == 0) texels_.run(points[ln.i], w, std::min(SampleTexels::kRun, n - w), ln.run);
      k = tree_.along_begin(path, ln.run.x[j], ln.run.y[j], w);
      walking = true;
    }
  };
  run_interleaved<Lane>(std::min(points.size(), out.size()), start, run);
  t_visited = visited;
  t_prefetched = prefetched;
}

float StackLookup::soft_visibility_independent(const Vec3d& p) const noexcept {
  uint32_t lit_samples = 0;
  for (uint32_t w = 0; w < tree_.slices(); ++w) lit_samples += lit(p, w);
  return float(lit_samples) / float(tree_.slices());
}

float StackLookup::soft_visibility_bounded(const Vec3d& p, const StackBounds& bounds) const noexcept {
  const moct::Geometry& g = tree_.geometry();
  const uint32_t n = tree_.slices(), L = g.depth();
  uint32_t lit_samples = 0;
  uint64_t steps = 0;
  for (uint32_t w = 0; w < n; ++w) {
    const LightPoint lp = lights_.samples[w].to_light(p);
    const auto t = LightSpace::texel_of(g.n, lp.u, lp.v);
    const float d = float(lp.d);
    MhOctree::Cursor c = tree_.root(), next;
    for (;;) {
      StackBounds::Range r = bounds.at(c.pos);
      if (c.code == moct::kCodeEmpty) {  // its texels may read the inherited value
        const float v = tree_.value(c);
        r.lo = std::min(r.lo, v), r.hi = std::max(r.hi, v);
      }
      if (d <= r.lo) {
        ++lit_samples;
        break;
      }
      if (d > r.hi) break;
      uint32_t slot = 0;
      if (c.level < L) {
        if (g.splits_xy(c.level)) {
          const uint32_t b = g.n - g.xy_bits(c.level + 1);
          slot = uint32_t((t[0] >> b) & 1) | uint32_t((t[1] >> b) & 1) << 1;
        }
        if (g.splits_w(c.level)) slot |= uint32_t((w >> (g.k - g.w_bits(c.level + 1))) & 1) << 2;
      }
      if (c.level >= L || !tree_.child(c, slot, next)) {
        lit_samples += d <= tree_.value(c);
        break;
      }
      c = next;
      ++steps;
    }
  }
  t_visited = steps + n;
  return float(lit_samples) / float(n);
}

uint64_t StackLookup::last_nodes_visited() noexcept { return t_visited; }
uint64_t StackLookup::last_lines_prefetched() noexcept { return t_prefetched; }

}  // namespace st

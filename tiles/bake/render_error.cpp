#include "tiles/bake/render_error.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <chrono>
#include <cmath>

#include "common/error.hpp"

namespace st {

FrameTruth make_frame_truth(const SceneTracer& tracer, const Camera& camera, uint32_t width, uint32_t height,
                            uint32_t map_level, const std::vector<uint32_t>& pcf_radii) {
  FrameTruth f;
  f.camera = camera;
  f.width = width, f.height = height;
  f.receivers = tracer.primary(camera, width, height);
  for (uint32_t i = 0; i < f.receivers.size(); ++i)
    if (f.receivers[i].hit && f.receivers[i].n_dot_l > 0) f.lit_facing.push_back(i);
  const size_t n = f.lit_facing.size();
  f.traced.assign(n, 0);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1024), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) f.traced[i] = tracer.traced(f.receivers[f.lit_facing[i]]);
  });
  const LightSpace& light = tracer.light();
  uint32_t max_r = 0;
  for (uint32_t r : pcf_radii) max_r = std::max(max_r, r);
  f.pcf_truth.resize(max_r);
  for (uint32_t radius : pcf_radii) {
    if (radius == 0) continue;
    if (radius > 4) throw Error("report: PCF radius must be at most 4");
    auto& out = f.pcf_truth[radius - 1];
    out.assign(n, 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const Receiver& rec = f.receivers[f.lit_facing[i]];
        // World size of a finest texel at the receiver (a spot's texels grow with distance).
        const double texel = (light.kind() == LightKind::sun ? light.extent_uv()
                                                               : length(rec.pos - light.origin()) * light.extent_uv()) /
                             std::ldexp(1.0, int(map_level));
        double sum = 0;
        int count = 0;
        const int k = int(radius);
        for (int ty = -k; ty <= k; ++ty)
          for (int tx = -k; tx <= k; ++tx)
            for (int s = 0; s < 4; ++s) {
              const double du = tx + ((s & 1) ? 0.25 : -0.25), dv = ty + ((s & 2) ? 0.25 : -0.25);
              // Across the light's u/v, then along the light ray back onto the receiver's
              // tangent plane: the surface the kernel's footprint covers.
              const Vec3d off = light.axis_u() * (du * texel) + light.axis_v() * (dv * texel);
              const Vec3d ldir = tracer.to_light(rec.pos);
              const double t = -dot(off, rec.normal) / dot(ldir, rec.normal);
              sum += tracer.traced(rec, off + ldir * t);
              ++count;
            }
        out[i] = float(sum / count);
      }
    });
  }
  return f;
}

FrameError frame_error(const Evaluator& eval, const LightSpace& light, const FrameTruth& f, uint32_t pcf_radius,
                       uint32_t level) {
  FrameError e;
  e.receivers = f.lit_facing.size();
  std::vector<float> vis(e.receivers);
  const auto t0 = std::chrono::steady_clock::now();
  for (size_t i = 0; i < vis.size(); ++i)
    vis[i] = map_visibility(eval, f.receivers[f.lit_facing[i]], light, pcf_radius, level);
  e.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (pcf_radius == 0) {
    for (size_t i = 0; i < vis.size(); ++i) e.differing += (vis[i] >= 0.5f) != (f.traced[i] >= 0.5f);
  } else {
    if (pcf_radius > f.pcf_truth.size() || f.pcf_truth[pcf_radius - 1].empty())
      throw Error("report: no PCF reference for radius " + std::to_string(pcf_radius));
    const auto& ref = f.pcf_truth[pcf_radius - 1];
    double sum = 0;
    for (size_t i = 0; i < vis.size(); ++i) sum += std::fabs(double(vis[i]) - double(ref[i]));
    e.mean_abs = vis.empty() ? 0 : sum / double(vis.size());
  }
  return e;
}

Disagreements count_disagreements(const Evaluator& a, const FlatMapEvaluator& full, const LightSpace& light,
                                  const FrameTruth& f) {
  Disagreements n;
  const uint32_t L = full.finest_level();
  for (uint32_t i : f.lit_facing) {
    const Receiver& r = f.receivers[i];
    if (map_visibility(a, r, light, 0, a.finest_level()) == map_visibility(full, r, light, 0, L)) continue;
    ++n.total;
    // The same lookup as map_visibility's: which texel, at which depth.
    const LightPoint lp = lookup_point(r, light, L, 0);
    const auto [x, y] = LightSpace::texel_of(L, lp.u, lp.v);
    const Interval* iv = full.interval(x, y);
    const float d = float(lp.d);
    if (iv && iv->lo < d && d <= iv->hi) ++n.within_interval;
  }
  return n;
}

FlatMapEvaluator::FlatMapEvaluator(const IntervalTile& tile, bool keep_intervals) : level_(tile.level) {
  const uint64_t side = uint64_t(1) << tile.level;
  if (tile.x0 != 0 || tile.y0 != 0 || tile.width != side || tile.height != side)
    throw Error("FlatMapEvaluator: needs the whole level-" + std::to_string(tile.level) + " map");
  values_.resize(tile.data.size());
  for (size_t i = 0; i < values_.size(); ++i) {
    const Interval& iv = tile.data[i];
    // Midpoint in double then float: lo <= v <= hi still holds after rounding.
    float v = float((double(iv.lo) + double(iv.hi)) / 2);
    values_[i] = std::clamp(v, iv.lo, iv.hi);
  }
  if (keep_intervals) intervals_ = tile.data;
}

float FlatMapEvaluator::depth(uint32_t level, uint64_t x, uint64_t y) const {
  const uint32_t s = level_ - std::min(level, level_);
  return values_[((y << s) << level_) + (x << s)];
}

}  // namespace st

#include "render/render_error.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "common/error.hpp"
#include "tiles/core/vsdag_format.hpp"

namespace st {

namespace {

// Mean ray-traced visibility over a square of `side` finest-level texels around the
// receiver, n x n samples at the centres of an even grid: across the light's u/v axes,
// then along the light ray back onto the receiver's tangent plane, so each ray samples
// the lit fraction of the surface the square covers.
float supersampled(const SceneTracer& tracer, const Receiver& rec, uint32_t map_level, double side, uint32_t n) {
  const LightSpace& light = tracer.light();
  // World size of a finest texel at the receiver (a spot's texels grow with distance).
  const double texel = light.texel_size(rec.pos, map_level);
  const Vec3d ldir = tracer.to_light(rec.pos);
  const double ln = dot(ldir, rec.normal);
  double sum = 0;
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) {
      const double du = side * ((i + 0.5) / n - 0.5), dv = side * ((j + 0.5) / n - 0.5);
      const Vec3d off = light.axis_u() * (du * texel) + light.axis_v() * (dv * texel);
      const double t = -dot(off, rec.normal) / ln;
      sum += tracer.traced(rec, off + ldir * t);
    }
  return float(sum / double(n * n));
}

}  // namespace

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
  uint32_t max_r = 0;
  for (uint32_t r : pcf_radii) max_r = std::max(max_r, r);
  f.pcf_truth.resize(max_r);
  for (uint32_t radius : pcf_radii) {
    if (radius == 0) continue;
    if (radius > 4) throw Error("report: PCF radius must be at most 4");
    auto& out = f.pcf_truth[radius - 1];
    out.assign(n, 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i)
        out[i] = supersampled(tracer, f.receivers[f.lit_facing[i]], map_level, double(2 * radius + 1), 2 * (2 * radius + 1));
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

void add_footprint_truth(const SceneTracer& tracer, FrameTruth& f, uint32_t map_level,
                         const std::vector<uint32_t>& radii, double pixel_angle) {
  if (!(pixel_angle > 0)) throw Error("report: the pixel angle must be positive");
  const LightSpace& light = tracer.light();
  const size_t n = f.lit_facing.size();
  f.pixel_angle = pixel_angle;
  f.footprint.resize(n);
  for (size_t i = 0; i < n; ++i)
    f.footprint[i] = receiver_footprint_texels(f.receivers[f.lit_facing[i]], light, map_level, pixel_angle);
  uint32_t max_r = 0;
  for (uint32_t r : radii) max_r = std::max(max_r, r);
  if (max_r > 4) throw Error("report: PCF radius must be at most 4");
  f.footprint_truth.resize(max_r + 1);
  for (uint32_t radius : radii) {
    auto& out = f.footprint_truth[radius];
    out.assign(n, 0);
    const uint32_t k = 2 * radius + 1;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 256), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const double s = std::max(1.0, double(f.footprint[i]));
        out[i] = supersampled(tracer, f.receivers[f.lit_facing[i]], map_level, k * s, s > 1 ? 4 * k : 2 * k);
      }
    });
  }
}

FrameError footprint_error(const Evaluator& eval, const LightSpace& light, const FrameTruth& f, uint32_t radius,
                           bool hierarchical) {
  if (radius >= f.footprint_truth.size() || f.footprint_truth[radius].empty())
    throw Error("report: no footprint reference for radius " + std::to_string(radius));
  FrameError e;
  e.receivers = f.lit_facing.size();
  const auto& ref = f.footprint_truth[radius];
  // The footprint was measured in texels of the reference's level; `eval` may be coarser.
  const uint32_t L = eval.finest_level();
  double sum = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (size_t i = 0; i < e.receivers; ++i) {
    const Receiver& rec = f.receivers[f.lit_facing[i]];
    const float fp = float(receiver_footprint_texels(rec, light, L, f.pixel_angle));
    const float v = hierarchical ? map_visibility_filtered(eval, rec, light, radius, fp)
                                 : map_visibility(eval, rec, light, radius, L);
    sum += std::fabs(double(v) - double(ref[i]));
  }
  e.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  e.mean_abs = e.receivers ? sum / double(e.receivers) : 0;
  return e;
}

Disagreements count_disagreements(const Evaluator& a, const FlatMapEvaluator& full, const LightSpace& light,
                                  const FrameTruth& f, uint32_t slab_bits) {
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
    if (iv && iv->lo < d && d <= iv->hi) {
      ++n.within_interval;
    } else if (iv && slab_bits > 0) {
      // The contract's exact cases: before the slab of lo (lit), after the slab of hi
      // (shadowed); anything else is the slab of a surface.
      const double scale = double(uint64_t(1) << slab_bits);
      const int32_t rs = vsdag::receiver_slab(d, slab_bits);
      const double k = rs == vsdag::kReceiverLit ? -1.0 : rs == vsdag::kReceiverShadowed ? scale + 1 : double(rs);
      const double klo = std::floor(std::clamp(double(iv->lo), 0.0, 1.0) * scale),
                   khi = std::floor(std::clamp(double(iv->hi), 0.0, 1.0) * scale);
      if (!((d < iv->lo && k < klo) || (d > iv->hi && k > khi))) ++n.within_slab;
    }
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

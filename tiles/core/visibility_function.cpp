#include "tiles/core/visibility_function.hpp"

#include <algorithm>
#include <cmath>

#include "common/error.hpp"

namespace st {
namespace {

using V3 = std::array<double, 3>;

V3 value_d(const VisVertex& v) { return {v.t[0], v.t[1], v.t[2]}; }

// An average's next vertex at depth z: t clamped to [0, 1] and to the previous vertex's
// (the function never rises), its first channel alone when the average is monochrome.
void push_average_vertex(VisibilityFunction& out, float z, const V3& t) {
  VisVertex v;
  v.depth = z;
  for (int c = 0; c < 3; ++c) v.t[c] = float(std::clamp(t[c], 0.0, 1.0));
  if (!out.vertices.empty())
    for (int c = 0; c < 3; ++c) v.t[c] = std::min(v.t[c], out.vertices.back().t[c]);
  if (out.monochrome) v.t[1] = v.t[2] = v.t[0];
  out.vertices.push_back(v);
}

}  // namespace

std::array<double, 3> VisibilityFunction::eval_d(double z, bool after) const {
  const auto& vs = vertices;
  if (vs.empty()) return {1, 1, 1};
  // k: first vertex at depth >= z (before a step) or > z (after a step).
  auto it = after ? std::upper_bound(vs.begin(), vs.end(), z,
                                     [](double a, const VisVertex& b) { return a < b.depth; })
                  : std::lower_bound(vs.begin(), vs.end(), z,
                                     [](const VisVertex& a, double b) { return a.depth < b; });
  const size_t k = size_t(it - vs.begin());
  if (k == 0) return value_d(vs.front());
  if (k == vs.size()) return value_d(vs.back());
  const VisVertex& a = vs[k - 1];
  const VisVertex& b = vs[k];
  const double dz = double(b.depth) - double(a.depth);
  if (!(dz > 0)) return value_d(after ? a : b);
  const double f = std::clamp((z - double(a.depth)) / dz, 0.0, 1.0);
  V3 r;
  for (int c = 0; c < 3; ++c) r[c] = double(a.t[c]) + (double(b.t[c]) - double(a.t[c])) * f;
  return r;
}

std::array<float, 3> VisibilityFunction::eval(float z) const {
  const V3 r = eval_d(z, false);
  return {float(r[0]), float(r[1]), float(r[2])};
}

std::array<float, 3> VisibilityFunction::eval_after(float z) const {
  const V3 r = eval_d(z, true);
  return {float(r[0]), float(r[1]), float(r[2])};
}

std::string VisibilityFunction::check() const {
  for (size_t i = 0; i < vertices.size(); ++i) {
    const VisVertex& v = vertices[i];
    if (!std::isfinite(v.depth)) return "vertex " + std::to_string(i) + ": depth not finite";
    for (float t : v.t)
      if (!(t >= 0 && t <= 1))
        return "vertex " + std::to_string(i) + ": transmittance outside [0, 1]";
    if (monochrome && (v.t[1] != v.t[0] || v.t[2] != v.t[0]))
      return "vertex " + std::to_string(i) + ": channels differ in a monochrome function";
    if (i == 0) continue;
    const VisVertex& p = vertices[i - 1];
    if (v.depth < p.depth) return "vertex " + std::to_string(i) + ": depth decreases";
    for (int c = 0; c < 3; ++c)
      if (v.t[c] > p.t[c]) return "vertex " + std::to_string(i) + ": transmittance increases";
    if (i >= 2 && vertices[i - 2].depth == v.depth)
      return "vertex " + std::to_string(i) + ": more than two vertices at one depth";
  }
  return "";
}

VisibilityFunction compress(const VisibilityFunction& in, double epsilon) {
  if (!(epsilon >= 0) || !std::isfinite(epsilon))
    throw Error("deep compression: epsilon must be finite and >= 0");
  if (const std::string why = in.check(); !why.empty())
    throw Error("deep compression: input function: " + why);
  VisibilityFunction out;
  out.monochrome = in.monochrome;
  const auto& vs = in.vertices;
  if (vs.size() <= 2) {
    out.vertices = vs;
    return out;
  }
  // Keep a margin for the float rounding of emitted values (DSM 2000 §3.3 works in reals).
  const double eps = std::max(0.0, epsilon - 1e-6);
  auto emit = [&](double z, const V3& t) {
    VisVertex v;
    v.depth = float(z);
    for (int c = 0; c < 3; ++c) v.t[c] = float(std::clamp(t[c], 0.0, 1.0));
    if (!out.vertices.empty()) {
      const VisVertex& p = out.vertices.back();
      for (int c = 0; c < 3; ++c) v.t[c] = std::min(v.t[c], p.t[c]);
      if (p == v) return;
    }
    if (in.monochrome) v.t[1] = v.t[2] = v.t[0];
    out.vertices.push_back(v);
  };
  // The segment's origin (an emitted vertex) and the cone of slopes, per channel, that
  // keep the segment within eps of every input vertex since the origin (the error of
  // two piecewise-linear functions peaks at their vertices, so that suffices).
  double z0 = vs[0].depth;
  V3 t0 = value_d(vs[0]);
  emit(z0, t0);
  t0 = value_d(out.vertices.back());
  V3 lo{-INFINITY, -INFINITY, -INFINITY}, hi{0, 0, 0};
  size_t last = 0;  // last input vertex inside the current segment
  size_t j = 1;
  // Ends the segment at input vertex `last`, on the middle slope of the cone (its upper
  // bound while the cone is still open below); returns that vertex's depth.
  auto close_segment = [&] {
    const double ze = vs[last].depth;
    V3 te;
    for (int c = 0; c < 3; ++c) {
      const double s = std::isfinite(lo[c]) ? 0.5 * (lo[c] + hi[c]) : hi[c];
      te[c] = t0[c] + s * (ze - z0);
    }
    emit(ze, te);
    return ze;
  };
  while (j < vs.size()) {
    const double zj = vs[j].depth;
    const V3 tj = value_d(vs[j]);
    const double dz = zj - z0;
    bool ok = true;
    V3 nlo = lo, nhi = hi;
    for (int c = 0; c < 3; ++c) {
      const double a = std::max(tj[c] - eps, 0.0), b = std::min(tj[c] + eps, 1.0);
      if (dz > 0) {
        nlo[c] = std::max(nlo[c], (a - t0[c]) / dz);
        nhi[c] = std::min(nhi[c], (b - t0[c]) / dz);
        if (nlo[c] > nhi[c]) ok = false;
      } else if (t0[c] < a || t0[c] > b) {
        ok = false;
      }
    }
    if (ok) {
      lo = nlo, hi = nhi, last = j++;
      continue;
    }
    // Close the segment at the last feasible input vertex, or emit a step if the
    // failing vertex sits at the origin's depth.
    if (dz == 0 || last == 0 || double(vs[last].depth) == z0) {
      z0 = zj;
      emit(z0, tj);
      t0 = value_d(out.vertices.back());  // as stored (rounded, never above the last)
      lo = {-INFINITY, -INFINITY, -INFINITY}, hi = {0, 0, 0};
      last = j++;
      continue;
    }
    const double ze = close_segment();
    z0 = ze;
    t0 = value_d(out.vertices.back());
    lo = {-INFINITY, -INFINITY, -INFINITY}, hi = {0, 0, 0};
    // Re-test vertex j against the new origin (no ++j).
    last = 0;
  }
  if (last != 0) close_segment();
  return out;
}

// The checks average() and average_sweep() share; returns the weights' sum.
static double checked_weight_sum(size_t functions, std::span<const double> weights) {
  if (functions != weights.size() || functions == 0)
    throw Error("deep average: one weight per function, at least one function");
  double sum = 0;
  for (double w : weights) {
    if (!(w >= 0) || !std::isfinite(w)) throw Error("deep average: a weight is not >= 0");
    sum += w;
  }
  if (!(sum > 0)) throw Error("deep average: the weights sum to 0");
  return sum;
}

VisibilityFunction average(std::span<const VisibilityFunction* const> in,
                           std::span<const double> weights) {
  const double sum = checked_weight_sum(in.size(), weights);
  VisibilityFunction out;
  std::vector<float> depths;
  for (const VisibilityFunction* f : in) {
    out.monochrome = out.monochrome && f->monochrome;
    for (const VisVertex& v : f->vertices) depths.push_back(v.depth);
  }
  std::sort(depths.begin(), depths.end());
  depths.erase(std::unique(depths.begin(), depths.end()), depths.end());
  for (float z : depths) {
    V3 before{0, 0, 0}, after{0, 0, 0};
    for (size_t i = 0; i < in.size(); ++i) {
      const V3 b = in[i]->eval_d(z, false), a = in[i]->eval_d(z, true);
      for (int c = 0; c < 3; ++c) before[c] += b[c] * weights[i] / sum, after[c] += a[c] * weights[i] / sum;
    }
    push_average_vertex(out, z, before);
    if (after != before) push_average_vertex(out, z, after);
  }
  return out;
}

VisibilityFunction average_sweep(std::span<const VisibilityFunction* const> in,
                                 std::span<const double> weights) {
  const double sum = checked_weight_sum(in.size(), weights);
  struct Event {
    float depth;
    uint32_t k, first, last;  // function, its first and last vertex at this depth
  };
  std::vector<Event> events;
  VisibilityFunction out;
  V3 value{0, 0, 0}, slope{0, 0, 0};
  for (size_t k = 0; k < in.size(); ++k) {
    const auto& vs = in[k]->vertices;
    out.monochrome = out.monochrome && in[k]->monochrome;
    const double w = weights[k] / sum;
    const V3 v0 = vs.empty() ? V3{1, 1, 1} : value_d(vs[0]);
    for (int c = 0; c < 3; ++c) value[c] += w * v0[c];
    for (size_t i = 0; i < vs.size();) {
      size_t j = i;
      while (j + 1 < vs.size() && vs[j + 1].depth == vs[i].depth) ++j;
      events.push_back({vs[i].depth, uint32_t(k), uint32_t(i), uint32_t(j)});
      i = j + 1;
    }
  }
  std::sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    return a.depth < b.depth || (a.depth == b.depth && a.k < b.k);
  });
  auto seg_slope = [&](const std::vector<VisVertex>& vs, size_t a) {  // segment a -> a + 1
    V3 s{0, 0, 0};
    if (a + 1 >= vs.size()) return s;
    const double dz = double(vs[a + 1].depth) - double(vs[a].depth);
    if (!(dz > 0)) return s;
    for (int c = 0; c < 3; ++c) s[c] = (double(vs[a + 1].t[c]) - double(vs[a].t[c])) / dz;
    return s;
  };
  double z_prev = events.empty() ? 0.0 : double(events[0].depth);
  for (size_t e = 0; e < events.size();) {
    const float z = events[e].depth;
    for (int c = 0; c < 3; ++c) value[c] += slope[c] * (double(z) - z_prev);
    z_prev = z;
    const V3 before = value;
    for (; e < events.size() && events[e].depth == z; ++e) {
      const Event& ev = events[e];
      const auto& vs = in[ev.k]->vertices;
      const double w = weights[ev.k] / sum;
      const V3 old_s = ev.first > 0 ? seg_slope(vs, ev.first - 1) : V3{0, 0, 0};
      const V3 new_s = seg_slope(vs, ev.last);
      for (int c = 0; c < 3; ++c) {
        value[c] += w * (double(vs[ev.last].t[c]) - double(vs[ev.first].t[c]));
        slope[c] += w * (new_s[c] - old_s[c]);
      }
    }
    push_average_vertex(out, z, before);
    if (value != before) push_average_vertex(out, z, value);
  }
  return out;
}

double max_difference(const VisibilityFunction& a, const VisibilityFunction& b) {
  double worst = 0;
  auto at = [&](double z) {
    for (bool after : {false, true}) {
      const V3 x = a.eval_d(z, after), y = b.eval_d(z, after);
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::fabs(x[c] - y[c]));
    }
  };
  for (const VisVertex& v : a.vertices) at(v.depth);
  for (const VisVertex& v : b.vertices) at(v.depth);
  at(0), at(1);
  return worst;
}

}  // namespace st

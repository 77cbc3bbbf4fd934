// Visibility functions (deep shadow maps, Lokovic and Veach 2000, DSM 2000 §3.1-§3.4): the
// fraction of light, per channel, that reaches depth z along a texel's light ray.
//
// A function is a list of vertices (depth, rgb transmittance), depth nondecreasing and
// every channel nonincreasing, values in [0, 1]. Between two vertices the function is
// linear; before the first vertex it is the first vertex's value, after the last one the
// last vertex's value. A step (a surface crossing) is two vertices at one depth: the value
// before it, then the value after it. A receiver exactly at a step's depth sees the value
// BEFORE the step (eval()), consistent with the opaque lit test `r <= v`: a surface does
// not shadow itself. eval_after() is the limit from the right (the value just behind).
//
// Depths are the light-space depth d in [0, 1] (light.hpp), stored as float.
// `monochrome` (DSM 2000 §5.2): every vertex has equal channels; storage keeps one.
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace st {

struct VisVertex {
  float depth = 0;
  std::array<float, 3> t{1, 1, 1};
  constexpr bool operator==(const VisVertex&) const = default;
};

struct VisibilityFunction {
  std::vector<VisVertex> vertices;  // empty: fully lit everywhere (transmittance 1)
  bool monochrome = true;

  // Transmittance at a receiver at depth z (before a step at exactly z).
  std::array<float, 3> eval(float z) const;
  // The limit from the right at z (after a step at exactly z).
  std::array<float, 3> eval_after(float z) const;
  // Double-precision evaluation (tests and the error bound): same rules.
  std::array<double, 3> eval_d(double z, bool after = false) const;

  // What is wrong with it, or "" if nothing: depths not finite or decreasing, values
  // outside [0, 1], not finite, or increasing in depth, more than two vertices at one
  // depth, channels unequal while monochrome.
  std::string check() const;
  constexpr bool operator==(const VisibilityFunction&) const = default;
};

// The greedy simplification of DSM 2000 §3.3: the fewest-segments-first piecewise-linear
// function that stays within `epsilon` of `in` at every depth (both sides of every step),
// per channel, never increasing and within [0, 1]. Depths of the output are depths of the
// input. The bound holds to max(epsilon, 1e-6) (float rounding of the stored values).
// `in` must pass check(); epsilon must be finite and >= 0 (else st::Error).
VisibilityFunction compress(const VisibilityFunction& in, double epsilon);

// The weighted average of functions (a texel's samples, DSM 2000 §3.2, or a mip level's
// children, §3.4): exact, a vertex (two at a step) at every depth where any input has one.
// Weights are >= 0 and sum to > 0 (normalised here). Monochrome when every input is.
VisibilityFunction average(std::span<const VisibilityFunction* const> in,
                           std::span<const double> weights);

// The same average by the sweep of DSM 2000 §5.1: every input vertex visited once in
// depth order, the running value and slope updated per vertex (O(M log M) for M input
// vertices instead of average()'s O(M n)). Equal to average() up to rounding (1e-9).
VisibilityFunction average_sweep(std::span<const VisibilityFunction* const> in,
                                 std::span<const double> weights);

// The largest |a - b| over all depths and channels (both sides of every vertex of either).
double max_difference(const VisibilityFunction& a, const VisibilityFunction& b);

}  // namespace st

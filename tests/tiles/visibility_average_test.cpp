// The sweep average of DSM 2000 §5.1 equals the direct weighted average (average())
// on random functions: steps, linear runs, empty functions, colour, uneven weights.
#include <gtest/gtest.h>

#include <random>

#include "tiles/core/visibility_function.hpp"

namespace st {
namespace {

VisibilityFunction random_function(std::mt19937_64& rng) {
  std::uniform_real_distribution<float> u(0, 1);
  VisibilityFunction f;
  f.monochrome = rng() % 2;
  std::array<float, 3> t{1, 1, 1};
  float z = 0.2f * u(rng);
  const int k = int(rng() % 7);
  for (int i = 0; i < k; ++i) {
    z += rng() % 4 == 0 ? 0.0f : 0.1f * u(rng);  // sometimes two steps at one depth
    if (f.vertices.size() >= 2 && f.vertices.back().depth == z && f.vertices[f.vertices.size() - 2].depth == z)
      z += 0.01f;
    f.vertices.push_back({z, t});
    const float keep = 0.3f + 0.7f * u(rng);
    for (int c = 0; c < 3; ++c) t[c] *= f.monochrome ? keep : 0.3f + 0.7f * u(rng);
    if (rng() % 3 == 0) z += 0.05f * u(rng);  // a linear run
    if (f.vertices.back().depth == z && f.vertices.size() >= 2 &&
        f.vertices[f.vertices.size() - 2].depth == z)
      z += 0.01f;
    f.vertices.push_back({z, t});
  }
  return f;
}

TEST(VisibilityAverage, SweepEqualsTheDirectAverage) {
  std::mt19937_64 rng(21);
  for (int trial = 0; trial < 200; ++trial) {
    const size_t n = 1 + rng() % 20;
    std::vector<VisibilityFunction> fs;
    std::vector<double> w;
    for (size_t i = 0; i < n; ++i) {
      fs.push_back(random_function(rng));
      ASSERT_EQ(fs.back().check(), "");
      w.push_back(trial % 2 ? 1.0 : 0.1 + double(rng() % 100));
    }
    std::vector<const VisibilityFunction*> p;
    for (auto& f : fs) p.push_back(&f);
    const VisibilityFunction a = average(p, w), b = average_sweep(p, w);
    ASSERT_EQ(b.check(), "") << trial;
    EXPECT_EQ(a.monochrome, b.monochrome);
    EXPECT_LE(max_difference(a, b), 1e-6) << trial;
  }
}

}  // namespace
}  // namespace st

// Visibility functions (DSM 2000 §3.1-§3.3): evaluation rules, averaging, and the error
// bound of the greedy compression on random and stiff functions.
#include "tiles/core/visibility_function.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "common/error.hpp"

namespace st {
namespace {

VisibilityFunction steps_function(std::mt19937_64& rng, int n, bool mono, double min_keep) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> z(n);
  for (double& d : z) d = u(rng);
  std::sort(z.begin(), z.end());
  VisibilityFunction f;
  f.monochrome = mono;
  std::array<float, 3> t{1, 1, 1};
  f.vertices.push_back({0, t});
  for (int i = 0; i < n; ++i) {
    VisVertex before{float(z[i]), t};
    for (int c = 0; c < 3; ++c) {
      const double keep = min_keep + (1 - min_keep) * u(rng);
      t[c] = float(t[c] * (mono ? (c == 0 ? keep : 1.0) : keep));
    }
    if (mono) t[1] = t[2] = t[0];
    if (u(rng) < 0.3) {
      // A linear run (a volume crossing) instead of a step.
      f.vertices.push_back(before);
      const float z1 = std::nextafter(float(z[i]), 2.0f);
      f.vertices.push_back({std::max(z1, float(z[i])), t});
    } else {
      f.vertices.push_back(before);
      f.vertices.push_back({float(z[i]), t});
    }
  }
  // At most two vertices at one depth (float rounding can merge depths): keep the
  // first and the last of each run.
  VisibilityFunction g;
  g.monochrome = mono;
  for (size_t i = 0; i < f.vertices.size(); ++i) {
    const float d = f.vertices[i].depth;
    const bool first = i == 0 || f.vertices[i - 1].depth != d;
    const bool last = i + 1 == f.vertices.size() || f.vertices[i + 1].depth != d;
    if (first || last) g.vertices.push_back(f.vertices[i]);
  }
  return g;
}

void expect_bound(const VisibilityFunction& in, double eps) {
  ASSERT_EQ(in.check(), "");
  const VisibilityFunction out = compress(in, eps);
  EXPECT_EQ(out.check(), "");
  EXPECT_LE(max_difference(in, out), std::max(eps, 1e-6)) << in.vertices.size() << " vertices";
  EXPECT_LE(out.vertices.size(), in.vertices.size());
}

TEST(VisibilityFunction, ReceiverAtAStepSeesTheValueBeforeIt) {
  VisibilityFunction f;
  f.vertices = {{0.25f, {1, 1, 1}}, {0.5f, {1, 1, 1}}, {0.5f, {0.25f, 0.25f, 0.25f}},
                {0.75f, {0, 0, 0}}};
  EXPECT_EQ(f.check(), "");
  EXPECT_EQ(f.eval(0.0f)[0], 1.0f);
  EXPECT_EQ(f.eval(0.5f)[0], 1.0f);
  EXPECT_EQ(f.eval_after(0.5f)[0], 0.25f);
  EXPECT_NEAR(f.eval(0.625f)[0], 0.125f, 1e-7);
  EXPECT_EQ(f.eval(0.75f)[0], 0.0f);
  EXPECT_EQ(f.eval(2.0f)[0], 0.0f);
  EXPECT_EQ(VisibilityFunction{}.eval(0.5f)[2], 1.0f);
}

TEST(VisibilityFunction, CheckRefusesWhatIsNotAVisibilityFunction) {
  VisibilityFunction up;
  up.vertices = {{0, {0.5f, 0.5f, 0.5f}}, {0.5f, {0.75f, 0.75f, 0.75f}}};
  EXPECT_NE(up.check(), "");
  VisibilityFunction back;
  back.vertices = {{0.5f, {1, 1, 1}}, {0.25f, {1, 1, 1}}};
  EXPECT_NE(back.check(), "");
  VisibilityFunction colour;
  colour.vertices = {{0.5f, {1, 0.5f, 1}}};
  EXPECT_NE(colour.check(), "");
  colour.monochrome = false;
  EXPECT_EQ(colour.check(), "");
  VisibilityFunction three;
  three.vertices = {{0.5f, {1, 1, 1}}, {0.5f, {0.5f, 0.5f, 0.5f}}, {0.5f, {0, 0, 0}}};
  EXPECT_NE(three.check(), "");
  VisibilityFunction nan;
  nan.vertices = {{NAN, {1, 1, 1}}};
  EXPECT_NE(nan.check(), "");
  EXPECT_THROW(compress(up, 0.01), Error);
  EXPECT_THROW(compress(VisibilityFunction{}, -1), Error);
}

TEST(VisibilityFunction, CompressionStaysWithinEpsilonOnRandomFunctions) {
  std::mt19937_64 rng(17);
  for (int i = 0; i < 300; ++i) {
    const int n = 1 + int(rng() % 60);
    const bool mono = i % 2 == 0;
    const VisibilityFunction f = steps_function(rng, n, mono, i % 3 == 0 ? 0.0 : 0.5);
    for (double eps : {0.0, 0.001, 0.01, 0.05, 0.2}) expect_bound(f, eps);
  }
}

TEST(VisibilityFunction, CompressionStaysWithinEpsilonOnStiffFunctions) {
  std::mt19937_64 rng(4);
  // Thousands of small steps (hair): the paper's case for compression.
  const VisibilityFunction hair = steps_function(rng, 4000, true, 0.99);
  for (double eps : {0.001, 0.01, 0.05}) expect_bound(hair, eps);
  EXPECT_LT(compress(hair, 0.01).vertices.size(), hair.vertices.size() / 10);
  // Near-total opacity in a thin slab: 1 -> 1e-6 over a depth of 8e-6.
  VisibilityFunction slab;
  slab.vertices = {{0.5f, {1, 1, 1}}};
  float z = 0.5f;
  for (int k = 1; k <= 64; ++k) {
    z = std::nextafter(std::nextafter(z, 1.0f), 1.0f);  // 64 vertices over ~8e-6
    const float t = float(std::exp(-13.8 * k / 64.0));
    slab.vertices.push_back({z, {t, t, t}});
  }
  for (double eps : {0.0, 0.001, 0.01}) expect_bound(slab, eps);
  // A dense volume: exp(-tau z) sampled at 5000 points, coloured extinction.
  VisibilityFunction fog;
  fog.monochrome = false;
  for (int k = 0; k <= 5000; ++k) {
    const double z = 0.2 + 0.6 * k / 5000.0;
    const double s = (z - 0.2) * 40;
    fog.vertices.push_back(
        {float(z), {float(std::exp(-s)), float(std::exp(-1.5 * s)), float(std::exp(-3 * s))}});
  }
  for (double eps : {0.0, 0.002, 0.02}) expect_bound(fog, eps);
  EXPECT_LT(compress(fog, 0.002).vertices.size(), 200u);
}

TEST(VisibilityFunction, AverageIsTheWeightedMeanEverywhere) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 50; ++i) {
    std::vector<VisibilityFunction> fs;
    std::vector<double> w;
    const int k = 1 + int(rng() % 8);
    for (int j = 0; j < k; ++j) {
      fs.push_back(steps_function(rng, 1 + int(rng() % 10), i % 2 == 0, 0.0));
      w.push_back(0.1 + u(rng));
    }
    std::vector<const VisibilityFunction*> ptr;
    double sum = 0;
    for (size_t j = 0; j < fs.size(); ++j) ptr.push_back(&fs[j]), sum += w[j];
    const VisibilityFunction avg = average(ptr, w);
    ASSERT_EQ(avg.check(), "");
    for (int s = 0; s < 40; ++s) {
      const double z = u(rng);
      for (bool after : {false, true}) {
        double want = 0;
        for (size_t j = 0; j < fs.size(); ++j) want += fs[j].eval_d(z, after)[0] * w[j] / sum;
        EXPECT_NEAR(avg.eval_d(z, after)[0], want, 1e-6);
      }
    }
  }
}

}  // namespace
}  // namespace st

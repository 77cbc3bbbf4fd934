// Partial occluders: the volume march against analytic optical depths, and the checks of
// alpha textures and volumes.
#include "scene/partial.hpp"

#include <gtest/gtest.h>

#include "common/error.hpp"

namespace st {
namespace partial_test {

Volume box(float rho, uint32_t n) {
  Volume v;
  v.name = "box";
  v.bounds.extend({0, 0, 0});
  v.bounds.extend({2, 2, 2});
  v.nx = v.ny = v.nz = n;
  v.density.assign(size_t(n) * n * n, rho);
  v.sigma = {1, 0.5f, 0.25f};
  return v;
}

TEST(Volume, ConstantDensityGivesSigmaTimesDensityTimesLength) {
  const Volume v = box(3, 8);
  v.validate();
  // A ray along x through the middle, from outside to outside: length 2 inside.
  const Rgb tau = v.optical_depth({-1, 1, 1}, {1, 0, 0}, 0, 10);
  EXPECT_NEAR(tau[0], 3 * 1.0 * 2, 1e-4);
  EXPECT_NEAR(tau[1], 3 * 0.5 * 2, 1e-4);
  EXPECT_NEAR(tau[2], 3 * 0.25 * 2, 1e-4);
  // march() ends where optical_depth() does, steps at most half a voxel apart.
  std::vector<Volume::Step> steps;
  v.march({-1, 1, 1}, {1, 0, 0}, 0, 10, steps);
  ASSERT_GE(steps.size(), 2u);
  EXPECT_DOUBLE_EQ(steps.front().t, 1);
  EXPECT_DOUBLE_EQ(steps.back().t, 3);
  EXPECT_EQ(steps.back().tau, tau);
  for (size_t i = 1; i < steps.size(); ++i) EXPECT_LE(steps[i].t - steps[i - 1].t, 0.125 + 1e-12);
  // A ray that misses the box sees nothing.
  v.march({-1, 5, 1}, {1, 0, 0}, 0, 10, steps);
  EXPECT_TRUE(steps.empty());
  EXPECT_EQ(v.optical_depth({-1, 5, 1}, {1, 0, 0}, 0, 10), (Rgb{0, 0, 0}));
}

TEST(Volume, DensityIsTrilinearBetweenVoxelCentresAndZeroOutside) {
  Volume v = box(0, 2);
  v.density[1] = 8;  // voxel (1, 0, 0), centre (1.5, 0.5, 0.5)
  EXPECT_FLOAT_EQ(v.density_at({1.5, 0.5, 0.5}), 8);
  EXPECT_FLOAT_EQ(v.density_at({1.0, 0.5, 0.5}), 4);
  EXPECT_FLOAT_EQ(v.density_at({0.5, 0.5, 0.5}), 0);
  EXPECT_FLOAT_EQ(v.density_at({2.5, 0.5, 0.5}), 0);
}

TEST(Volume, ValidateNamesWhatIsWrong) {
  Volume v = box(1, 2);
  v.density.pop_back();
  EXPECT_THROW(v.validate(), Error);
  v = box(1, 2);
  v.density[3] = -1;
  EXPECT_THROW(v.validate(), Error);
  v = box(1, 2);
  v.bounds = {};
  EXPECT_THROW(v.validate(), Error);
}

TEST(AlphaTexture, WrapsAndChecksItsSize) {
  AlphaTexture t;
  t.name = "leaf";
  t.width = 2;
  t.height = 1;
  t.alpha = {255, 0};
  t.validate();
  EXPECT_TRUE(t.solid(0.25f, 0.5f));
  EXPECT_FALSE(t.solid(0.75f, 0.5f));
  EXPECT_TRUE(t.solid(1.25f, 0.5f));   // wrapped
  EXPECT_TRUE(t.solid(-0.75f, 0.5f));  // wrapped from below
  EXPECT_FALSE(t.solid(NAN, 0.5f));
  t.alpha.push_back(7);
  EXPECT_THROW(t.validate(), Error);
  t.alpha.pop_back();
  t.cutoff = 2;
  EXPECT_THROW(t.validate(), Error);
}

}  // namespace partial_test
}  // namespace st

// Per-texel visibility functions (DSM 2000 §3.1-§3.3): thin slabs give the analytic
// steps, an alpha texture covers what it says, a constant-density volume gives
// exp(-sigma rho length), and compression stays within epsilon on every texel.
#include "tiles/bake/deep_sampler.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "common/error.hpp"
#include "scene/scene_mesh.hpp"
#include "tiles/encode/deep_encode.hpp"
#include "tiles/core/deep_tile.hpp"

namespace st {
namespace {

// A horizontal quad at height y, side 2h, facing +Y.
MeshSoup quad(const std::string& name, double y, double h, Rgb transmit) {
  MeshSoup m{name, {{-h, y, -h}, {-h, y, h}, {h, y, h}, {h, y, -h}}, {{0, 1, 2}, {0, 2, 3}}};
  m.transmit = transmit;
  return m;
}

LightSpace overhead(const Scene& s) {
  return LightSpace::fit(LightSpec::parse("sun:azimuth=0,elevation=90"), s.bounds());
}

TEST(DeepSampler, TwoThinSlabsGiveTheAnalyticSteps) {
  Scene s;
  s.name = "slabs";
  append_mesh(s, quad("top", 1, 5, {0.5f, 0.5f, 0.5f}));
  append_mesh(s, quad("bottom", 0, 5, {0.5f, 0.25f, 0.125f}));
  const LightSpace light = overhead(s);
  const DeepSampler sampler(s, light);
  const double d_top = light.to_light({0, 1, 0}).d, d_bottom = light.to_light({0, 0, 0}).d;
  ASSERT_LT(d_top, d_bottom);
  DeepSampleOptions o;
  o.samples_per_side = 3;
  o.epsilon = 0.01;
  for (uint64_t x : {3u, 4u, 5u})
    for (bool compressed : {false, true}) {
      // Uncompressed: exactly the analytic steps; compressed: within epsilon of them.
      const double tol = compressed ? o.epsilon + 1e-6 : 1e-6;
      const VisibilityFunction f = sampler.texel(3, x, 4, o, compressed);
      ASSERT_EQ(f.check(), "");
      EXPECT_FALSE(f.monochrome);  // the bottom slab is coloured
      const auto before = f.eval(float(d_top - 1e-3));
      const auto mid = f.eval(float(0.5 * (d_top + d_bottom)));
      const auto after = f.eval(float(d_bottom + 1e-3));
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(before[c], 1.0, tol);
        EXPECT_NEAR(mid[c], 0.5, tol);
      }
      EXPECT_NEAR(after[0], 0.25, tol);
      EXPECT_NEAR(after[1], 0.125, tol);
      EXPECT_NEAR(after[2], 0.0625, tol);
    }
  // A receiver on the top slab is not shadowed by it (the value before the step).
  const VisibilityFunction one = sampler.ray_function(0.5, 0.5);
  ASSERT_EQ(one.vertices.size(), 4u);
  EXPECT_EQ(one.eval(one.vertices[0].depth)[0], 1.0f);
  EXPECT_EQ(one.eval_after(one.vertices[0].depth)[0], 0.5f);
}

TEST(DeepSampler, PartialCoverageIsTheCoveredFractionOfTheTexel) {
  // A card blocking all light whose edge at world x = 0.3 crosses a
  // texel: the texel's value behind it is the uncovered fraction (§3.1, Figure 3b),
  // within one stratum of the 8 x 8 jittered grid.
  Scene s;
  s.name = "edge";
  append_mesh(s, MeshSoup{"card", {{-4, 0, -4}, {-4, 0, 4}, {0.3, 0, 4}, {0.3, 0, -4}}, {{0, 1, 2}, {0, 2, 3}}});
  append_mesh(s, quad("far", -1, 5, {1, 1, 1}));  // widens the light box, lets all light through
  const LightSpace light = overhead(s);
  // The card blocks all light through a solid alpha texture (what makes it partial).
  s.triangle_uv.assign(s.triangles.size(), {});
  s.alpha_textures.push_back(AlphaTexture{"solid", 1, 1, {255}, 0.5f});
  s.meshes[0].alpha_texture = 0;
  const DeepSampler sampler(s, light);
  const uint32_t level = 3, res = 1u << level;
  const LightPoint e = light.to_light({0.3, 0, 0.5}), in = light.to_light({-1, 0, 0.5});
  const bool along_u = std::fabs(in.u - e.u) > std::fabs(in.v - e.v);
  const double w = along_u ? e.u : e.v;  // the edge's coordinate across it
  const auto [tx, ty] = LightSpace::texel_of(level, e.u, e.v);
  const double lo = double(along_u ? tx : ty) / res;
  const double covered_below = (w - lo) * res;  // fraction of the texel below the edge
  const bool card_below = (along_u ? in.u - e.u : in.v - e.v) < 0;
  const double expect = card_below ? 1 - covered_below : covered_below;
  DeepSampleOptions o;
  o.samples_per_side = 8;
  o.epsilon = 0;
  const VisibilityFunction f = sampler.texel(level, tx, ty, o, false);
  EXPECT_NEAR(f.eval_after(float(e.d + 1e-3))[0], expect, 1.0 / 8 + 1e-6);
  EXPECT_GT(f.eval_after(float(e.d + 1e-3))[0], 0.0f);
  EXPECT_LT(f.eval_after(float(e.d + 1e-3))[0], 1.0f);
}

TEST(DeepSampler, SpotLightDepthsAreTheLightsDepths) {
  Scene s;
  s.name = "spot";
  append_mesh(s, quad("top", 1, 5, {0.5f, 0.5f, 0.5f}));
  append_mesh(s, quad("bottom", 0, 5, {0.5f, 0.5f, 0.5f}));
  const LightSpace light =
      LightSpace::fit(LightSpec::parse("spot:pos=0.3,6,0.2,target=0,0,0,fov=60"), s.bounds());
  const DeepSampler sampler(s, light);
  for (const Vec3d& p : {Vec3d{0.5, 1, -0.7}, Vec3d{-1, 0, 1.5}}) {
    const LightPoint lp = light.to_light(p);
    const VisibilityFunction f = sampler.ray_function(lp.u, lp.v);
    ASSERT_GE(f.vertices.size(), 2u);
    bool found = false;
    for (const VisVertex& v : f.vertices) found = found || std::fabs(v.depth - lp.d) < 1e-5;
    EXPECT_TRUE(found) << "no step at the light depth " << lp.d << " of the surface point";
  }
}

TEST(DeepSampler, AlphaTextureBlocksWhereSolid) {
  Scene s;
  s.name = "card";
  MeshSoup m = quad("card", 0, 4, {0, 0, 0});
  // Corners (-4,-4), (-4,4), (4,4), (4,-4) map u = (x + 4) / 8: the left half is solid.
  m.uv = {{Vec2f{0, 0}, Vec2f{0, 1}, Vec2f{1, 1}}, {Vec2f{0, 0}, Vec2f{1, 1}, Vec2f{1, 0}}};
  m.alpha_texture = 0;
  append_mesh(s, std::move(m));
  AlphaTexture t;
  t.name = "half";
  t.width = 2, t.height = 1, t.alpha = {255, 0};
  s.alpha_textures.push_back(t);
  ASSERT_TRUE(s.any_partial());
  const LightSpace light = overhead(s);
  const DeepSampler sampler(s, light);
  auto at = [&](double wx) {
    const LightPoint p = light.to_light({wx, 0, 0.3});
    const VisibilityFunction f = sampler.ray_function(p.u, p.v);
    return f.eval_after(float(p.d + 1e-3))[0];
  };
  EXPECT_EQ(at(-2), 0.0f);
  EXPECT_EQ(at(2), 1.0f);
  EXPECT_EQ(at(-3.5), 0.0f);
  EXPECT_EQ(at(3.5), 1.0f);
}

TEST(DeepSampler, ConstantDensityVolumeIsExponentialWithinTheBound) {
  Scene s;
  s.name = "fog";
  Volume v;
  v.name = "fog";
  v.bounds.extend({-1, -1, -1});
  v.bounds.extend({1, 1, 1});
  v.nx = v.ny = v.nz = 16;
  v.density.assign(16 * 16 * 16, 2.0f);
  v.sigma = {1, 0.5f, 0.25f};
  s.volumes.push_back(v);
  const LightSpace light = overhead(s);
  const DeepSampler sampler(s, light);
  DeepSampleOptions o;
  o.samples_per_side = 2;
  o.epsilon = 0.01;
  // Linear interpolation between march steps (half a voxel: 1/16 world, tau <= 2/16
  // per step) misses exp by at most dtau^2 / 8.
  const double interp = (2.0 / 16) * (2.0 / 16) / 8 + 1e-5;
  const double d0 = light.to_light({0, 1, 0}).d, d1 = light.to_light({0, -1, 0}).d;
  for (bool compressed : {false, true}) {
    const VisibilityFunction f = sampler.texel(4, 8, 8, o, compressed);
    ASSERT_EQ(f.check(), "");
    EXPECT_FALSE(f.monochrome);
    for (int k = 0; k <= 40; ++k) {
      const double d = d0 + (d1 - d0) * k / 40.0;
      const double length = 2.0 * k / 40.0;  // world distance inside the box
      const auto got = f.eval(float(d));
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(got[c], std::exp(-2.0 * v.sigma[c] * length),
                    interp + (compressed ? o.epsilon : 0.0) + 1e-5)
            << "k=" << k << " c=" << c;
    }
  }
}

TEST(DeepSampler, CompressionStaysWithinEpsilonOnEveryTexel) {
  const bool small = std::getenv("SHADOWTILE_TEST_SCALE") != nullptr;
  for (const char* spec : {"procedural:hairball,count=24,segments=40,transmit=0.6",
                           "procedural:forest,trees=2,leaves=80,size=8,translucency=0.5",
                           "procedural:smoke,res=12"}) {
    const Scene s = make_procedural(spec);
    ASSERT_TRUE(s.any_partial()) << spec;
    const LightSpace light =
        LightSpace::fit(LightSpec::parse("sun:azimuth=20,elevation=60"), s.bounds());
    const DeepSampler sampler(s, light);
    DeepSampleOptions o;
    o.samples_per_side = small ? 2 : 3;
    o.epsilon = 0.02;
    const uint32_t level = small ? 2 : 3, n = 1u << level;
    DeepSampleStats stats;
    const DeepRegion raw = sampler.trace({level, 0, 0, n, n}, o, nullptr, false);
    const DeepRegion packed = sampler.trace({level, 0, 0, n, n}, o, &stats, true);
    EXPECT_EQ(stats.texels, uint64_t(n) * n);
    EXPECT_LE(stats.vertices_out, stats.vertices_in);
    uint64_t non_empty = 0;
    for (size_t i = 0; i < raw.functions.size(); ++i) {
      ASSERT_EQ(raw.functions[i].check(), "") << spec;
      ASSERT_EQ(packed.functions[i].check(), "") << spec;
      EXPECT_LE(max_difference(raw.functions[i], packed.functions[i]), o.epsilon + 1e-6)
          << spec << " texel " << i;
      non_empty += !raw.functions[i].vertices.empty();
    }
    EXPECT_GT(non_empty, 0u) << spec;
    // Deterministic: one texel alone equals the same texel of the region.
    EXPECT_EQ(sampler.texel(level, 1, 1, o), packed.at(1, 1)) << spec;
  }
}

TEST(DeepSampler, StiffFunctionsStayWithinEpsilon) {
  // Thousands of steps (1000 stacked sheets letting 99.5% through), near-total opacity in
  // a thin slab (a dense volume) behind them: every texel of a small map stays within
  // epsilon after compression, and compression removes most vertices.
  Scene s;
  s.name = "stiff";
  for (int k = 0; k < 1000; ++k) append_mesh(s, quad("sheet", 1 + 0.001 * k, 3, {0.995f, 0.995f, 0.995f}));
  Volume v;
  v.name = "dense";
  v.bounds.extend({-3, 0.4, -3});
  v.bounds.extend({3, 0.45, 3});
  v.nx = v.nz = 4, v.ny = 2;
  v.density.assign(32, 400.0f);
  s.volumes.push_back(v);
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=10,elevation=80"), s.bounds());
  const DeepSampler sampler(s, light);
  DeepSampleOptions o;
  o.samples_per_side = 2;
  o.epsilon = 0.01;
  DeepSampleStats st;
  const DeepRegion raw = sampler.trace({2, 0, 0, 4, 4}, o, nullptr, false);
  const DeepRegion packed = sampler.trace({2, 0, 0, 4, 4}, o, &st);
  EXPECT_GT(st.vertices_in, 16u * 2000);
  EXPECT_LT(st.vertices_out * 20, st.vertices_in);
  for (size_t i = 0; i < raw.functions.size(); ++i)
    EXPECT_LE(max_difference(raw.functions[i], packed.functions[i]), o.epsilon + 1e-6) << i;
}

TEST(DeepSampler, AnEncodedTileAnswersLikeTheSampledFunctions) {
  // A sampled 8 x 8 block of semi-transparent hair as one deep tile: mip 0 answers the
  // sampler's compressed functions (to the unorm16 rounding), mip 1 the average of four
  // uncompressed texels within the tile's bound.
  const Scene s = make_procedural("procedural:hairball,count=16,segments=30,transmit=0.5");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=40,elevation=60"), s.bounds());
  const DeepSampler sampler(s, light);
  DeepSampleOptions o;
  o.samples_per_side = 2;
  o.epsilon = 0.02;
  const TraceRegion r{5, 12, 12, 8, 8};
  const DeepRegion raw = sampler.trace(r, o, nullptr, false);
  const DeepRegion packed = sampler.trace(r, o);
  const std::vector<uint8_t> bytes = encode_deep_tile(packed.functions, 3, o.epsilon);
  const DeepTileView v = DeepTileView::open(bytes);
  for (uint32_t j = 0; j < 8; ++j)
    for (uint32_t i = 0; i < 8; ++i) {
      EXPECT_LE(max_difference(v.function(i, j, 0), packed.at(i, j)), deep::kQuantisation + 1e-6);
      if (i % 2 || j % 2) continue;
      const VisibilityFunction* kids[4] = {&raw.at(i, j), &raw.at(i + 1, j), &raw.at(i, j + 1),
                                           &raw.at(i + 1, j + 1)};
      const double w[4] = {1, 1, 1, 1};
      EXPECT_LE(max_difference(v.function(i / 2, j / 2, 1), average(kids, w)),
                o.epsilon * 1.5 + deep::kQuantisation + 1e-6);
    }
}

TEST(DeepSampler, RefusesBadOptionsAndScenes) {
  Scene s;
  s.name = "bad";
  MeshSoup m = quad("card", 0, 1, {0, 0, 0});
  m.alpha_texture = 3;  // no such texture
  append_mesh(s, std::move(m));
  const LightSpace light = overhead(s);
  EXPECT_THROW(DeepSampler(s, light), Error);
  s.meshes[0].alpha_texture = -1;
  s.meshes[0].transmit = {0.5f, 0.5f, 0.5f};
  const DeepSampler ok(s, light);
  DeepSampleOptions o;
  o.samples_per_side = 0;
  EXPECT_THROW(ok.texel(0, 0, 0, o), Error);
  o.samples_per_side = 2;
  EXPECT_THROW(ok.texel(1, 2, 0, o), Error);  // outside the level-1 map
}

}  // namespace
}  // namespace st

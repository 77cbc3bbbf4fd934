// Partial occluders in the rendered view (render_view with a DeepLookup): the forest's leaf
// shadows come from its deep map, and its map render agrees with ray-traced shadows (an
// opaque shadow ray times the transmittance along the light ray) about as well as the
// opaque city's does; without the deep part every leaf shadow is missing. Primary rays go
// through the cut-away corners of alpha-tested cards.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "tiles/bake/deep_build.hpp"
#include "tiles/bake/map_build.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"
#include "tiles/core/deep_pack.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st {
namespace render_deep_test {

constexpr uint32_t kLevel = 9;

struct Built {
  std::shared_ptr<PackReader> pack;
  std::unique_ptr<PackEvaluator> eval;
  std::unique_ptr<PackDeepMap> deep;
};

// The scene's opaque map at kLevel and, when it has partial occluders, its deep map at
// kLevel (tiles of 16^2, 4x4 samples a texel), in one pack as `shadowtile build` makes it.
Built build(const Scene& s, const LightSpace& light, const std::string& name) {
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/" + name + ".pack";
  DeepSampleOptions so;
  so.samples_per_side = 4;
  DeepMapBuild deep;
  if (s.any_partial()) deep = build_deep_tiles(DeepSampler(s, light), kLevel, 4, so);
  MapBuildOptions o;
  o.map_level = kLevel;
  o.encoding = Encoding::dagmh;
  if (s.any_partial())
    o.before_finish = [&](PackWriter& w) {
      append_deep_map(w, deep, so.effective_epsilon(), so.samples_per_side);
    };
  build_map(opaque_part(s), light, o, path);
  Built b;
  b.pack = PackReader::open(path);
  b.eval = std::make_unique<PackEvaluator>(b.pack, 4096);
  b.deep = PackDeepMap::load(*b.pack);
  return b;
}

DeepLookup lookup_of(const PackDeepMap& m) {
  DeepLookup d;
  d.level = m.map().level();
  d.transmittance = [&dm = m.map()](double u, double v, float z, double width) {
    return width > 0 ? dm.filtered(u, v, z, width) : dm.transmittance(u, v, z);
  };
  return d;
}

uint64_t shadowed(const RenderResult& r) {
  uint64_t n = 0;
  for (size_t i = 0; i < r.visibility.size(); ++i)
    n += r.visibility[i] * (r.transmittance[3 * i] + r.transmittance[3 * i + 1] + r.transmittance[3 * i + 2]) / 3 <
         0.5f;
  return n;
}

TEST(RenderDeep, ForestAgreesWithRaysAsWellAsTheOpaqueCity) {
  const LightSpec spec = LightSpec::parse("sun:azimuth=30,elevation=40");
  RenderOptions ro;
  ro.width = 200, ro.height = 120, ro.diff = true;

  const Scene city = make_procedural("procedural:city,size=3");
  const LightSpace city_light = LightSpace::fit(spec, city.bounds());
  const Built cb = build(city, city_light, "render_deep_city");
  ASSERT_EQ(cb.deep, nullptr) << "an opaque scene carries no deep part";
  const SceneTracer ct(city, city_light);
  EXPECT_FALSE(ct.has_partial());
  Camera cc;
  cc.pos = {-120, 90, -130}, cc.target = {0, 0, 0}, cc.fov_deg = 50;
  const RenderResult c = render_view(ct, ct.primary(cc, ro.width, ro.height), *cb.eval, ro);

  const Scene forest = make_procedural("procedural:forest,trees=3,leaves=200,size=10");
  const LightSpace light = LightSpace::fit(spec, forest.bounds());
  const Built fb = build(forest, light, "render_deep_forest");
  ASSERT_NE(fb.deep, nullptr);
  const SceneTracer ft(forest, light);
  EXPECT_TRUE(ft.has_partial());
  Camera fc;
  fc.pos = {-9, 11, -10}, fc.target = {0, 2, 0}, fc.fov_deg = 50;
  const auto rec = ft.primary(fc, ro.width, ro.height);
  const RenderResult without = render_view(ft, rec, *fb.eval, ro);
  ro.deep = lookup_of(*fb.deep);
  const RenderResult with = render_view(ft, rec, *fb.eval, ro);
  std::printf("mismatch: city %.4f%%, forest %.4f%% with its deep part, %.4f%% without; mean |map - rays| %.4f / %.4f\n",
              100 * c.differing_fraction(), 100 * with.differing_fraction(), 100 * without.differing_fraction(),
              with.mean_abs_difference, without.mean_abs_difference);
  ASSERT_GT(c.receivers, uint64_t(ro.width) * ro.height / 8);
  ASSERT_GT(with.receivers, uint64_t(ro.width) * ro.height / 8);
  // The leaves shadow a visible part of the view, which the opaque map alone misses.
  EXPECT_GT(shadowed(with), shadowed(without) + with.receivers / 50);
  EXPECT_GT(without.differing_fraction(), 0.02);
  // With the deep part, about as few receivers differ as on the opaque city: measured
  // 1.12% against the city's 0.64% (17.6% without the deep part; 1.85% when a single tap
  // read one deep texel as a step instead of filtering bilinearly). Leaf shadows have far
  // more edge per area than buildings, and a deep texel holds the box-filtered coverage of
  // 16 rays where a ray samples a point, so edges differ somewhat more often.
  EXPECT_LE(with.differing_fraction(), std::max(2.5 * c.differing_fraction(), 0.01));
  EXPECT_LT(with.mean_abs_difference, without.mean_abs_difference / 3);
  // The PCF and filtered paths read the deep map too (its mips), and stay close to the rays.
  ro.pcf_radius = 1;
  const RenderResult pcf = render_view(ft, rec, *fb.eval, ro);
  EXPECT_LE(pcf.differing_fraction(), 3 * std::max(with.differing_fraction(), 0.005));
}

// Primary rays skip the transparent corners of alpha-tested cards (as the deep sampler's
// crossings do): a ray through a card's corner hits what lies behind it.
TEST(RenderDeep, PrimaryRaysPassTheCutAwayCornersOfAlphaTestedCards) {
  const Scene forest = make_procedural("procedural:forest,trees=1,leaves=20,size=6");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=40"), forest.bounds());
  Scene cards = forest;  // the same scene with the leaf texture solid everywhere
  for (AlphaTexture& t : cards.alpha_textures) std::fill(t.alpha.begin(), t.alpha.end(), uint8_t(255));
  const SceneTracer a(forest, light), b(cards, light);
  Camera cam;
  cam.pos = {0, 14, 0.01}, cam.target = {0, 0, 0}, cam.fov_deg = 40;
  const auto ra = a.primary(cam, 160, 160), rb = b.primary(cam, 160, 160);
  uint64_t nearer = 0, farther = 0;
  for (size_t i = 0; i < ra.size(); ++i) {
    if (!ra[i].hit || !rb[i].hit) continue;
    nearer += ra[i].distance < rb[i].distance;
    farther += ra[i].distance > rb[i].distance;
  }
  EXPECT_EQ(nearer, 0u);
  EXPECT_GT(farther, 0u) << "the solid card hides what the cut-away one lets the camera see";
}

}  // namespace render_deep_test
}  // namespace st

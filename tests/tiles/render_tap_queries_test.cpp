// A sun's tap queries in render_view (sun_tap_queries): the packed SSE2 and AVX paths
// give the scalar path's light-space texels and depths bit for bit, and the rendered map
// shadows are the same whichever path computes them.
#include <gtest/gtest.h>

#include <bit>
#include <random>
#include <string>
#include <vector>

#include "tiles/bake/map_build.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tests/tiles/render_scenes.hpp"

namespace st {
namespace {

using render_test::cube_on_slab;

constexpr TapQueryPath kPaths[] = {TapQueryPath::scalar, TapQueryPath::sse2, TapQueryPath::avx,
                                   TapQueryPath::best};

const char* name(TapQueryPath p) {
  switch (p) {
    case TapQueryPath::scalar: return "scalar";
    case TapQueryPath::sse2: return "sse2";
    case TapQueryPath::avx: return "avx";
    case TapQueryPath::best: return "best";
  }
  return "?";
}

// The reference: lookup_point, the in-map test and LightSpace::texel_of per receiver,
// as map_visibility computes them.
size_t reference_queries(const LightSpace& light, uint32_t level, uint32_t radius, const std::vector<Receiver>& rc,
                         std::vector<PcfQuery>& q, std::vector<uint32_t>& index) {
  size_t n = 0;
  for (size_t i = 0; i < rc.size(); ++i) {
    const LightPoint lp = lookup_point(rc[i], light, level, radius);
    if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) continue;
    const auto [x, y] = LightSpace::texel_of(level, lp.u, lp.v);
    q[n] = {x, y, level, 2 * radius + 1, float(lp.d)};
    index[n++] = uint32_t(i);
  }
  return n;
}

TEST(RenderTapQueries, EveryPathGivesTheScalarTexelsAndDepthsBitForBit) {
  const Scene s = cube_on_slab();
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=40"), s.bounds());
  // Receivers across and beyond the scene (a fifth outside the map), any normal, both
  // kinds; an odd count, so every packed path also runs its scalar tail.
  std::mt19937_64 rng(20261204);
  std::uniform_real_distribution<double> pos(-13.0, 13.0), dir(-1.0, 1.0);
  std::vector<Receiver> rc(4099);
  for (Receiver& r : rc) {
    r.hit = true;
    r.closed = (rng() & 1) != 0;
    r.pos = {pos(rng), pos(rng) * 0.4 + 1, pos(rng)};
    Vec3d n{dir(rng), dir(rng), dir(rng)};
    if (length(n) < 1e-3) n = {0, 1, 0};
    r.normal = normalize(n);
    r.n_dot_l = 1;
  }
  std::vector<PcfQuery> want(rc.size()), got(rc.size());
  std::vector<uint32_t> want_index(rc.size()), got_index(rc.size());
  int packed_paths_run = 0;
  for (uint32_t level : {0u, 9u, 13u, 24u, 30u, 31u, 40u}) {  // 31 and 40: packed paths fall back to scalar
    for (uint32_t radius : {0u, 2u}) {
      const size_t n = reference_queries(light, level, radius, rc, want, want_index);
      if (level >= 9) {
        ASSERT_GT(n, rc.size() / 2) << "level " << level;
        ASSERT_LT(n, rc.size()) << "some receivers should fall outside the map";
      }
      for (TapQueryPath path : kPaths) {
        if (!tap_query_path_available(path)) continue;
        packed_paths_run += path == TapQueryPath::sse2 || path == TapQueryPath::avx;
        // From an odd offset too: no alignment assumed.
        for (size_t first : {size_t(0), size_t(3)}) {
          const std::span<const Receiver> part(rc.data() + first, rc.size() - first);
          const size_t m = sun_tap_queries(light, level, radius, part, got.data(), got_index.data(), path);
          size_t k0 = 0;  // the reference's first query of a receiver >= first
          while (k0 < n && want_index[k0] < first) ++k0;
          ASSERT_EQ(m, n - k0) << name(path) << " level " << level << " radius " << radius;
          for (size_t k = 0; k < m; ++k) {
            const PcfQuery& a = got[k];
            const PcfQuery& b = want[k0 + k];
            ASSERT_EQ(got_index[k] + first, want_index[k0 + k]) << name(path) << " query " << k;
            ASSERT_EQ(a.x, b.x) << name(path) << " level " << level << " receiver " << want_index[k0 + k];
            ASSERT_EQ(a.y, b.y) << name(path) << " level " << level << " receiver " << want_index[k0 + k];
            ASSERT_EQ(a.level, b.level);
            ASSERT_EQ(a.r, b.r);
            ASSERT_EQ(std::bit_cast<uint32_t>(a.receiver), std::bit_cast<uint32_t>(b.receiver))
                << name(path) << " level " << level << " receiver " << want_index[k0 + k];
          }
        }
      }
    }
  }
#if defined(__x86_64__)
  EXPECT_GT(packed_paths_run, 0) << "an x86-64 build runs the SSE2 path at least";
#endif
}

TEST(RenderTapQueries, RenderedMapShadowsAreTheSameOnEveryPath) {
  const Scene s = cube_on_slab();
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=40"), s.bounds());
  MapBuildOptions o;
  o.map_level = 9;
  o.encoding = Encoding::mh;
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/render_tap_queries.pack";
  build_map(s, light, o, path);
  const PackEvaluator eval(std::shared_ptr<PackReader>(PackReader::open(path)), 4096);
  const SceneTracer tracer(s, light);
  Camera cam;
  cam.pos = {-11, 8, 12};  // the cube's shadow and the slab's edge, where the map ends
  cam.target = {0, 0, 0};
  const uint32_t w = 160, h = 90;
  const auto rec = tracer.primary(cam, w, h);
  for (uint32_t radius : {0u, 1u}) {
    RenderOptions ro;
    ro.width = w, ro.height = h, ro.pcf_radius = radius, ro.tap_query_path = TapQueryPath::scalar;
    const RenderResult scalar = render_view(tracer, rec, eval, ro);
    uint64_t shadowed = 0;
    for (size_t i = 0; i < rec.size(); ++i) {
      ASSERT_EQ(std::bit_cast<uint32_t>(scalar.visibility[i]),
                std::bit_cast<uint32_t>(map_visibility(eval, rec[i], light, radius, eval.finest_level())))
          << "pixel " << i;
      shadowed += rec[i].hit && rec[i].n_dot_l > 0 && scalar.visibility[i] < 1;
    }
    EXPECT_GT(shadowed, 100u) << "the view should contain the cube's shadow";
    for (TapQueryPath p : kPaths) {
      if (!tap_query_path_available(p)) continue;
      ro.tap_query_path = p;
      const RenderResult v = render_view(tracer, rec, eval, ro);
      for (size_t i = 0; i < rec.size(); ++i)
        ASSERT_EQ(std::bit_cast<uint32_t>(v.visibility[i]), std::bit_cast<uint32_t>(scalar.visibility[i]))
            << name(p) << " pixel " << i << " radius " << radius;
      for (size_t i = 0; i < v.image.size(); ++i)
        ASSERT_EQ(std::bit_cast<uint32_t>(v.image[i]), std::bit_cast<uint32_t>(scalar.image[i]))
            << name(p) << " image value " << i;
    }
  }
}

}  // namespace
}  // namespace st

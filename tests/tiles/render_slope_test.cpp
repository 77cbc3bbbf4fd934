// Shadow acne on sloped ground under hierarchical filtering: a lit, open plane tilted to
// the sun must read fully lit at every footprint and PCF kernel. The coarse level of the
// blend compares its kernel's taps (coarse texels, 2^s finest texels apart, each one
// child's own depth on open geometry) with the receiver; against the receiver's one depth
// (a normal offset of fine-level texels) the far taps of a tilted plane lay in front of it
// and shadowed it partly: concentric rings on a forest's terrain. With the receiver plane
// (tiles/core/receiver_plane.hpp) each tap compares the plane over its own texel.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>

#include "tiles/bake/map_build.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/camera.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tests/tiles/render_scenes.hpp"

namespace st {
namespace {

TEST(RenderSlope, FilteredLookupsOnALitTiltedPlaneAreFullyLit) {
  const LightSpec spec = LightSpec::parse("sun:azimuth=30,elevation=40");
  // The plane's normal: up, tilted about the x axis away from the sun until n.l is about
  // 0.55 (57 degrees between the normal and the light: a steep slope, still lit).
  Scene probe;
  probe.name = "probe";
  probe.vertices = {{-1, 0, -1}, {1, 0, -1}, {0, 0, 1}};
  probe.triangles = {{0, 1, 2}};
  probe.meshes.push_back(Mesh{"p", 0, 1});
  const Vec3d to_sun = -LightSpace::fit(spec, probe.bounds()).forward();
  double tilt = 0;
  for (double a = -1.2; a <= 1.2; a += 0.01) {
    const Vec3d n{0, std::cos(a), std::sin(a)};
    if (std::fabs(dot(n, to_sun) - 0.55) < std::fabs(dot(Vec3d{0, std::cos(tilt), std::sin(tilt)}, to_sun) - 0.55))
      tilt = a;
  }
  const Vec3d normal{0, std::cos(tilt), std::sin(tilt)};
  ASSERT_NEAR(dot(normal, to_sun), 0.55, 0.02);
  // One open quad of 20 x 20 units in that plane.
  const Vec3d ex{1, 0, 0}, ez = cross(ex, normal);  // in-plane axes
  Scene s;
  s.name = "tilted-plane";
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) s.vertices.push_back(ex * (i ? 10.0 : -10.0) + ez * (j ? 10.0 : -10.0));
  s.triangles = {{0, 1, 3}, {0, 3, 2}};
  s.meshes.push_back(Mesh{"plane", 0, 2});
  const LightSpace light = LightSpace::fit(spec, s.bounds());
  MapBuildOptions o;
  o.map_level = 9;
  o.encoding = Encoding::dagmh;
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/render_tilted_plane.pack";
  build_map(s, light, o, path);
  const PackEvaluator eval(std::shared_ptr<PackReader>(PackReader::open(path)), 4096);

  // Receivers on the plane's inner part (a kernel of the coarsest level tried stays on it),
  // at points that fall anywhere within their texels.
  uint64_t asked = 0, shadowed = 0;
  float worst = 1;
  for (int j = 0; j < 23; ++j)
    for (int i = 0; i < 23; ++i) {
      Receiver r;
      r.hit = true, r.closed = false, r.normal = normal, r.distance = 10;
      r.pos = ex * (-5.5 + 0.4783 * i) + ez * (-5.5 + 0.4791 * j);
      r.n_dot_l = dot(normal, to_sun);
      ASSERT_EQ(map_visibility(eval, r, light, 0, eval.finest_level()), 1.0f);  // single tap: exact
      for (uint32_t radius : {1u, 2u})
        for (float footprint : {1.0f, 1.25f, 1.5f, 1.75f, 1.99f, 2.5f, 3.3f, 3.9f, 5.0f, 7.0f}) {
          const float v = map_visibility_filtered(eval, r, light, radius, footprint);
          ++asked;
          shadowed += v != 1.0f;
          worst = std::min(worst, v);
        }
    }
  EXPECT_EQ(shadowed, 0u) << "of " << asked << " filtered lookups on the lit plane; darkest " << worst;
}

// pcf_plane's shortcuts (the kernel's extreme tap depths through Evaluator::pcf, the
// square regions of depth_region) give the tap-by-tap count of receiver_plane_depth
// against Evaluator::depth, for planes of every slope sign through a map with shadows.
TEST(RenderSlope, PlanePcfCountsEveryTapLikeTheTapByTapDefinition) {
  const Scene s = render_test::cube_on_slab();
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  MapBuildOptions o;
  o.map_level = 7;
  o.encoding = Encoding::dagmh;
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/render_plane_pcf.pack";
  build_map(s, light, o, path);
  const PackEvaluator eval(std::shared_ptr<PackReader>(PackReader::open(path)), 4096);
  const uint32_t L = eval.finest_level();
  std::mt19937 rng(7);
  std::uniform_int_distribution<uint64_t> texel(0, (uint64_t(1) << L) - 1);
  std::uniform_real_distribution<float> depth(0.0f, 1.0f), slope(-0.02f, 0.02f);
  uint64_t partial = 0;
  for (int k = 0; k < 3000; ++k) {
    ReceiverPlane p;
    p.finest = L, p.fx = texel(rng), p.fy = texel(rng), p.corner = depth(rng), p.gx = slope(rng), p.gy = slope(rng);
    const uint32_t level = L - uint32_t(k % 4), r = 1 + 2 * uint32_t(k % 5);
    const uint64_t x = p.fx >> (L - level), y = p.fy >> (L - level), side = uint64_t(1) << level;
    uint32_t lit = 0;
    for (uint32_t j = 0; j < r; ++j)
      for (uint32_t i = 0; i < r; ++i) {
        const uint64_t tx = pcf_tap(x, i, r, side), ty = pcf_tap(y, j, r, side);
        lit += receiver_plane_depth(p, level, tx, ty) <= eval.depth(level, tx, ty);
      }
    const float want = float(lit) / float(r * r);
    partial += want != 0.0f && want != 1.0f;
    ASSERT_EQ(pcf_plane(eval, level, x, y, r, p), want) << "query " << k;
  }
  EXPECT_GT(partial, 100u);  // the tap-by-tap path was exercised, not only the shortcuts
}

// Evaluator::pcf_on_plane inside each encoding's shared traversal (a square of texels that
// share a value counted at once when the plane over it lies on one side of the value, else
// halved; PlaneTaps) equals the tap-by-tap count through depth() on a real open mesh's
// tiles: MH, MMH, DAG-MH (plane tiles too) and VSDAG, receiver planes of the view's own
// receivers (filtered_lookup), the same planes at zero slope, at the 4:1 cap and at random
// slopes up to it, at the finest level and three coarser ones, every kernel side.
TEST(RenderSlope, PcfOnPlaneInsideTheTraversalCountsLikeTapByTapOnRealTiles) {
  const std::string file = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
  if (!std::filesystem::exists(file)) GTEST_SKIP() << "assimp-testmodels missing: run scripts/deps";
  const Scene scene = load_scene(file);
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  const SceneTracer tracer(scene, light);
  const std::vector<Receiver> rec = tracer.primary(parse_camera("pos=400,300,400,target=0,0,0,fov=50"), 40, 24);
  struct Variant {
    Encoding e;
    bool planes;
  };
  uint64_t partial = 0, asked = 0;
  for (const Variant var : {Variant{Encoding::mh, false}, Variant{Encoding::mmh, true}, Variant{Encoding::dagmh, false},
                            Variant{Encoding::dagmh, true}, Variant{Encoding::vsdag, false}}) {
    MapBuildOptions o;
    o.map_level = 7;
    o.skip_level = 3;
    o.tile_bytes = 1024;  // several tiles: kernels across tile borders too
    o.encoding = var.e;
    o.planes = var.planes;
    const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/render_plane_tiles_" + to_string(var.e) +
                             (var.planes ? "_planes" : "") + ".pack";
    build_map(scene, light, o, path);
    const PackEvaluator eval(std::shared_ptr<PackReader>(PackReader::open(path)), 4096);
    const uint32_t L = eval.finest_level();
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    for (const Receiver& r : rec) {
      if (!r.hit || r.n_dot_l <= 0) continue;
      LightPoint lp;
      ReceiverPlane real;
      if (!filtered_lookup(r, light, L, lp, real)) continue;
      // filtered_lookup's cap: kMaxReceiverSlope texels of depth along the light ray.
      const double texel = light.texel_size(r.pos, L);
      const float cap = float(kMaxReceiverSlope * std::fabs(light.to_light(r.pos - light.forward() * texel).d -
                                                            light.to_light(r.pos).d));
      ReceiverPlane flat = real, capped = real, random = real;
      flat.gx = flat.gy = 0;
      capped.gx = unit(rng) < 0 ? -cap : cap, capped.gy = unit(rng) < 0 ? -cap : cap;
      random.gx = cap * unit(rng), random.gy = cap * unit(rng);
      for (const ReceiverPlane& p : {real, flat, capped, random})
        for (uint32_t up = 0; up < 4; ++up) {
          const uint32_t level = L - up, r_side = 1 + 2 * uint32_t(rng() % 5);
          const uint64_t x = p.fx >> up, y = p.fy >> up;
          const float want = pcf_plane_by_taps(eval, level, x, y, r_side, p);
          partial += want != 0.0f && want != 1.0f;
          ++asked;
          ASSERT_EQ(eval.pcf_on_plane(level, x, y, r_side, p), want)
              << to_string(var.e) << (var.planes ? "+planes" : "") << " level " << level << " texel " << x << "," << y
              << " r " << r_side << " slopes " << p.gx << "," << p.gy;
        }
    }
  }
  EXPECT_GT(partial, asked / 20) << "of " << asked;  // kernels that straddle the plane were counted
}

}  // namespace
}  // namespace st

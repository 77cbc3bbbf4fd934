// A pack built from an OpenVDB volume (a scene of one .vdb box, nothing opaque) is served
// like any other: the client's Map answers transmittance exactly as the pack's own deep
// map does, and that answer is exp(-sigma * rho * length) through the box.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "client/map_access.hpp"
#include "tests/client/deep_pack_fixture.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/bake/deep_build.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "tiles/core/deep_pack.hpp"
#ifdef SHADOWTILE_HAVE_OPENVDB
#include "tests/tiles/vdb_fixtures.hpp"
#endif

namespace st::client {
namespace {

#ifdef SHADOWTILE_HAVE_OPENVDB
TEST(DeepVdbLoopback, VolumePackAnswersAlikeOverTheWire) {
  const std::string vdb = std::string(SHADOWTILE_TEST_TMP) + "/box.vdb";
  vdbtest::write(vdb, {vdbtest::box_grid(8, 4, 8, 0.5, {0, 0, 0}, 0.5f)});  // [0,4] x [0,2] x [0,4]
  const Scene s = load_scene(vdb);
  ASSERT_TRUE(s.triangles.empty());
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=10,elevation=70"), s.bounds());
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/vdb_loop.pack";
  // Nothing opaque: an all-lit depth map.
  const DeepSampleOptions so = looptest::deep_options(0.01);
  const DeepMapBuild deep = looptest::build_deep_pack(s, light, so, path);
  ASSERT_GT(deep.tiles.size(), 1u);
  const auto pack = PackReader::open(path);
  const auto local = PackDeepMap::load(*pack);
  ASSERT_NE(local, nullptr);

  looptest::TestServer srv = looptest::start_server({path});
  Client c({"127.0.0.1", srv.port}, looptest::quick_options());
  Map m = c.open("vdb_loop");
  ASSERT_TRUE(m.has_deep());
  // Below the box's centre, the light crossed 2 / sin(70 deg) of density 0.5 (sigma 1).
  const Vec3d f = light.forward();
  const double want = std::exp(-0.5 * 2 * length(f) / std::fabs(f.y));
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> ux(1.5, 2.5), uy(-1.0, 0.0);
  for (int i = 0; i < 60; ++i) {
    const WorldPoint w{ux(rng), uy(rng), ux(rng)};
    const LightPoint p = light.to_light({w.x, w.y, w.z});
    ASSERT_TRUE(looptest::wait_until([&] { return m.deep_resident(p.u, p.v, p.u, p.v); })) << i;
    const Transmittance t = m.transmittance(w);
    const auto local_t = local->map().transmittance(p.u, p.v, float(p.d));
    EXPECT_EQ(t.r, local_t[0]) << i;
    EXPECT_EQ(t.g, local_t[1]) << i;
    EXPECT_EQ(t.b, local_t[2]) << i;
    EXPECT_NEAR(t.r, want, so.epsilon + 1e-3) << i;
    EXPECT_EQ(m.visibility(w), 1.0f) << i;  // nothing opaque in the scene
  }
  srv.stop();
}
#endif

}  // namespace
}  // namespace st::client

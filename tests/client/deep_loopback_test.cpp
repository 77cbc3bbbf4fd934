// Deep tiles over the wire (loopback, in-process server): a pack with a deep part is
// served like any other; the client's Map answers transmittance from its deep tiles
// exactly as the pack's own deep map does locally (PackDeepMap), at points and over
// footprints, and answers 1 for a pack without a deep part.
#include <gtest/gtest.h>

#include <random>

#include "client/map_access.hpp"
#include "tests/client/deep_pack_fixture.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/bake/deep_build.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "tiles/core/deep_pack.hpp"

namespace st::client {
namespace {

using looptest::quick_options;
using looptest::start_server;
using looptest::wait_until;

TEST(DeepLoopback, SameAnswersFromThePackAndOverTheWire) {
  const Scene s = make_procedural("procedural:hairball,count=12,segments=24,transmit=0.5");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=40,elevation=60"), s.bounds());
  const DeepSampleOptions so = looptest::deep_options(0.02);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/deep_loop.pack";
  const DeepMapBuild deep = looptest::build_deep_pack(s, light, so, path);
  ASSERT_GT(deep.tiles.size(), 1u);
  const auto pack = PackReader::open(path);
  const auto local = PackDeepMap::load(*pack);
  ASSERT_NE(local, nullptr);

  looptest::TestServer srv = start_server({path});
  ClientOptions co = quick_options();
  co.cache_slots = 8;  // fewer than the deep tiles: the deep cache evicts and refetches
  Client c({"127.0.0.1", srv.port}, co);
  Map m = c.open("deep_loop");
  ASSERT_TRUE(m.has_deep());

  std::mt19937_64 rng(7);
  const Aabb b = s.bounds();
  std::uniform_real_distribution<double> ux(b.lo.x, b.hi.x), uy(b.lo.y, b.hi.y), uz(b.lo.z, b.hi.z);
  int partial = 0, compared = 0;
  for (int i = 0; i < 400; ++i) {
    const WorldPoint w{ux(rng), uy(rng), uz(rng)};
    const LightPoint p = light.to_light({w.x, w.y, w.z});
    if (!(p.u >= 0 && p.u < 1 && p.v >= 0 && p.v < 1)) continue;
    const float foot = (i % 3) * 0.05f * float(light.extent_uv());  // 0, 5% and 10% of the map
    // Until its tile arrives a point answers 1; then exactly what the pack answers.
    ASSERT_TRUE(wait_until([&] { return m.deep_resident(p.u, p.v, p.u, p.v); })) << i;
    const Transmittance t = foot > 0 ? m.transmittance_filtered(w, foot) : m.transmittance(w);
    const auto want = foot > 0 ? local->map().filtered(p.u, p.v, float(p.d), foot / light.extent_uv())
                               : local->map().transmittance(p.u, p.v, float(p.d));
    EXPECT_EQ(t.r, want[0]) << i;
    EXPECT_EQ(t.g, want[1]) << i;
    EXPECT_EQ(t.b, want[2]) << i;
    partial += want[0] < 1.0f;
    ++compared;
  }
  EXPECT_GT(compared, 100);
  EXPECT_GT(partial, 0);
  srv.stop();
}

TEST(DeepLoopback, MapsWithoutADeepPartAnswerOne) {
  const looptest::TestPack p = looptest::build_pack("nodeep", 5, 3, looptest::first_encoding(), 2, 4096);
  looptest::TestServer srv = start_server({p.path});
  Client c({"127.0.0.1", srv.port}, quick_options());
  Map m = c.open("nodeep");
  EXPECT_FALSE(m.has_deep());
  EXPECT_EQ(m.transmittance({0, 0, 0}), Transmittance{});
  EXPECT_FALSE(m.deep_resident(0, 0, 1, 1));
  EXPECT_EQ(Map().transmittance_filtered({0, 0, 0}, 1.0f), Transmittance{});
  srv.stop();
}

}  // namespace
}  // namespace st::client

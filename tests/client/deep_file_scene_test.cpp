// A scene file whose materials let light through (OBJ/MTL: a tinted glass pane, `d` and
// `Tf`, over a leaf card alpha-tested through a PNG `map_d`, over opaque ground): built
// into a pack and served, the client's Map::transmittance answers what the deep sampler
// makes of the file's texels (the texel's compressed function, up to the tile's unorm16
// rounding).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "client/map_access.hpp"
#include "tests/client/deep_pack_fixture.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/bake/deep_build.hpp"
#include "tiles/bake/map_build.hpp"
#include "image/png_io.hpp"
#include "scene/scene.hpp"
#include "tiles/core/deep_format.hpp"

namespace st::client {
namespace {

std::string write_scene(const std::string& dir) {
  std::filesystem::create_directories(dir);
  std::vector<uint8_t> ga;  // 4 x 4 checker of solid and clear texels
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) ga.insert(ga.end(), {255, uint8_t((x + y) % 2 ? 255 : 0)});
  write_png_grey_alpha(dir + "/leaf.png", 4, 4, ga);
  std::ofstream(dir + "/s.mtl") << "newmtl glass\nd 0.5\nTf 1 0.5 0.25\nnewmtl leaf\nmap_d leaf.png\n";
  std::ofstream(dir + "/s.obj") << "mtllib s.mtl\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                   "v -4 0 -4\nv -4 0 4\nv 4 0 4\nv 4 0 -4\nf 1 2 3 4\n"
                                   "v -3 1 -3\nv -3 1 1\nv 1 1 1\nv 1 1 -3\nusemtl leaf\nf 5/1 6/4 7/3 8/2\n"
                                   "v -1 2 -1\nv -1 2 3\nv 3 2 3\nv 3 2 -1\nusemtl glass\nf 9/1 10/4 11/3 12/2\n";
  return dir + "/s.obj";
}

TEST(DeepFileScene, ClientAnswersWhatTheSamplerMakesOfTheFilesMaterials) {
  const std::string dir = std::string(SHADOWTILE_TEST_TMP) + "/deep_file_scene";
  const Scene s = load_scene(write_scene(dir));
  ASSERT_TRUE(s.any_partial());
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=20,elevation=70"), s.bounds());
  const DeepSampleOptions so = looptest::deep_options(0.02);
  const std::string path = dir + "/s.pack";
  constexpr uint32_t kLevel = looptest::kDeepLevel;
  const DeepMapBuild deep = looptest::build_deep_pack(s, light, so, path);
  const DeepSampler sampler(s, light);

  looptest::TestServer srv = looptest::start_server({path});
  Client c({"127.0.0.1", srv.port}, looptest::quick_options());
  Map m = c.open("s");
  ASSERT_TRUE(m.has_deep());
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> ux(-4, 4), uy(0, 2.5), uz(-4, 4);
  int compared = 0, tinted = 0, blocked = 0, lit = 0;
  for (int i = 0; i < 300; ++i) {
    const WorldPoint w{ux(rng), uy(rng), uz(rng)};
    const LightPoint p = light.to_light({w.x, w.y, w.z});
    if (!(p.u >= 0 && p.u < 1 && p.v >= 0 && p.v < 1)) continue;
    ASSERT_TRUE(looptest::wait_until([&] { return m.deep_resident(p.u, p.v, p.u, p.v); })) << i;
    const auto [x, y] = LightSpace::texel_of(kLevel, p.u, p.v);
    const auto want = sampler.texel(kLevel, x, y, so).eval(float(p.d));
    const Transmittance t = m.transmittance(w);
    EXPECT_NEAR(t.r, want[0], 2 * deep::kQuantisation) << i;
    EXPECT_NEAR(t.g, want[1], 2 * deep::kQuantisation) << i;
    EXPECT_NEAR(t.b, want[2], 2 * deep::kQuantisation) << i;
    tinted += want[0] > want[2] + 0.05f;
    blocked += want[0] < 0.4f;
    lit += want[0] == 1.0f;
    ++compared;
  }
  EXPECT_GT(compared, 150);
  EXPECT_GT(tinted, 5);   // behind the glass: (1 - d) x Tf is coloured
  EXPECT_GT(blocked, 5);  // behind solid leaf texels (and the glass)
  EXPECT_GT(lit, 5);
  srv.stop();
}

}  // namespace
}  // namespace st::client

// Deep tiles through the GPU's feedback (shaders/st_deep.glsl, GPU_LAYOUT.md "The deep
// block"): an engine's fragment shader calling st_shadow over a forest records the deep
// tiles (partial occluders) its lookups needed and the device lacked, GpuMap asks the Map
// for them, and nothing else fetches them (no deep_resident, no CPU lookup). The first
// frame's feedback names exactly the absent deep tiles under the receivers (the directory's
// tiles, less those already resident); the frames then converge to the CPU twin bit for
// bit, and the validation layer stays silent.
#include <gtest/gtest.h>

#include <bit>
#include <set>
#include <thread>

#include "shadowtile/cache_view.hpp"
#include "tests/client/deep_pack_fixture.hpp"
#include "tests/client/loopback.hpp"
#include "tests/gpu/engine_harness.hpp"
#include "tests/gpu/raster_pass.hpp"
#include "tests/gpu/shadow_twins.hpp"
#include "tiles/core/pack_format.hpp"

namespace st::gpu {
namespace {

using looptest::kDeepLevel;
using looptest::wait_until;

// Receivers over the forest: a grid across the scene, every other row on the ground (normal
// up), the others at crown heights (inside the foliage's partial shadow).
struct ForestGrid {
  static constexpr uint32_t width = 48, height = 48;
  std::vector<float> pos, nrm;
  explicit ForestGrid(const Aabb& b) : pos(size_t(width) * height * 4), nrm(pos.size(), 0.0f) {
    for (uint32_t y = 0; y < height; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const size_t p = size_t(y) * width + x;
        pos[4 * p] = float(b.lo.x + (b.hi.x - b.lo.x) * (x + 0.5) / width);
        pos[4 * p + 1] = y % 2 ? 0.0f : float(b.hi.y * (0.35 + 0.5 * double((x * 5 + y) % 11) / 10));
        pos[4 * p + 2] = float(b.lo.z + (b.hi.z - b.lo.z) * (y + 0.5) / height);
        pos[4 * p + 3] = 1.0f;
        nrm[4 * p + 1] = 1;
      }
  }
  ShadowPassInput input(const ShadowPassSettings& s) const {
    ShadowPassInput in;
    in.positions = pos, in.normals = nrm, in.width = width, in.height = height;
    in.kernel = s.kernel, in.normal_offset = s.normal_offset, in.footprint = s.footprint;
    in.neighbour_footprint = false;  // the fragment shader is given the footprint
    return in;
  }
};

TEST(GpuDeepFeedback, AForestsFragmentShaderFetchesItsDeepTilesThroughFeedbackAndConvergesToTheCpuTwin) {
  const Scene scene = make_procedural("procedural:forest,trees=4,leaves=80,size=10,translucency=0.5");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=40"), scene.bounds());
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/gpu_deep_feedback.pack";
  const DeepMapBuild deep = looptest::build_deep_pack(scene, light, looptest::deep_options(0.02), path);
  looptest::TestServer server = looptest::start_server({path});
  client::ClientOptions co = looptest::quick_options();
  co.cache_slots = 256;  // more than the deep tiles: all stay resident
  client::Client client(client::Endpoint{"127.0.0.1", server.port}, co);
  client::Map map = client.open("gpu_deep_feedback");
  ASSERT_TRUE(map.has_deep());
  const uint32_t l = map.finest_level();
  const uint64_t side = uint64_t(1) << l;
  map.request_region(l, 0, 0, side, side, 10);  // the opaque tiles: only the deep ones are left to feedback
  ASSERT_TRUE(wait_until([&] { return map.region_resident(l, 0, 0, side, side) && map.deep_level() == kDeepLevel; }));
  // One column's deep tiles resident beforehand (the first stored tile's): the feedback
  // must not name them.
  const uint32_t per_side = 1u << (kDeepLevel - deep.side_bits);
  ASSERT_FALSE(deep.tiles.empty());
  const double u0 = double(deep.tiles[0].tx) / per_side, u1 = (deep.tiles[0].tx + 0.5) / per_side;
  ASSERT_TRUE(wait_until([&] { return map.deep_resident(u0, 0, u1, 0.999); }));
  const client::CacheView view(map);
  std::set<uint64_t> resident_before;
  view.deep_tiles([&](const client::DeepTile& t) {
    resident_before.insert(kDeepTileIdBit | make_tile_id(kDeepLevel - deep.side_bits, t.tx, t.ty));
  });
  // Expected: every tile the pack stores under a receiver's surface point (the twin's float
  // light transform, no normal offset: where st_deep_shadow looks), less those resident.
  const ForestGrid grid(scene.bounds());
  ShadowPassSettings set;
  set.kernel = 3;
  set.normal_offset = 0.01f;
  set.footprint = 2.5f;
  std::set<uint64_t> stored, expected;
  for (const DeepTileBytes& t : deep.tiles) stored.insert(kDeepTileIdBit | make_tile_id(kDeepLevel - deep.side_bits, t.tx, t.ty));
  {
    ShadowPassSettings at_surface = set;
    at_surface.normal_offset = 0;
    const ShadowPassInput in0 = grid.input(at_surface);
    const ShadowLight sl = shadow_light(client::pack_header(map));
    for (size_t p = 0; p < size_t(grid.width) * grid.height; ++p) {
      uint32_t x = 0, y = 0;
      if (!shadow_pass_texel(sl, in0, p, kDeepLevel, x, y)) continue;
      const uint64_t id = kDeepTileIdBit | make_tile_id(kDeepLevel - deep.side_bits, x >> deep.side_bits, y >> deep.side_bits);
      if (stored.count(id) && !resident_before.count(id)) expected.insert(id);
    }
  }
  ASSERT_FALSE(resident_before.empty());
  ASSERT_GT(expected.size(), 4u);

  enginetest::TestEngine e(1);
  ASSERT_TRUE(e.fragment_stores) << "the device has no fragmentStoresAndAtomics";
  enginetest::Targets t(e, grid.width, grid.height, grid.pos, grid.nrm, 1);
  enginetest::Image& colour = e.image(grid.width, grid.height, VK_FORMAT_R32_SFLOAT, VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT);
  GpuOptions o;
  o.frames_in_flight = 1;
  GpuMap g(map, e.engine_device(), o);
  const enginetest::RasterPass raster(e, colour, *t.pos, *t.nrm, g.descriptors(2), true);
  uint64_t f = 0;
  auto frame = [&](uint32_t channel) {
    const enginetest::RasterPass::Frame r =
        raster.run_frame(e, g, ++f, t.readback[0], set.kernel, set.normal_offset, set.footprint, channel);
    EXPECT_EQ(r.retired.size(), 1u);
    FrameStats fs = r.retired.empty() ? FrameStats{} : r.retired.back();
    fs.bytes_uploaded = r.uploads.bytes_uploaded;
    return fs;
  };
  // Frame 1: the feedback names exactly the absent deep tiles under the receivers.
  const FrameStats first = frame(1);
  std::set<uint64_t> named;
  for (const GpuMap::FeedbackTile& ft : g.last_feedback()) {
    EXPECT_NE(ft.tile & kDeepTileIdBit, 0u) << "an opaque tile named: all were resident";
    EXPECT_GT(ft.pixels, 0u);
    named.insert(ft.tile);
  }
  EXPECT_EQ(named, expected);
  EXPECT_EQ(first.deep_wanted, expected.size());
  EXPECT_EQ(first.requested, expected.size());
  EXPECT_GT(first.holes, 0u);
  // Then: frames until no hole is left and nothing moves; the tiles came through feedback.
  bool converged = false;
  for (int i = 0; i < 60 && !converged; ++i) {
    const FrameStats fs = frame(1);
    converged = fs.holes == 0 && fs.deep_wanted == 0 && fs.bytes_uploaded == 0;
    if (!converged) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(converged);
  std::set<uint64_t> resident_after;
  view.deep_tiles([&](const client::DeepTile& d) {
    resident_after.insert(kDeepTileIdBit | make_tile_id(kDeepLevel - deep.side_bits, d.tx, d.ty));
  });
  for (uint64_t id : expected) EXPECT_TRUE(resident_after.count(id)) << id;
  EXPECT_EQ(g.stats().deep_tiles, resident_after.size());
  // The CPU twin, now that the cache holds still: the visibility and each channel of
  // st_shadow bit for bit.
  server.stop();
  ASSERT_TRUE(wait_until([&] { return !client.stats().connected; }));
  const ShadowPassInput in = grid.input(set);
  const size_t n = size_t(grid.width) * grid.height;
  std::vector<float> want_vis(n), want(3 * n);
  shadow_pass_reference(client::evaluator(map), client::pack_header(map), in, want_vis);
  shadow_pass_light_reference(map, in, want_vis, want);
  size_t bad = 0, partial = 0;
  for (uint32_t c = 0; c <= 3; ++c) {
    frame(c);
    const std::vector<float> got = t.read(f);
    for (size_t p = 0; p < n; ++p) {
      const float w = c == 0 ? want_vis[p] : want[3 * p + c - 1];
      bad += std::bit_cast<uint32_t>(got[p]) != std::bit_cast<uint32_t>(w);
      partial += c > 0 && got[p] > 0.0f && got[p] < want_vis[p];
    }
  }
  EXPECT_EQ(bad, 0u) << "values differing from the CPU twin";
  EXPECT_GT(partial, 20u);  // leaf shadows: light between shadow and full visibility
  EXPECT_EQ(e.messages(), 0u) << e.first_message();
}

}  // namespace
}  // namespace st::gpu

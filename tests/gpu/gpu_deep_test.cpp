// Deep shadow maps on the GPU (shaders/st_deep.glsl, GPU_LAYOUT.md "The deep block"): the
// deep tiles a Map holds are mirrored into GpuMap's page table (read through the public
// CacheView), and every GPU path answers the transmittance of partial occluders bit for
// bit like the CPU: evaluate_deep against the Map's own lookup (CacheView::
// deep_transmittance, what Map::transmittance calls) and the pack's DeepMap, point and
// mip-filtered, on the alpha-tested cards of procedural:forest and the volume of
// procedural:smoke; the own-device pass, the engine pass's light image and an engine's
// fragment shader calling st_shadow against their CPU twin. The validation layer stays
// silent.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>

#include "gpu/layout.hpp"
#include "shadowtile/cache_view.hpp"
#include "tests/client/deep_pack_fixture.hpp"
#include "tests/client/loopback.hpp"
#include "tests/gpu/engine_harness.hpp"
#include "tests/gpu/gpu_test_util.hpp"
#include "tests/gpu/raster_pass.hpp"
#include "tests/gpu/shadow_twins.hpp"

namespace st::gpu {
namespace gpu_deep_test {

using looptest::kDeepLevel;
using looptest::wait_until;

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

constexpr const char* kForest = "procedural:forest,trees=4,leaves=80,size=10,translucency=0.5";

struct DeepServed {
  Scene scene;
  LightSpace light;
  DeepMapBuild deep;
  std::shared_ptr<PackReader> pack;
  std::unique_ptr<PackDeepMap> local;
  looptest::TestServer server;
  std::unique_ptr<client::Client> client;
  client::Map map;
};

// A pack of `spec` with its deep part (level 5, tiles of 4^2 texels), served, and a client
// Map holding every deep tile (and, with `opaque`, every opaque tile).
std::unique_ptr<DeepServed> serve_deep(const std::string& name, const std::string& spec, bool opaque = false) {
  auto s = std::make_unique<DeepServed>();
  s->scene = make_procedural(spec);
  s->light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=40"), s->scene.bounds());
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/" + name + ".pack";
  s->deep = looptest::build_deep_pack(s->scene, s->light, looptest::deep_options(0.02), path);
  s->pack = PackReader::open(path);
  s->local = PackDeepMap::load(*s->pack);
  s->server = looptest::start_server({path});
  client::ClientOptions o = looptest::quick_options();
  o.cache_slots = 256;  // more than the deep tiles: all stay resident
  s->client = std::make_unique<client::Client>(client::Endpoint{"127.0.0.1", s->server.port}, o);
  s->map = s->client->open(name);
  EXPECT_TRUE(wait_until([&] { return s->map.deep_resident(0, 0, 0.999999, 0.999999); }));
  if (opaque) {
    const uint32_t l = s->map.finest_level();
    const uint64_t side = uint64_t(1) << l;
    s->map.request_region(l, 0, 0, side, side, 10);
    EXPECT_TRUE(wait_until([&] { return s->map.region_resident(l, 0, 0, side, side); }));
  }
  return s;
}

// Every texel centre of the deep level at up to 24 depths (a grid, the texels' stored
// vertex depths where the answer steps, random ones) as point lookups, and random points
// with footprints from a quarter texel to the whole map (every mip pair) as filtered ones:
// the GPU against the Map's lookup and the pack's DeepMap, bit for bit.
void expect_deep_bit_exact(const std::string& name, const std::string& spec) {
  const auto s = serve_deep(name, spec);
  ASSERT_TRUE(s->map.has_deep());
  ASSERT_NE(s->local, nullptr);
  const client::CacheView view(s->map);
  ASSERT_EQ(view.deep_tiles([](const client::DeepTile&) {}).level, kDeepLevel);
  GpuMap g(s->map, gputest::options());
  ASSERT_TRUE(g.has_deep());
  std::vector<float> depths;
  for (int i = 0; i <= 8; ++i) depths.push_back(float(i) / 8);
  for (const DeepTileBytes& t : s->deep.tiles) {
    const DeepTileView v = DeepTileView::open(t.bytes);
    for (uint32_t y = 0; y < v.side(0); ++y)
      for (uint32_t x = 0; x < v.side(0); ++x)
        for (const VisVertex& vx : v.function(x, y, 0).vertices) depths.push_back(vx.depth);
  }
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> ud(-0.1f, 1.1f), unit(0.0f, 1.0f);
  for (int i = 0; i < 8; ++i) depths.push_back(ud(rng));
  std::sort(depths.begin(), depths.end());
  depths.erase(std::unique(depths.begin(), depths.end()), depths.end());
  const uint32_t side = 1u << kDeepLevel;
  const size_t step = std::max<size_t>(1, depths.size() / 24);
  std::vector<GpuDeepQuery> q;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x)
      for (size_t k = (x + 7 * y) % step; k < depths.size(); k += step)
        q.push_back({(float(x) + 0.5f) / float(side), (float(y) + 0.5f) / float(side), depths[k], 0.0f});
  const size_t points = q.size();
  const float texel = 1.0f / float(side);
  for (int i = 0; i < 12000; ++i) {
    const float w = texel * std::ldexp(1.0f, int(rng() % 8) - 2) * (1.0f + unit(rng));  // 1/4 texel .. 2 maps
    q.push_back({unit(rng), unit(rng), depths[rng() % depths.size()], w});
  }
  size_t bad = 0, partial = 0, coloured = 0, filtered_partial = 0;
  std::string first;
  for (size_t b0 = 0; b0 < q.size(); b0 += 1u << 15) {
    const std::span<const GpuDeepQuery> batch(q.data() + b0, std::min<size_t>(1u << 15, q.size() - b0));
    std::vector<float> got(3 * batch.size());
    g.evaluate_deep(batch, got);
    for (size_t i = 0; i < batch.size(); ++i) {
      const GpuDeepQuery& d = batch[i];
      const auto want = view.deep_transmittance(d.u, d.v, d.depth, d.width);
      const auto local = d.width > 0 ? s->local->map().filtered(d.u, d.v, d.depth, d.width)
                                     : s->local->map().transmittance(d.u, d.v, d.depth);
      ASSERT_EQ(want, local) << "the Map and the pack disagree at query " << b0 + i;
      const bool part = want[0] < 1.0f || want[1] < 1.0f || want[2] < 1.0f;
      (b0 + i < points ? partial : filtered_partial) += part;
      coloured += want[0] != want[1];
      for (int c = 0; c < 3; ++c)
        if (bits(got[3 * i + size_t(c)]) != bits(want[size_t(c)]) && bad++ == 0)
          first = "query " + std::to_string(b0 + i) + " (" + std::to_string(d.u) + ", " + std::to_string(d.v) +
                  ") depth " + std::to_string(d.depth) + " width " + std::to_string(d.width) + " channel " +
                  std::to_string(c) + ": gpu " + std::to_string(got[3 * i + size_t(c)]) + ", cpu " +
                  std::to_string(want[size_t(c)]);
    }
  }
  EXPECT_EQ(bad, 0u) << bad << " of " << 3 * q.size() << " channels differ; first: " << first;
  EXPECT_GT(partial, points / 50) << "the scene should cast partial shadows";
  EXPECT_GT(filtered_partial, (q.size() - points) / 50);
  std::printf("%s: %zu point and %zu filtered lookups, %zu and %zu partial, %zu coloured\n", name.c_str(), points,
              q.size() - points, partial, filtered_partial, coloured);
  EXPECT_EQ(g.stats().deep_tiles, s->deep.tiles.size());
  EXPECT_EQ(g.stats().deep_tiles_dropped, 0u);
  EXPECT_EQ(g.stats().validation_messages, 0u);
  s->server.stop();
}

TEST(GpuDeep, ForestTransmittanceEqualsTheCpuOnEveryQueriedPoint) { expect_deep_bit_exact("gpu_deep_forest", kForest); }

TEST(GpuDeep, SmokeTransmittanceEqualsTheCpuOnEveryQueriedPoint) {
  expect_deep_bit_exact("gpu_deep_smoke", "procedural:smoke,res=12,size=6");
}

// A G-buffer over the forest: a grid of points across the scene, every other row on the
// ground (y = 0, normal up), the others at crown heights, a few background pixels.
struct ForestGBuffer {
  static constexpr uint32_t width = 48, height = 48;
  std::vector<float> pos, nrm;
  explicit ForestGBuffer(const Aabb& b) : pos(size_t(width) * height * 4), nrm(pos.size(), 0.0f) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> crown(0.3 * b.hi.y, 0.9 * b.hi.y);
    for (uint32_t y = 0; y < height; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const size_t p = size_t(y) * width + x;
        pos[4 * p] = float(b.lo.x + (b.hi.x - b.lo.x) * (x + 0.5) / width);
        pos[4 * p + 1] = y % 2 ? 0.0f : float(crown(rng));
        pos[4 * p + 2] = float(b.lo.z + (b.hi.z - b.lo.z) * (y + 0.5) / height);
        pos[4 * p + 3] = (x * 7 + y * 3) % 31 == 0 ? 0.0f : 1.0f;
        nrm[4 * p + 1] = 1;
      }
  }
  ShadowPassInput input(const ShadowPassSettings& s) const {
    ShadowPassInput in;
    in.positions = pos, in.normals = nrm, in.width = width, in.height = height;
    in.kernel = s.kernel, in.normal_offset = s.normal_offset;
    in.neighbour_footprint = s.neighbour_footprint, in.footprint = s.footprint;
    return in;
  }
};

// Counts channels whose bits differ; `partial`: pixels whose light is below their visibility.
size_t differing(std::span<const float> got, std::span<const float> want) {
  size_t bad = 0;
  for (size_t i = 0; i < got.size(); ++i) bad += bits(got[i]) != bits(want[i]);
  return bad;
}
size_t partial(std::span<const float> vis, std::span<const float> light) {
  size_t n = 0;
  for (size_t p = 0; p < vis.size(); ++p) n += light[3 * p] < vis[p] || light[3 * p + 2] < vis[p];
  return n;
}

// The own-device pass on a map with a deep part: the visibility as before (its CPU twin)
// and the light per channel, visibility x transmittance at the surface point, bit for bit
// its CPU twin, with a point lookup (kernel 1, footprint 0) and with the deep mips
// (kernel 3, the neighbours' footprint).
TEST(GpuDeep, ShadowPassLightIsVisibilityTimesTransmittance) {
  const auto s = serve_deep("gpu_deep_pass", kForest, true);
  GpuMap g(s->map, gputest::options());
  const ForestGBuffer gb(s->scene.bounds());
  for (const uint32_t kernel : {1u, 3u}) {
    SCOPED_TRACE(kernel);
    ShadowPassSettings set;
    set.kernel = kernel;
    set.normal_offset = 0.01f;
    set.neighbour_footprint = kernel == 3;
    set.footprint = 0;
    const ShadowPassInput in = gb.input(set);
    const size_t n = size_t(gb.width) * gb.height;
    std::vector<float> vis(n), light(3 * n), want_vis(n), want_light(3 * n);
    g.wait(g.submit_shadow_pass(in), vis, light);
    shadow_pass_reference(client::evaluator(s->map), client::pack_header(s->map), in, want_vis);
    shadow_pass_light_reference(s->map, in, vis, want_light);
    EXPECT_EQ(differing(vis, want_vis), 0u);
    EXPECT_EQ(differing(light, want_light), 0u);
    EXPECT_GT(partial(vis, light), 20u) << "some pixels should lie in the leaves' partial shadow";
  }
  EXPECT_EQ(g.stats().validation_messages, 0u);
  s->server.stop();
}

// Engine mode on a device the test owns: the engine pass's light image (rgb = visibility x
// transmittance, a = visibility) and an engine's fragment shader calling st_shadow, each
// channel bit for bit the CPU twin of the same G-buffer.
TEST(GpuDeep, EnginePassAndFragmentShaderLightEqualTheCpuTwin) {
  const auto s = serve_deep("gpu_deep_engine", kForest, true);
  s->server.stop();
  ASSERT_TRUE(wait_until([&] { return !s->client->stats().connected; }));
  const ForestGBuffer gb(s->scene.bounds());
  const size_t n = size_t(gb.width) * gb.height;
  enginetest::TestEngine e(1);
  ASSERT_TRUE(e.fragment_stores) << "the device has no fragmentStoresAndAtomics";
  enginetest::Targets t(e, gb.width, gb.height, gb.pos, gb.nrm, 1);
  enginetest::Image& light =
      e.image(gb.width, gb.height, VK_FORMAT_R32G32B32A32_SFLOAT, VK_IMAGE_USAGE_STORAGE_BIT);
  e.upload(light, std::vector<float>(4 * n, -1.0f), VK_IMAGE_LAYOUT_GENERAL);
  gpu::GpuBuffer light_back = e.host_buffer(16 * n);
  enginetest::Image& colour = e.image(gb.width, gb.height, VK_FORMAT_R32_SFLOAT, VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT);
  GpuOptions o;
  o.frames_in_flight = 1;
  o.light_pass = true;
  GpuMap g(s->map, e.engine_device(), o);
  ASSERT_TRUE(g.has_deep());
  // Frame 1: the compute pass with the light image, the neighbours' footprint, kernel 3.
  ShadowPassSettings set;
  set.kernel = 3;
  set.normal_offset = 0.01f;
  set.neighbour_footprint = true;
  uint64_t completed = 0;
  VkCommandBuffer cmd = e.begin(1, completed);
  g.retire(completed);
  g.record_uploads(cmd, 1);
  ShadowPassImages im = t.images();
  im.light = light.view;
  g.record_shadow_pass(cmd, 1, im, set);
  e.record_readback(cmd, *t.vis, VK_IMAGE_LAYOUT_GENERAL, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, t.readback[0]);
  e.record_readback(cmd, light, VK_IMAGE_LAYOUT_GENERAL, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, light_back);
  g.record_end_of_frame(cmd, 1);
  e.submit(1);
  g.retire(e.finish());
  const std::vector<float> vis = t.read(1);
  std::vector<float> got(3 * n), got_a(n), want_vis(n), want(3 * n);
  const auto* rgba = static_cast<const float*>(light_back.mapped);
  for (size_t p = 0; p < n; ++p) {
    for (int c = 0; c < 3; ++c) got[3 * p + size_t(c)] = rgba[4 * p + size_t(c)];
    got_a[p] = rgba[4 * p + 3];
  }
  ShadowPassInput in = gb.input(set);
  shadow_pass_reference(client::evaluator(s->map), client::pack_header(s->map), in, want_vis);
  shadow_pass_light_reference(s->map, in, want_vis, want);
  EXPECT_EQ(differing(vis, want_vis), 0u);
  EXPECT_EQ(differing(got_a, want_vis), 0u);
  EXPECT_EQ(differing(got, want), 0u);
  EXPECT_GT(partial(vis, got), 20u);
  // Frames 2..4: the fragment shader, one channel of st_shadow each (footprint given).
  set.neighbour_footprint = false;
  set.footprint = 2.5f;
  in = gb.input(set);
  shadow_pass_reference(client::evaluator(s->map), client::pack_header(s->map), in, want_vis);
  shadow_pass_light_reference(s->map, in, want_vis, want);
  EXPECT_EQ(g.descriptors(2).pool_view, VkBufferView(VK_NULL_HANDLE));  // storage buffers only (no texel_buffers)
  const enginetest::RasterPass raster(e, colour, *t.pos, *t.nrm, g.descriptors(2), true);
  size_t bad = 0, below = 0;
  for (uint32_t c = 1; c <= 3; ++c) {
    const uint64_t f = 1 + c;
    raster.run_frame(e, g, f, t.readback[0], set.kernel, set.normal_offset, set.footprint, c);
    const std::vector<float> frag = t.read(f);
    for (size_t p = 0; p < n; ++p) {
      bad += bits(frag[p]) != bits(want[3 * p + c - 1]);
      below += frag[p] < want_vis[p];
    }
  }
  EXPECT_EQ(bad, 0u) << "fragment shader channels differing from the CPU twin";
  EXPECT_GT(below, 20u);
  e.free_host_buffer(light_back);
  EXPECT_EQ(e.messages(), 0u) << e.first_message();
}

}  // namespace gpu_deep_test
}  // namespace st::gpu

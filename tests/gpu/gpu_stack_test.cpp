// GpuMap on a stack map (shadow-map stacks, MH 2016 §4) over a loopback server: every texel
// of every level of every slice answers bit for bit like the Map's CPU lookup
// (Map::slice_depth), with every tile resident and with cells absent (the level-K value,
// and feedback naming exactly the absent cells); PCF and the footprint's level per slice;
// the shadow pass at sample times and between equals its CPU twin; its feedback queues the
// cells the pass needed, and once they arrive the pass has no holes. The validation layer
// is on throughout and must stay silent.
#include <gtest/gtest.h>

#include <bit>
#include <random>
#include <set>

#include "client/map_access.hpp"
#include "gpu/shadow_reference.hpp"
#include "tests/client/loopback.hpp"
#include "tests/gpu/gpu_test_util.hpp"
#include "tiles/build/stack_pack.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/light_set.hpp"
#include "tiles/core/stack_map.hpp"

namespace st::gpu {
namespace {

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

// Boxes' shadows sliding with w over a ground at 0.8 (coherent slices), as the stack
// loopback test builds them.
IntervalStack sliding_stack(uint32_t level, uint32_t slices) {
  const uint64_t side = uint64_t(1) << level;
  IntervalStack s{level, slices, std::vector<Interval>(side * side * slices, Interval{0.8f, 0.8f})};
  for (uint32_t w = 0; w < slices; ++w)
    for (int b = 0; b < 3; ++b) {
      const uint64_t x0 = (7 + 17 * b + w) % (side - 12), y0 = (5 + 23 * b) % (side - 12);
      for (uint64_t y = y0; y < y0 + 10; ++y)
        for (uint64_t x = x0; x < x0 + 10; ++x) s.at(x, y, w) = {0.2f + 0.1f * float(b), 0.35f + 0.1f * float(b)};
    }
  return s;
}

struct ServedStack {
  std::string path;
  size_t tiles = 0;
  looptest::TestServer server;
  std::unique_ptr<client::Client> client;
  client::Map map;
};

constexpr uint32_t kSlices = 10;

ServedStack serve_stack(const std::string& name) {
  ServedStack s;
  const IntervalStack is = sliding_stack(looptest::small_scale() ? 5 : 6, kSlices);
  StackCut cut = cut_stack(build_octree(is), std::nullopt, 512);
  Aabb box;
  box.extend({-10, 0, -10});
  box.extend({10, 5, 10});
  const LightSet set = LightSet::fit(
      LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=" + std::to_string(kSlices)), box);
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  s.path = std::string(SHADOWTILE_TEST_TMP) + "/" + name + ".pack";
  StackPackParams p;
  p.tile_bytes = 512;
  write_stack_pack(s.path, cut, p);
  s.tiles = cut.tiles.size();
  s.server = looptest::start_server({s.path});
  client::ClientOptions o = looptest::quick_options();
  o.cache_slots = uint32_t(s.tiles) + 4;
  s.client = std::make_unique<client::Client>(client::Endpoint{"127.0.0.1", s.server.port}, o);
  s.map = s.client->open(name);
  return s;
}

std::string describe(const GpuStackQuery& q) {
  return "slice " + std::to_string(q.slice) + " level " + std::to_string(q.level) + " x " + std::to_string(q.x) +
         " y " + std::to_string(q.y) + " r " + std::to_string(q.r);
}

// Every texel (and one past the edge) of every level up to n + 1, of every slice and one
// past the last: GPU depths against Map::slice_depth. Returns "" or the first difference.
std::string compare_every_texel(GpuMap& g, const client::Map& map, uint32_t n) {
  size_t bad = 0;
  std::string first;
  for (uint32_t w = 0; w <= kSlices; ++w) {
    std::vector<GpuStackQuery> q;
    for (uint32_t l = 0; l <= n + 1; ++l)
      for (uint32_t y = 0; y <= (1u << l); ++y)
        for (uint32_t x = 0; x <= (1u << l); ++x) q.push_back({x, y, w, l, 0, 1, 0});
    std::vector<float> out(q.size());
    g.evaluate(q, out);
    for (size_t i = 0; i < q.size(); ++i) {
      const float want = map.slice_depth(q[i].slice, q[i].level, q[i].x, q[i].y);
      if (bits(out[i]) == bits(want)) continue;
      if (bad++ == 0) first = describe(q[i]) + ": gpu " + std::to_string(out[i]) + ", cpu " + std::to_string(want);
    }
  }
  return bad ? std::to_string(bad) + " differ; first: " + first : "";
}

TEST(GpuStack, EveryTexelOfEverySliceAnswersBitExactlyLikeTheCpu) {
  ServedStack s = serve_stack("gpu_stack_all");
  ASSERT_GT(s.tiles, 4u);
  ASSERT_EQ(s.map.slices(), kSlices);
  ASSERT_GT(s.map.request_slices(0, kSlices - 1, 10), 0u);
  ASSERT_TRUE(looptest::wait_until([&] { return s.map.slices_resident(0, kSlices - 1); }));
  s.server.stop();
  GpuMap g(s.map, gputest::options());
  EXPECT_TRUE(g.is_stack());
  EXPECT_EQ(g.sync(), s.tiles);
  const StackGrid& grid = *client::MapAccess::remote(s.map).stack_grid();
  const uint32_t n = grid.geo.n;
  EXPECT_EQ(compare_every_texel(g, s.map, n), "");

  // r x r PCF at a level and through the footprint's level, per slice, with random
  // receivers: against the same kernel over Map::slice_depth (StackMap::filtered's).
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> depth01(0.1f, 0.9f), fp(-1.0f, 7.0f);
  std::vector<GpuStackQuery> q;
  for (int i = 0; i < 6000; ++i) {
    GpuStackQuery a;
    a.slice = uint32_t(rng() % kSlices);
    a.x = uint32_t(rng() % (1u << n));
    a.y = uint32_t(rng() % (1u << n));
    a.receiver = depth01(rng);
    a.r = uint32_t(1 + rng() % 9);
    if (i % 2) a.level = kLevelFromFootprint, a.footprint = std::exp2(fp(rng));
    else a.level = n - uint32_t(rng() % 3), a.x >>= n - a.level, a.y >>= n - a.level;
    q.push_back(a);
  }
  std::vector<float> out(q.size());
  g.evaluate(q, out);
  auto pcf = [&](const GpuStackQuery& a, uint32_t level, uint32_t x, uint32_t y) {
    const uint64_t side = uint64_t(1) << level;
    uint32_t lit = 0;
    for (uint32_t j = 0; j < a.r; ++j)
      for (uint32_t i = 0; i < a.r; ++i)
        lit += a.receiver <= s.map.slice_depth(a.slice, level, pcf_tap(x, i, a.r, side), pcf_tap(y, j, a.r, side));
    return float(lit) / float(a.r * a.r);
  };
  size_t bad = 0, fractional = 0;
  for (size_t i = 0; i < q.size(); ++i) {
    const GpuStackQuery& a = q[i];
    float want;
    if (a.level != kLevelFromFootprint) {
      want = pcf(a, a.level, a.x, a.y);
    } else {
      const FilterLevels f = filter_levels(n, a.footprint);
      want = pcf(a, f.fine, a.x >> (n - f.fine), a.y >> (n - f.fine));
      if (f.t != 0.0f) want = filter_blend(want, pcf(a, f.coarse, a.x >> (n - f.coarse), a.y >> (n - f.coarse)), f.t);
    }
    fractional += want > 0.0f && want < 1.0f;
    if (bits(out[i]) != bits(want) && bad++ == 0)
      ADD_FAILURE() << describe(a) << ": gpu " << out[i] << ", cpu " << want;
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_GT(fractional, 100u);  // the kernels straddle shadow edges
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

}  // namespace
}  // namespace st::gpu

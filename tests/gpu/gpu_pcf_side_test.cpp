// The GPU module takes PCF as the kernel side too (client.hpp "PCF"): a query's r is 0
// (the depth) or odd 1..9, a shadow pass's kernel odd 1..9; anything else is a GpuError
// naming it, before anything is submitted, and the map keeps answering afterwards.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "tests/client/loopback.hpp"
#include "tests/gpu/gpu_test_util.hpp"

namespace st::gpu {
namespace gpu_pcf_side_test {

TEST(GpuPcfSide, EvenZeroAndLargeKernelsAreRefusedByName) {
  auto pack = looptest::build_pack("gpu_pcf_side", 5, 3, looptest::first_encoding(), 2, 512);
  looptest::TestServer srv = looptest::start_server({pack.path});
  client::ClientOptions o = looptest::quick_options();
  o.cache_slots = uint32_t(pack.reader->tiles().size()) + 4;
  client::Client c({"127.0.0.1", srv.port}, o);
  client::Map map = c.open("gpu_pcf_side");
  GpuMap g(map, gputest::options());
  auto error_of = [](auto&& call) -> std::string {
    try {
      call();
    } catch (const GpuError& e) {
      return e.what();
    }
    return "";
  };
  std::vector<float> out(3);
  for (uint32_t r : {2u, 4u, 8u, 10u, 11u, 0xFFFFFFFFu}) {
    const std::vector<GpuQuery> q = {{1, 1, 0.5f, 1, 3, 5}, {2, 2, 0.5f, 1, 0, 5}, {3, 3, 0.5f, 1, r, 5}};
    const std::string why = error_of([&] { g.evaluate(q, out); });
    EXPECT_NE(why.find("query 2: r " + std::to_string(r) + " is neither 0 (the depth) nor a PCF kernel side (odd, 1..9)"),
              std::string::npos)
        << r << ": '" << why << "'";
  }
  std::vector<float> pos(4 * 4, 0.0f), nrm(4 * 4, 0.0f);
  for (uint32_t k : {0u, 2u, 4u, 10u, 11u}) {
    ShadowPassInput in;
    in.positions = pos;
    in.normals = nrm;
    in.width = 2, in.height = 2;
    in.kernel = k;
    const std::string why = error_of([&] { (void)g.submit_shadow_pass(in); });
    EXPECT_NE(why.find("kernel " + std::to_string(k) + " is not a PCF kernel side (odd, 1..9)"), std::string::npos)
        << k << ": '" << why << "'";
  }
  // Valid sides and depth queries still answer, in [0, 1].
  const std::vector<GpuQuery> ok = {{1, 1, 0.5f, 1, 1, 5}, {2, 2, 0.5f, 1, 9, 5}, {3, 3, 0.5f, 1, 0, 5}};
  EXPECT_NO_THROW(g.evaluate(ok, out));
  for (float v : out) {
    EXPECT_GE(v, 0.0f);
    EXPECT_LE(v, 1.0f);
  }
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

// st_pcf counts a kernel's taps in blocks: a tap's answer holds for the square of texels
// its page-table walk and tile path share (a value, a leaf, a missing child, an empty
// treelet subtree), so every tap of the kernel in that square counts with it (blocks may
// overlap). The count must stay the per-tap count: every texel of every level,
// every kernel side, against the CPU's PCF, with each receiver at (or one float either side
// of) the depth of one of its own taps, so a run that swallowed a tap of another depth
// flips the count; and receivers below and above every depth (all lit, none). The random field mixes constant blocks (wide missing children), noise
// (treelets), slopes and lit blocks; the map edges clamp taps.
TEST(GpuPcfSide, KernelRunsCountEveryTapLikeTheCpu) {
  for (Encoding e : looptest::available_encodings()) {
    SCOPED_TRACE(to_string(e));
    const std::string name = "gpu_pcf_runs_" + to_string(e);
    auto pack = looptest::build_pack(name, 6, 23, e, 2, 512);
    looptest::TestServer srv = looptest::start_server({pack.path});
    client::ClientOptions o = looptest::quick_options();
    o.cache_slots = uint32_t(pack.reader->tiles().size()) + 4;
    client::Client c({"127.0.0.1", srv.port}, o);
    client::Map map = c.open(name);
    const uint32_t finest = map.finest_level();
    const uint64_t side = uint64_t(1) << finest;
    map.request_region(finest, 0, 0, side, side, 10);
    ASSERT_TRUE(looptest::wait_until([&] { return map.region_resident(finest, 0, 0, side, side); }));
    GpuMap g(map, gputest::options());
    g.sync();
    std::mt19937_64 rng(5);
    std::vector<GpuQuery> q;
    for (uint32_t level : {finest, finest - 1, finest - 3})
      for (uint32_t y = 0; y < (1u << level); ++y)
        for (uint32_t x = 0; x < (1u << level); ++x) {
          const uint32_t r = uint32_t(1 + 2 * (rng() % 5)), h = (r - 1) / 2, n = 1u << level;
          auto tap = [&](uint32_t t, uint32_t i) { return uint32_t(std::clamp<int>(int(t) - int(h) + int(i), 0, int(n) - 1)); };
          float d = map.depth(level, tap(x, uint32_t(rng() % r)), tap(y, uint32_t(rng() % r)));
          const uint32_t nudge = uint32_t(rng() % 5);
          if (nudge == 1) d = std::nextafter(d, -1.0f);
          if (nudge == 2) d = std::nextafter(d, 2.0f);
          if (nudge == 3) d = -0.0f;  // below every depth: all lit
          if (nudge == 4) d = 2.0f;   // above every depth: none lit
          q.push_back({x, y, d, 1, r, level});
        }
    std::vector<float> out(q.size());
    g.evaluate(q, out);
    size_t bad = 0;
    std::string first;
    for (size_t i = 0; i < q.size(); ++i) {
      const float want = map.pcf(q[i].level, q[i].x, q[i].y, q[i].r, q[i].receiver);
      if (std::bit_cast<uint32_t>(want) == std::bit_cast<uint32_t>(out[i])) continue;
      if (bad++ == 0)
        first = "level " + std::to_string(q[i].level) + " (" + std::to_string(q[i].x) + ", " + std::to_string(q[i].y) +
                ") r " + std::to_string(q[i].r) + ": gpu " + std::to_string(out[i]) + ", cpu " + std::to_string(want);
    }
    EXPECT_EQ(bad, 0u) << first;
    EXPECT_EQ(g.stats().validation_messages, 0u);
    srv.stop();
  }
}

}  // namespace gpu_pcf_side_test
}  // namespace st::gpu

// The GPU module takes PCF as the kernel side too (client.hpp "PCF"): a query's r is 0
// (the depth) or odd 1..9, a shadow pass's kernel odd 1..9; anything else is a GpuError
// naming it, before anything is submitted, and the map keeps answering afterwards.
#include <gtest/gtest.h>

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

}  // namespace gpu_pcf_side_test
}  // namespace st::gpu

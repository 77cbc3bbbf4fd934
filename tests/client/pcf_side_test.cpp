// PCF takes one unit in the public API, the kernel side (client.hpp "PCF"): odd, 1..9.
// Every lookup answers NaN for any other side (0, even, above 9), every element of a
// batch included and nothing past the batch; valid sides answer what the map's own
// kernels answer (Evaluator::pcf, the internal radius-based lookups), bit for bit.
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>
#include <vector>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"

namespace st::client {
namespace pcf_side_test {

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

const std::vector<uint32_t> kBadSides = {0, 2, 4, 6, 8, 10, 11, 12, 1000, std::numeric_limits<uint32_t>::max()};
const std::vector<uint32_t> kGoodSides = {1, 3, 5, 7, 9};

TEST(PcfSide, TheValidSidesAreTheOddOnesUpToNine) {
  for (uint32_t s = 0; s < 64; ++s) EXPECT_EQ(pcf_side_valid(s), s % 2 == 1 && s <= kMaxPcfSide) << s;
  EXPECT_FALSE(pcf_side_valid(std::numeric_limits<uint32_t>::max()));
  static_assert(pcf_side_valid(1) && pcf_side_valid(kMaxPcfSide) && !pcf_side_valid(kMaxPcfSide + 2));
}

// A default-constructed Map answers like an empty map (lit), but an invalid side is still
// NaN: the unit is checked before anything else.
TEST(PcfSide, AnEmptyMapRefusesInvalidSidesToo) {
  const Map none;
  const WorldPoint p{0, 0, 0};
  std::vector<WorldPoint> pts(5, p);
  std::vector<float> out(7, -1.0f);
  const std::vector<float> fp(5, 0.5f);
  for (uint32_t s : kGoodSides) {
    EXPECT_EQ(none.visibility(p, s), 1.0f);
    EXPECT_EQ(none.soft_visibility(p, s), 1.0f);
  }
  for (uint32_t s : kBadSides) {
    EXPECT_TRUE(std::isnan(none.pcf(0, 0, 0, s, 0.5f))) << s;
    EXPECT_TRUE(std::isnan(none.visibility(p, s))) << s;
    EXPECT_TRUE(std::isnan(none.visibility_filtered(p, 0.5f, s))) << s;
    EXPECT_TRUE(std::isnan(none.time_visibility(p, 0.5, s))) << s;
    EXPECT_TRUE(std::isnan(none.time_visibility_filtered(p, 0.5, 0.5f, s))) << s;
    EXPECT_TRUE(std::isnan(none.soft_visibility(p, s))) << s;
    EXPECT_TRUE(std::isnan(none.soft_visibility_filtered(p, 0.5f, s))) << s;
    std::fill(out.begin(), out.end(), -1.0f);
    none.soft_visibility(pts, out, s);
    for (size_t i = 0; i < out.size(); ++i) EXPECT_EQ(std::isnan(out[i]), i < pts.size()) << s << " " << i;
  }
}

TEST(PcfSide, ServedMapAnswersValidSidesExactlyAndInvalidOnesNaN) {
  const uint32_t level = 7;
  auto pack = looptest::build_pack("pcf_side", level, 23, looptest::first_encoding(), 3, 4096);
  looptest::TestServer srv = looptest::start_server({pack.path});
  ClientOptions o = looptest::quick_options();
  o.cache_slots = uint32_t(pack.reader->tiles().size()) + 8;
  Client c({"127.0.0.1", srv.port}, o);
  Map m = c.open("pcf_side");
  const uint64_t side = uint64_t(1) << level;
  m.request_region(level, 0, 0, side, side, 10);
  ASSERT_TRUE(looptest::wait_until([&] { return m.region_resident(level, 0, 0, side, side); }));
  const RemoteMap& rm = MapAccess::remote(m);
  const Evaluator& ev = evaluator(m);

  // Texel kernels: the side is the Evaluator's own r; invalid sides NaN.
  for (uint64_t i = 0; i < 200; ++i) {
    const uint64_t x = (i * 37) % side, y = (i * 91) % side;
    const float d = float(i % 17) / 16.0f;
    for (uint32_t s : kGoodSides) {
      const float v = m.pcf(level, x, y, s, d);
      ASSERT_EQ(bits(v), bits(ev.pcf(level, x, y, s, d))) << s;
      ASSERT_NEAR(v * float(s * s), std::nearbyint(v * float(s * s)), 1e-3) << "not a fraction of " << s * s << " taps";
    }
    for (uint32_t s : kBadSides) ASSERT_TRUE(std::isnan(m.pcf(level, x, y, s, d))) << s;
  }

  // World points along texel rays: side 2R+1 is the internal lookups' radius R.
  const LightTransform& lt = m.info().light;
  std::vector<WorldPoint> pts;
  std::vector<float> footprints;
  for (uint64_t i = 0; i < 400; ++i) {
    const double u = (double((i * 53) % side) + 0.5) / double(side), v = (double((i * 29) % side) + 0.5) / double(side);
    pts.push_back(lt.to_world({u, v, double(i % 23) / 22.0}));
    footprints.push_back(float(lt.texel_size(pts.back(), level)) * float(1 + i % 9));
  }
  std::vector<float> batch(pts.size() + 3), filtered(pts.size() + 3);
  for (uint32_t s : kGoodSides) {
    std::fill(batch.begin(), batch.end(), -1.0f);
    m.visibility(pts, batch, s);
    m.visibility_filtered(pts, footprints, filtered, s);
    for (size_t i = 0; i < pts.size(); ++i) {
      const Vec3d w{pts[i].x, pts[i].y, pts[i].z};
      ASSERT_EQ(bits(m.visibility(pts[i], s)), bits(rm.visibility(w, (s - 1) / 2))) << s << " " << i;
      ASSERT_EQ(bits(batch[i]), bits(m.visibility(pts[i], s))) << s << " " << i;
      ASSERT_EQ(bits(filtered[i]), bits(m.visibility_filtered(pts[i], footprints[i], s))) << s << " " << i;
      ASSERT_GE(batch[i], 0.0f);
      ASSERT_LE(batch[i], 1.0f);
    }
    EXPECT_EQ(batch[pts.size()], -1.0f);
  }
  // The default is the single tap.
  for (size_t i = 0; i < pts.size(); ++i) ASSERT_EQ(bits(m.visibility(pts[i])), bits(m.visibility(pts[i], 1)));
  for (uint32_t s : kBadSides) {
    std::fill(batch.begin(), batch.end(), -1.0f);
    std::fill(filtered.begin(), filtered.end(), -1.0f);
    m.visibility(pts, batch, s);
    m.visibility_filtered(pts, footprints, filtered, s);
    for (size_t i = 0; i < batch.size(); ++i) {
      ASSERT_EQ(std::isnan(batch[i]), i < pts.size()) << s << " " << i;
      ASSERT_EQ(std::isnan(filtered[i]), i < pts.size()) << s << " " << i;
    }
    EXPECT_EQ(batch.back(), -1.0f);
    EXPECT_TRUE(std::isnan(m.visibility(pts[0], s)));
    EXPECT_TRUE(std::isnan(m.visibility_filtered(pts[0], footprints[0], s)));
  }
}

}  // namespace pcf_side_test
}  // namespace st::client

// The log rate limit: a burst passes, a flood is counted instead of written, and the
// next line written says how many were dropped; kinds do not share a budget.
#include <gtest/gtest.h>

#include "server/log_throttle.hpp"

namespace st::server {
namespace {

using namespace std::chrono_literals;

TEST(LogThrottle, BurstThenCountedThenSaysHowManyWereDropped) {
  LogThrottle t(5, 1);
  const auto t0 = LogThrottle::Clock::now();
  int written = 0;
  for (int i = 0; i < 3000; ++i)  // 3,000 wrong keys within a millisecond
    written += t.admit("auth", "wrong key", t0 + std::chrono::microseconds(i / 10)).has_value();
  EXPECT_EQ(written, 5);
  auto later = t.admit("auth", "wrong key", t0 + 2s);
  ASSERT_TRUE(later);
  EXPECT_NE(later->find("2995 similar line(s) suppressed"), std::string::npos) << *later;
  // Another kind has its own budget.
  EXPECT_TRUE(t.admit("tile", "tile read failed", t0 + 2s));
  // Steady at the refill rate: every line passes.
  for (int s = 3; s < 20; ++s) EXPECT_EQ(t.admit("auth", "x", t0 + std::chrono::seconds(s)), std::string("x"));
}

}  // namespace
}  // namespace st::server

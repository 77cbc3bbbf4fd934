// The soak's view of a server: /proc status parsing, histogram quantiles, interval
// figures from two GetStats snapshots of a live in-process server.
#include <gtest/gtest.h>

#include <unistd.h>

#include <ctime>

#include "client/map_access.hpp"
#include "load_fixture.hpp"
#include "loadgen/server_watch.hpp"
#include "common/error.hpp"

namespace st::loadgen {
namespace {

TEST(ServerWatch, ParsesProcStatus) {
  const ProcMemory m = parse_proc_status("Name:\tshadowtile\nVmHWM:\t  204800 kB\nVmRSS:\t  102400 kB\nThreads:\t7\n");
  EXPECT_TRUE(m.alive);
  EXPECT_EQ(m.rss_bytes, 100ull << 20);
  EXPECT_EQ(m.hwm_bytes, 200ull << 20);
  EXPECT_EQ(m.threads, 7u);
  EXPECT_FALSE(parse_proc_status("Name:\tzombie\nState:\tZ (zombie)\nThreads:\t1\n").alive);
  const auto burn_until = std::clock() + CLOCKS_PER_SEC / 20;  // 50 ms of CPU: a few ticks
  while (std::clock() < burn_until) {
  }
  const ProcMemory self = read_proc_memory(::getpid());
  EXPECT_TRUE(self.alive);
  EXPECT_GT(self.rss_bytes, 0u);
  EXPECT_GE(self.hwm_bytes, self.rss_bytes);
  EXPECT_GT(self.cpu_seconds, 0.0);
  EXPECT_FALSE(read_proc_memory(0).alive);
  EXPECT_FALSE(read_proc_memory(-5).alive);
}

TEST(ServerWatch, ParsesProcStatCpuTimes) {
  // comm with a space and a ')' inside; utime 250, stime 50 ticks at 100 Hz = 3 s.
  const std::string stat = "4242 (a b) c) S 1 4242 4242 0 -1 4194560 100 0 0 0 250 50 0 0 20 0 8 0 1 2 3";
  EXPECT_DOUBLE_EQ(parse_proc_stat_cpu(stat, 100), 3.0);
  EXPECT_EQ(parse_proc_stat_cpu("4242 (x) S 1 2", 100), -1);
  EXPECT_EQ(parse_proc_stat_cpu("no parenthesis", 100), -1);
}

TEST(ServerWatch, HistogramQuantilesAreBucketBounds) {
  const std::vector<uint64_t> upper = {0, 1, 3, 7, 15, ~uint64_t(0)};
  EXPECT_EQ(histogram_quantile(upper, {0, 0, 0, 0, 0, 0}, 0.99), 0u);
  // 100 samples: 98 in [2,4), one in [8,16), one in the open bucket.
  const std::vector<uint64_t> c = {0, 0, 98, 0, 1, 1};
  EXPECT_EQ(histogram_quantile(upper, c, 0.5), 4u);
  EXPECT_EQ(histogram_quantile(upper, c, 0.98), 4u);  // rank 98 of 100
  EXPECT_EQ(histogram_quantile(upper, c, 0.99), 16u);  // rank 99
  EXPECT_EQ(histogram_quantile(upper, c, 1.0), ~uint64_t(0));
  EXPECT_EQ(histogram_quantile(upper, {1, 2}, 0.5), 0u);  // shapes differ: no answer
}

TEST(ServerWatch, IntervalFiguresFromALiveServer) {
  const auto& pack = loadtest::city_pack(11);
  auto srv = loadtest::start_server("city", pack.path);
  client::Client c({"127.0.0.1", srv->port()});
  client::Map m = c.open("city");
  const ServerSample a = sample_from(c.server_stats(), 0.0);
  const uint32_t L = m.finest_level(), side = 1u << L;
  m.request_region(L, 0, 0, side / 4, side / 4, 1);
  for (int i = 0; i < 20000 && !m.region_resident(L, 0, 0, side / 4, side / 4); ++i)
    usleep(1000);
  ASSERT_TRUE(m.region_resident(L, 0, 0, side / 4, side / 4));
  const ServerSample b = sample_from(c.server_stats(), 2.0);
  const IntervalFigures f = interval_between(a, b);
  EXPECT_EQ(f.dt, 2.0);
  EXPECT_EQ(f.connections_open, 1u);
  const uint64_t tiles = b.counter("tiles_sent") - a.counter("tiles_sent");
  EXPECT_EQ(tiles, m.stats().tiles_received);
  EXPECT_DOUBLE_EQ(f.tiles_per_s, double(tiles) / 2.0);
  EXPECT_GT(f.requests_per_s, 0.0);
  EXPECT_GT(f.latency_count, 0u);
  EXPECT_GE(f.p99_us, f.p50_us);
  EXPECT_GT(f.p99_us, 0u);
  EXPECT_EQ(f.errors, 0u);
  // A sample without the histogram is refused with a clear error.
  client::ServerStats bare;
  bare.counters.push_back({"requests", 1});
  EXPECT_THROW(sample_from(bare, 0), Error);
  srv->stop();
}

}  // namespace
}  // namespace st::loadgen

// A short deterministic load run against an in-process server: the counters add up.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <dirent.h>

#include <algorithm>
#include <cmath>
#include <atomic>
#include <thread>

#include "load_fixture.hpp"
#include "loadgen/load_report.hpp"
#include "loadgen/load_run.hpp"

namespace st::loadgen {
namespace {

size_t thread_count() {
  size_t n = 0;
  if (DIR* d = ::opendir("/proc/self/task")) {
    while (dirent* e = ::readdir(d))
      if (e->d_name[0] != '.') ++n;
    ::closedir(d);
  }
  return n;
}

LoadResult run(PathKind path, uint32_t cameras, uint32_t connections, double cache_mb, uint32_t workers = 0,
               uint32_t io_threads = 2) {
  const auto& pack = loadtest::city_pack(11);
  auto srv = loadtest::start_server("city", pack.path);
  LoadOptions o;
  o.workers = workers;
  o.io_threads = io_threads;
  o.endpoint = {"127.0.0.1", srv->port()};
  o.map = "city";
  o.cameras = cameras;
  o.connections = connections;
  o.path = path;
  o.duration = loadtest::small_scale() ? 1.0 : 2.0;
  o.rate = 30;
  o.cache_mb = cache_mb;
  o.seed = 3;
  LoadResult r = run_load(o);
  srv->stop();
  return r;
}

void expect_counters_add_up(const LoadResult& r) {
  EXPECT_EQ(r.errors(), 0u) << load_table(r);
  EXPECT_TRUE(r.drained) << load_table(r);
  // Every sent request was answered with the tile or cancelled; none failed.
  EXPECT_EQ(r.map.tiles_requested, r.map.tiles_received + r.map.tiles_cancelled + r.map.tiles_failed);
  EXPECT_EQ(r.map.tiles_failed, 0u);
  EXPECT_GT(r.map.tiles_received, 0u);
  EXPECT_GT(r.map.bytes_received, 0u);
  // The cache never held more slots than its budget.
  EXPECT_LE(r.peak_slots_used, r.cache_slots);
  EXPECT_EQ(r.map.cache_full, 0u);
  // Every scheduled frame ran, or was skipped because the run was past its duration (a
  // machine too busy for the rate: the duration holds), each camera cut at least once at
  // its start.
  const uint64_t per_camera = uint64_t(r.options.duration * r.options.rate);
  EXPECT_EQ(r.frames + r.frames_skipped, per_camera * r.options.cameras);
  EXPECT_GT(r.frames, 0u);
  EXPECT_GE(r.cuts, r.options.cameras);
  EXPECT_EQ(r.cuts, r.cut_residency_ms.size() + r.cuts_incomplete);
  EXPECT_LE(r.frames_with_holes, r.frames);
  EXPECT_LE(r.cells_missing, r.cells_needed);
  EXPECT_EQ(r.lookups, r.lookups);  // counted
  EXPECT_GT(r.lookups, 0u);
  // Every frame's work was timed; a 2D map has no slice crossings.
  EXPECT_EQ(r.frame_times.frames, r.frames);
  EXPECT_GT(r.frame_times.max_ms, 0.0);
  EXPECT_LE(r.frame_times.percentile_ms(.5), r.frame_times.percentile_ms(.99));
  EXPECT_LE(r.frame_times.percentile_ms(.99), r.frame_times.max_ms);
  EXPECT_LE(r.frame_times.mean_ms(), r.frame_times.max_ms);
  EXPECT_EQ(r.crossing_times.frames, 0u);
  // JSON names the totals the table shows.
  const std::string j = load_json(r);
  EXPECT_NE(j.find("\"requested\": " + std::to_string(r.map.tiles_requested)), std::string::npos);
  // The percentile curve the HTML page draws: q rising from 0 to 1, latency never falling,
  // from the fastest cell to the slowest.
  const auto curve = nlohmann::json::parse(j)["latency_ms"]["percentiles"];
  ASSERT_EQ(curve.empty(), r.latency_ms.empty());
  if (!curve.empty()) {
    EXPECT_EQ(curve.front()[0].get<double>(), 0.0);
    EXPECT_EQ(curve.back()[0].get<double>(), 1.0);
    EXPECT_EQ(curve.front()[1].get<double>(), *std::min_element(r.latency_ms.begin(), r.latency_ms.end()));
    EXPECT_EQ(curve.back()[1].get<double>(), *std::max_element(r.latency_ms.begin(), r.latency_ms.end()));
    for (size_t i = 1; i < curve.size(); ++i) {
      EXPECT_GT(curve[i][0].get<double>(), curve[i - 1][0].get<double>());
      EXPECT_GE(curve[i][1].get<double>(), curve[i - 1][1].get<double>());
    }
  }
}

// The frame-time histogram: exact count, mean and maximum; a percentile is the upper edge
// of its bucket, at most one bucket (2^(1/8), about 9%) above the exact value.
TEST(LoadFrameTimes, PercentilesLieWithinOneBucketOfTheExactValue) {
  FrameTimes a, b;
  for (int i = 1; i <= 100; ++i) (i % 2 ? a : b).add(0.1 * i);  // 0.1 .. 10 ms
  a.merge(b);
  EXPECT_EQ(a.frames, 100u);
  EXPECT_NEAR(a.mean_ms(), 5.05, 1e-9);
  EXPECT_EQ(a.max_ms, 10.0);
  EXPECT_EQ(a.percentile_ms(1), 10.0);
  for (double p : {0.01, 0.5, 0.9, 0.99}) {
    const double exact = 0.1 * std::ceil(p * 100);
    EXPECT_GE(a.percentile_ms(p), exact - 1e-12) << p;
    EXPECT_LE(a.percentile_ms(p), exact * std::exp2(1.0 / FrameTimes::kBucketsPerOctave) + 1e-12) << p;
  }
  FrameTimes empty;
  EXPECT_EQ(empty.percentile_ms(.5), 0.0);
  EXPECT_EQ(empty.mean_ms(), 0.0);
  FrameTimes huge;  // beyond the last bucket: counted there, the maximum exact
  huge.add(1e9);
  EXPECT_EQ(huge.percentile_ms(.5), 1e9);
}

TEST(LoadRun, FlyoverCountersAddUp) {
  const LoadResult r = run(PathKind::flyover, 3, 2, 64);
  expect_counters_add_up(r);
  EXPECT_GT(r.latency_ms.size(), 0u);
}

TEST(LoadRun, TeleportWithATinyCacheEvictsButNeverExceedsIt) {
  // 1.5 MiB: the request table, page reserve and preview first, then slots of the pack's
  // slot size + client::kSlotOverheadBytes each (client.hpp cache_bytes).
  const LoadResult r = run(PathKind::teleport, 2, 1, 1.5);
  expect_counters_add_up(r);
  EXPECT_LE(r.map.accounted_bytes, uint64_t(1.5 * 1048576));
  EXPECT_GE(r.cache_slots, 8u);
  EXPECT_LE(r.cache_slots, 1.5 * 1048576 / (r.slot_bytes + client::kSlotOverheadBytes)) << "slot bytes " << r.slot_bytes;
  EXPECT_GE(r.cuts, 2u * uint64_t(r.options.duration / kTeleportSeconds));
}

// Many cameras on as many connections run on a few threads (camera workers + the shared
// client I/O pool + the watcher), not two threads per camera, and still add up.
TEST(LoadRun, ManyConnectionsOnAFewThreads) {
  const uint32_t n = loadtest::small_scale() ? 16 : 48;
  (void)loadtest::city_pack(11);  // built before counting threads (the build uses a pool)
  const size_t before = thread_count();
  std::atomic<bool> done{false};
  std::atomic<size_t> peak{0};
  std::thread sampler([&] {
    while (!done) {
      peak = std::max(peak.load(), thread_count());
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  const LoadResult r = run(PathKind::flyover, n, n, 2, 2, 1);  // 2 MiB each: the request table and a few slots (client.hpp cache_bytes)
  done = true;
  sampler.join();
  expect_counters_add_up(r);
  EXPECT_EQ(r.connections, n);
  EXPECT_EQ(r.workers, 2u);
  EXPECT_EQ(r.client.connects, n);
  EXPECT_EQ(r.client.disconnects, 0u);
  // server (1 I/O thread + its signal/control) + sampler + 2 workers + 1 I/O + watcher
  // + the probe client's thread + resolver helpers: far below 2 per camera.
  EXPECT_LE(peak.load(), before + 12) << "threads before " << before;
}

TEST(LoadRun, PathsAreDeterministic) {
  const auto& pack = loadtest::city_pack(11);
  auto reader = PackReader::open(pack.path);
  const WorldFrame w = world_frame(reader->header(), reader->grid());
  EXPECT_LT(w.ground, w.top);
  for (PathKind k : {PathKind::flyover, PathKind::orbit, PathKind::walk, PathKind::teleport}) {
    const CameraPath a(k, w, 5, 1), b(k, w, 5, 1), c(k, w, 6, 1);
    for (double t : {0.0, 0.4, 1.7, 5.0}) {
      EXPECT_EQ(a.at(t).pos, b.at(t).pos);
      EXPECT_EQ(a.at(t).target, b.at(t).target);
    }
    EXPECT_NE(a.at(1.7).pos, c.at(1.7).pos);
  }
}

}  // namespace
}  // namespace st::loadgen

// Server counters: connections, requests, tiles, bytes, errors and a latency histogram.
// Updated from the I/O threads with relaxed atomics (counters, not synchronization);
// snapshot() reads them for the periodic log line and for the protocol's Stats answer.
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace st::server {

// Log2 latency buckets in microseconds: bucket b counts latencies in [2^(b-1), 2^b) us
// (bucket 0: < 1 us); the last bucket is open-ended (>= 2^30 us ~ 18 min).
inline constexpr uint32_t kLatencyBuckets = 32;

struct StatsSnapshot {
  uint64_t connections_total = 0, connections_open = 0, connections_rejected = 0;
  uint64_t requests = 0;        // frames answered (GetTiles, OpenMap, Ping, ...)
  uint64_t tiles_sent = 0, tile_bytes_sent = 0, bytes_sent = 0, bytes_received = 0;
  uint64_t tiles_cancelled = 0;
  uint64_t errors = 0;          // Error / TileError frames sent
  uint64_t protocol_errors = 0; // connections closed for a malformed stream
  uint64_t timeouts = 0;
  uint64_t auth_failures = 0;   // connections refused for a missing or wrong key
  uint64_t tiles_corrupt = 0;   // tiles whose stored bytes failed the pack's CRC or read
  uint64_t connections_evicted = 0;  // pending connections closed to make room (PendingBudget)
  uint64_t log_lines_suppressed = 0; // repeated log lines not written (LogThrottle)
  std::array<uint64_t, kLatencyBuckets> latency_us{};  // GetTiles receipt -> tile queued to send
  uint64_t latency_sum_us = 0;  // sum of the latencies the histogram counts (Prometheus _sum)

  // Upper bound (us) of the bucket holding quantile q in [0,1]; 0 if no samples.
  uint64_t latency_quantile_us(double q) const;
  // Named counters in a fixed order (the Stats message's (name, value) pairs).
  std::vector<std::pair<std::string, uint64_t>> named() const;
  // One line for the periodic log.
  std::string line() const;
};

class ServerStats {
 public:
  void connection_opened() { add(connections_total_), add(connections_open_); }
  void connection_closed() { connections_open_.fetch_sub(1, std::memory_order_relaxed); }
  void connection_rejected() { add(connections_rejected_); }
  void request() { add(requests_); }
  void tile_sent(uint64_t tile_bytes) { add(tiles_sent_), add(tile_bytes_sent_, tile_bytes); }
  void sent(uint64_t bytes) { add(bytes_sent_, bytes); }
  void received(uint64_t bytes) { add(bytes_received_, bytes); }
  void tiles_cancelled(uint64_t n) { add(tiles_cancelled_, n); }
  void error() { add(errors_); }
  void protocol_error() { add(protocol_errors_); }
  void timeout() { add(timeouts_); }
  void auth_failure() { add(auth_failures_); }
  void tile_corrupt() { add(tiles_corrupt_); }
  void connection_evicted() { add(connections_evicted_); }
  void log_suppressed() { add(log_lines_suppressed_); }
  void latency(uint64_t us);

  StatsSnapshot snapshot() const;

 private:
  static void add(std::atomic<uint64_t>& c, uint64_t n = 1) {
    c.fetch_add(n, std::memory_order_relaxed);
  }
  std::atomic<uint64_t> connections_total_{0}, connections_open_{0}, connections_rejected_{0};
  std::atomic<uint64_t> requests_{0}, tiles_sent_{0}, tile_bytes_sent_{0}, bytes_sent_{0},
      bytes_received_{0}, tiles_cancelled_{0}, errors_{0}, protocol_errors_{0}, timeouts_{0},
      auth_failures_{0}, tiles_corrupt_{0}, connections_evicted_{0}, log_lines_suppressed_{0},
      latency_sum_us_{0};
  std::array<std::atomic<uint64_t>, kLatencyBuckets> latency_{};
};

}  // namespace st::server

#include "server/server_stats.hpp"

#include <bit>
#include <cstdio>

namespace st::server {

void ServerStats::latency(uint64_t us) {
  uint32_t b = us == 0 ? 0 : uint32_t(std::bit_width(us));
  if (b >= kLatencyBuckets) b = kLatencyBuckets - 1;
  add(latency_[b]);
  add(latency_sum_us_, us);
}

StatsSnapshot ServerStats::snapshot() const {
  auto get = [](const std::atomic<uint64_t>& a) { return a.load(std::memory_order_relaxed); };
  StatsSnapshot s;
  s.connections_total = get(connections_total_);
  s.connections_open = get(connections_open_);
  s.connections_rejected = get(connections_rejected_);
  s.requests = get(requests_);
  s.tiles_sent = get(tiles_sent_);
  s.tile_bytes_sent = get(tile_bytes_sent_);
  s.bytes_sent = get(bytes_sent_);
  s.bytes_received = get(bytes_received_);
  s.tiles_cancelled = get(tiles_cancelled_);
  s.errors = get(errors_);
  s.protocol_errors = get(protocol_errors_);
  s.timeouts = get(timeouts_);
  s.auth_failures = get(auth_failures_);
  s.tiles_corrupt = get(tiles_corrupt_);
  s.connections_evicted = get(connections_evicted_);
  s.log_lines_suppressed = get(log_lines_suppressed_);
  for (uint32_t b = 0; b < kLatencyBuckets; ++b) s.latency_us[b] = get(latency_[b]);
  s.latency_sum_us = get(latency_sum_us_);
  return s;
}

uint64_t StatsSnapshot::latency_quantile_us(double q) const {
  uint64_t total = 0;
  for (uint64_t c : latency_us) total += c;
  if (total == 0) return 0;
  const uint64_t want = uint64_t(q * double(total - 1)) + 1;  // 1-based rank
  uint64_t seen = 0;
  for (uint32_t b = 0; b < kLatencyBuckets; ++b) {
    seen += latency_us[b];
    if (seen >= want) return uint64_t(1) << b;  // bucket b holds [2^(b-1), 2^b)
  }
  return uint64_t(1) << (kLatencyBuckets - 1);
}

std::vector<std::pair<std::string, uint64_t>> StatsSnapshot::named() const {
  return {{"connections_total", connections_total},
          {"connections_open", connections_open},
          {"connections_rejected", connections_rejected},
          {"requests", requests},
          {"tiles_sent", tiles_sent},
          {"tile_bytes_sent", tile_bytes_sent},
          {"bytes_sent", bytes_sent},
          {"bytes_received", bytes_received},
          {"tiles_cancelled", tiles_cancelled},
          {"errors", errors},
          {"protocol_errors", protocol_errors},
          {"timeouts", timeouts},
          {"latency_p50_us", latency_quantile_us(0.5)},
          {"latency_p99_us", latency_quantile_us(0.99)},
          {"auth_failures", auth_failures},
          {"tiles_corrupt", tiles_corrupt},
          {"connections_evicted", connections_evicted},
          {"log_lines_suppressed", log_lines_suppressed},
          {"latency_sum_us", latency_sum_us}};
}

std::string StatsSnapshot::line() const {
  char buf[768];
  std::snprintf(buf, sizeof buf,
                "connections %llu open / %llu total (%llu rejected), requests %llu, tiles %llu "
                "(%llu B), sent %llu B, received %llu B, cancelled %llu, errors %llu, "
                "protocol errors %llu, timeouts %llu, latency p50 <%llu us p99 <%llu us, "
                "auth failures %llu, corrupt tiles %llu, evicted %llu, log lines suppressed %llu",
                (unsigned long long)connections_open, (unsigned long long)connections_total,
                (unsigned long long)connections_rejected, (unsigned long long)requests,
                (unsigned long long)tiles_sent, (unsigned long long)tile_bytes_sent,
                (unsigned long long)bytes_sent, (unsigned long long)bytes_received,
                (unsigned long long)tiles_cancelled, (unsigned long long)errors,
                (unsigned long long)protocol_errors, (unsigned long long)timeouts,
                (unsigned long long)latency_quantile_us(0.5),
                (unsigned long long)latency_quantile_us(0.99),
                (unsigned long long)auth_failures, (unsigned long long)tiles_corrupt,
                (unsigned long long)connections_evicted, (unsigned long long)log_lines_suppressed);
  return buf;
}

}  // namespace st::server

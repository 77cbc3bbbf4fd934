// Watching a running server from outside (the soak, LOAD.md "Soak"): its counters over
// the wire protocol (GetStats: counters plus the latency_us histogram) and a process's
// memory from /proc/PID/status. Figures over an interval are differences of two
// snapshots: rates from counter deltas, latency quantiles from the histogram's bucket
// deltas (so p99 is that interval's, not the run's so far).
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "shadowtile/client.hpp"

namespace st::loadgen {

struct ProcMemory {
  bool alive = false;     // /proc/PID/status could be read
  uint64_t rss_bytes = 0; // VmRSS
  uint64_t hwm_bytes = 0; // VmHWM (peak RSS)
  uint64_t threads = 0;   // Threads
  double cpu_seconds = 0; // user + system time so far (/proc/PID/stat utime + stime)
};
// Reads /proc/PID/status and /proc/PID/stat; alive = false if the process is gone
// (never throws).
ProcMemory read_proc_memory(int pid);
// Parses the text of a /proc/PID/status file (exposed for tests).
ProcMemory parse_proc_status(const std::string& text);
// utime + stime in seconds from the text of a /proc/PID/stat file; -1 if malformed.
double parse_proc_stat_cpu(const std::string& text, double ticks_per_second);

struct ServerSample {
  double t = 0;  // seconds since the watch began
  std::map<std::string, uint64_t> counters;
  std::vector<uint64_t> latency_upper_us, latency_counts;  // the latency_us histogram
  uint64_t counter(const std::string& name) const;         // 0 if absent
};
// st::Error if the Stats message lacks the latency_us histogram or its buckets are not
// strictly increasing.
ServerSample sample_from(const client::ServerStats& stats, double t);

// Quantile q in [0, 1] of a histogram: the exclusive upper bound (upper + 1) of the
// bucket holding it; 0 when the histogram is empty.
uint64_t histogram_quantile(const std::vector<uint64_t>& upper, const std::vector<uint64_t>& counts, double q);

struct IntervalFigures {
  double t = 0, dt = 0;             // end of the interval, its length (s)
  uint64_t connections_open = 0;    // at the end (includes the watcher's own connection)
  uint64_t connections_total = 0, connections_rejected = 0;
  double requests_per_s = 0, tiles_per_s = 0, mib_per_s = 0;
  uint64_t latency_count = 0;       // requests timed in the interval
  uint64_t p50_us = 0, p99_us = 0;  // of the interval (bucket bounds: within a factor 2)
  uint64_t errors = 0, protocol_errors = 0, timeouts = 0;  // cumulative at the end
};
// Figures of the interval (a, b]; st::Error if the histograms differ in shape.
IntervalFigures interval_between(const ServerSample& a, const ServerSample& b);

}  // namespace st::loadgen

#include "loadgen/server_watch.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "common/error.hpp"

namespace st::loadgen {

ProcMemory parse_proc_status(const std::string& text) {
  ProcMemory m;
  std::istringstream in(text);
  std::string line;
  auto kib = [](const std::string& l) {  // "VmRSS:\t  1234 kB"
    const size_t colon = l.find(':');
    return uint64_t(std::strtoull(l.c_str() + colon + 1, nullptr, 10)) * 1024;
  };
  bool any = false;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) m.rss_bytes = kib(line), any = true;
    else if (line.rfind("VmHWM:", 0) == 0) m.hwm_bytes = kib(line), any = true;
    else if (line.rfind("Threads:", 0) == 0) m.threads = std::strtoull(line.c_str() + 8, nullptr, 10);
  }
  m.alive = any;  // a zombie's status has no Vm* lines: count it as gone
  return m;
}

double parse_proc_stat_cpu(const std::string& text, double ticks_per_second) {
  // "pid (comm) state ppid ...": comm may hold spaces and parentheses, so fields are
  // counted after the last ')'; utime and stime are fields 14 and 15 (proc(5)).
  const size_t close = text.rfind(')');
  if (close == std::string::npos || ticks_per_second <= 0) return -1;
  std::istringstream in(text.substr(close + 1));
  std::string field;
  unsigned long long utime = 0, stime = 0;
  for (int i = 3; i <= 15; ++i) {
    if (!(in >> field)) return -1;
    if (i == 14) utime = std::strtoull(field.c_str(), nullptr, 10);
    if (i == 15) stime = std::strtoull(field.c_str(), nullptr, 10);
  }
  return double(utime + stime) / ticks_per_second;
}

namespace {
std::string slurp(const std::string& path, bool& ok) {
  std::ifstream f(path);
  ok = bool(f);
  if (!ok) return {};
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}
}  // namespace

ProcMemory read_proc_memory(int pid) {
  if (pid <= 0) return {};
  bool ok = false;
  const std::string status = slurp("/proc/" + std::to_string(pid) + "/status", ok);
  if (!ok) return {};
  ProcMemory m = parse_proc_status(status);
  const std::string stat = slurp("/proc/" + std::to_string(pid) + "/stat", ok);
  if (ok) m.cpu_seconds = std::max(0.0, parse_proc_stat_cpu(stat, double(::sysconf(_SC_CLK_TCK))));
  return m;
}

uint64_t ServerSample::counter(const std::string& name) const {
  auto it = counters.find(name);
  return it == counters.end() ? 0 : it->second;
}

ServerSample sample_from(const client::ServerStats& stats, double t) {
  ServerSample s;
  s.t = t;
  for (const auto& c : stats.counters) s.counters[c.name] = c.value;
  for (const auto& h : stats.histograms) {
    if (h.name != "latency_us") continue;
    for (size_t i = 0; i < h.buckets.size(); ++i) {
      if (i > 0 && h.buckets[i].upper_bound <= h.buckets[i - 1].upper_bound)
        throw Error("stats: histogram latency_us: bucket " + std::to_string(i) + " bound not increasing");
      s.latency_upper_us.push_back(h.buckets[i].upper_bound);
      s.latency_counts.push_back(h.buckets[i].count);
    }
  }
  if (s.latency_upper_us.empty()) throw Error("stats: the server's Stats has no latency_us histogram");
  return s;
}

uint64_t histogram_quantile(const std::vector<uint64_t>& upper, const std::vector<uint64_t>& counts, double q) {
  uint64_t total = 0;
  for (uint64_t c : counts) total += c;
  if (total == 0 || upper.size() != counts.size()) return 0;
  // 1-based rank of the quantile (the server's own rule: server_stats.cpp).
  const uint64_t want = uint64_t(q * double(total - 1)) + 1;
  uint64_t seen = 0;
  for (size_t b = 0; b < counts.size(); ++b) {
    seen += counts[b];
    if (seen >= want) return upper[b] == ~uint64_t(0) ? upper[b] : upper[b] + 1;
  }
  return upper.back();
}

IntervalFigures interval_between(const ServerSample& a, const ServerSample& b) {
  if (a.latency_upper_us != b.latency_upper_us) throw Error("stats: latency histogram changed shape between samples");
  IntervalFigures f;
  f.t = b.t;
  f.dt = b.t - a.t;
  auto delta = [&](const char* name) {
    const uint64_t x = a.counter(name), y = b.counter(name);
    return y >= x ? y - x : 0;  // a restarted server starts again from zero
  };
  const double dt = f.dt > 0 ? f.dt : 1;
  f.connections_open = b.counter("connections_open");
  f.connections_total = b.counter("connections_total");
  f.connections_rejected = b.counter("connections_rejected");
  f.requests_per_s = double(delta("requests")) / dt;
  f.tiles_per_s = double(delta("tiles_sent")) / dt;
  f.mib_per_s = double(delta("bytes_sent")) / dt / 1048576.0;
  std::vector<uint64_t> counts(b.latency_counts.size());
  for (size_t i = 0; i < counts.size(); ++i)
    counts[i] = b.latency_counts[i] >= a.latency_counts[i] ? b.latency_counts[i] - a.latency_counts[i] : 0;
  for (uint64_t c : counts) f.latency_count += c;
  f.p50_us = histogram_quantile(b.latency_upper_us, counts, 0.5);
  f.p99_us = histogram_quantile(b.latency_upper_us, counts, 0.99);
  f.errors = b.counter("errors");
  f.protocol_errors = b.counter("protocol_errors");
  f.timeouts = b.counter("timeouts");
  return f;
}

}  // namespace st::loadgen

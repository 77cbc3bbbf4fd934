// `shadowtile stats --server HOST:PORT [--interval S] [--duration S] [--pid NAME=PID]...
//  [--until-gone PID] [--jsonl FILE] [--prometheus FILE]`: watches a running server over the wire protocol
// (GetStats every interval on one connection) and, optionally, processes' memory from
// /proc; prints a row per interval (connections open, requests/s, tiles/s, MiB/s,
// latency p50/p99 of that interval, errors, RSS) and appends a JSON line per row; with
// --prometheus it also rewrites a Prometheus textfile every interval
// (loadgen/prometheus_text.hpp). The
// soak (scripts/soak, loadgen/LOAD.md) runs it next to `shadowtile load`.
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <thread>

#include "shadowtile/client.hpp"
#include "loadgen/prometheus_text.hpp"
#include "loadgen/server_watch.hpp"
#include "app/command.hpp"
#include "common/error.hpp"

namespace st::cli {

client::Endpoint parse_endpoint(const std::string& option, const std::string& text);  // cmd_load.cpp

namespace {

struct StatsArgs {
  std::string server, jsonl, prometheus;
  double interval = 2, duration = 0;
  std::vector<std::string> pids;  // NAME=PID
  int until_gone = 0;
};

struct Watched {
  std::string name;
  int pid = 0;
};

std::vector<Watched> parse_pids(const std::vector<std::string>& specs) {
  std::vector<Watched> out;
  for (const std::string& s : specs) {
    const size_t eq = s.find('=');
    char* end = nullptr;
    const long pid = eq == std::string::npos ? 0 : std::strtol(s.c_str() + eq + 1, &end, 10);
    if (eq == std::string::npos || eq == 0 || pid <= 0 || *end != 0)
      throw Error("--pid: '" + s + "' is not NAME=PID");
    out.push_back({s.substr(0, eq), int(pid)});
  }
  return out;
}

void run_stats(const StatsArgs& a) {
  const client::Endpoint ep = parse_endpoint("--server", a.server);
  const std::vector<Watched> watched = parse_pids(a.pids);
  std::unique_ptr<std::ofstream> out;
  if (!a.jsonl.empty()) {
    out = std::make_unique<std::ofstream>(a.jsonl, std::ios::app);
    if (!*out) throw Error(a.jsonl + ": cannot open for append");
  }
  client::ClientOptions co;
  co.cache_slots = 1;
  co.client_name = "shadowtile-stats";
  co.request_timeout = std::chrono::milliseconds(int64_t(std::max(1.0, a.interval) * 1000));
  client::Client cl(ep, co);

  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  std::printf("%7s %6s %9s %9s %8s %9s %9s %6s", "t_s", "conns", "req/s", "tiles/s", "MiB/s", "p50_us", "p99_us",
              "errors");
  for (const Watched& w : watched) std::printf(" %12s %8s", (w.name + "_MiB").c_str(), (w.name + "_cpu").c_str());
  std::printf("\n");
  std::fflush(stdout);

  std::optional<loadgen::ServerSample> prev;
  std::vector<double> last_cpu(watched.size(), -1);
  double last_t = 0;
  uint64_t failures = 0;
  for (uint64_t tick = 1;; ++tick) {
    const auto due = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(a.interval * double(tick)));
    std::this_thread::sleep_until(due);
    nlohmann::json j;
    j["t_s"] = seconds();
    std::string row;
    try {
      loadgen::ServerSample s = loadgen::sample_from(cl.server_stats(), seconds());
      if (!a.prometheus.empty())
        loadgen::write_textfile_atomically(a.prometheus, loadgen::prometheus_text(s, a.server));
      if (prev) {
        const loadgen::IntervalFigures f = loadgen::interval_between(*prev, s);
        char buf[256];
        std::snprintf(buf, sizeof buf, "%7.1f %6llu %9.0f %9.0f %8.2f %9llu %9llu %6llu", f.t,
                      (unsigned long long)f.connections_open, f.requests_per_s, f.tiles_per_s, f.mib_per_s,
                      (unsigned long long)f.p50_us, (unsigned long long)f.p99_us,
                      (unsigned long long)(f.errors + f.protocol_errors + f.timeouts));
        row = buf;
        j.update({{"dt_s", f.dt},
                  {"connections_open", f.connections_open},
                  {"connections_total", f.connections_total},
                  {"connections_rejected", f.connections_rejected},
                  {"requests_per_s", f.requests_per_s},
                  {"tiles_per_s", f.tiles_per_s},
                  {"mib_per_s", f.mib_per_s},
                  {"latency_count", f.latency_count},
                  {"p50_us", f.p50_us},
                  {"p99_us", f.p99_us},
                  {"errors", f.errors},
                  {"protocol_errors", f.protocol_errors},
                  {"timeouts", f.timeouts}});
      }
      j["counters"] = s.counters;
      j["latency_us"] = s.latency_counts;
      prev = std::move(s);
    } catch (const Error& e) {
      ++failures;
      if (!a.prometheus.empty())
        loadgen::write_textfile_atomically(a.prometheus, loadgen::prometheus_down_text(a.server));
      j["stats_error"] = e.what();
      char buf[256];
      std::snprintf(buf, sizeof buf, "%7.1f  (no stats: %.180s)", seconds(), e.what());
      row = buf;
    }
    for (size_t i = 0; i < watched.size(); ++i) {
      const Watched& w = watched[i];
      const loadgen::ProcMemory m = loadgen::read_proc_memory(w.pid);
      // CPU use over the interval, in cores (1.0 = one core busy).
      const double cpu = m.alive && last_cpu[i] >= 0 && j["t_s"].get<double>() > last_t
                             ? (m.cpu_seconds - last_cpu[i]) / (j["t_s"].get<double>() - last_t)
                             : 0.0;
      last_cpu[i] = m.alive ? m.cpu_seconds : -1;
      j["proc"][w.name] = {{"pid", w.pid}, {"alive", m.alive}, {"rss_bytes", m.rss_bytes},
                           {"hwm_bytes", m.hwm_bytes}, {"threads", m.threads}, {"cpu_seconds", m.cpu_seconds},
                           {"cpu_cores", cpu}};
      if (!row.empty()) {
        char buf[64];
        std::snprintf(buf, sizeof buf, " %12.1f %8.2f", double(m.rss_bytes) / 1048576.0, cpu);
        row += m.alive ? buf : "         gone        -";
      }
    }
    last_t = j["t_s"].get<double>();
    if (!row.empty()) {
      std::printf("%s\n", row.c_str());
      std::fflush(stdout);
    }
    if (out) {
      *out << j.dump() << "\n";
      out->flush();
    }
    const bool gone = a.until_gone > 0 && !loadgen::read_proc_memory(a.until_gone).alive;
    if (gone || (a.duration > 0 && seconds() >= a.duration)) break;
  }
  if (failures > 0) {
    std::fprintf(stderr, "shadowtile stats: %llu sample(s) got no answer\n", (unsigned long long)failures);
    exit_with(kExitError);
  }
}

Register reg_stats{"stats", "Watch a running server's counters (and processes' memory) over time", [](CLI::App& sub) {
  auto a = std::make_shared<StatsArgs>();
  sub.add_option("--server", a->server, "Server address HOST:PORT")->required();
  sub.add_option("--interval", a->interval, "Seconds between samples")->capture_default_str()
      ->check(CLI::Range(0.05, 3600.0));
  sub.add_option("--duration", a->duration, "Stop after this many seconds (0: no bound)")->capture_default_str()
      ->check(CLI::Range(0.0, 864000.0));
  sub.add_option("--pid", a->pids, "NAME=PID: also sample that process's VmRSS/VmHWM/Threads (repeatable)");
  sub.add_option("--until-gone", a->until_gone, "Stop once this process has exited")->check(CLI::Range(1, 1 << 30));
  sub.add_option("--jsonl", a->jsonl, "Append one JSON object per sample to this file");
  sub.add_option("--prometheus", a->prometheus,
                 "Rewrite this file every interval with the server's counters and latency histogram in "
                 "Prometheus' text format (node_exporter textfile collector: a *.prom file in its directory)");
  sub.callback([a] { run_stats(*a); });
}};

}  // namespace
}  // namespace st::cli

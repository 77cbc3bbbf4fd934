#include "loadgen/prometheus_text.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "common/error.hpp"

namespace st::loadgen {
namespace {

struct MetricName {
  const char* counter;  // the GetStats counter name
  const char* name;     // the Prometheus metric family
  const char* type;     // "counter" (sample name + "_total") or "gauge"
  const char* help;
};

// GetStats counters (PROTOCOL.md §4.12) -> Prometheus families.
constexpr MetricName kMetrics[] = {
    {"connections_total", "shadowtile_server_connections", "counter", "Connections accepted and served."},
    {"connections_open", "shadowtile_server_connections_open", "gauge", "Connections open now."},
    {"connections_rejected", "shadowtile_server_connections_rejected", "counter",
     "Connections refused at accept (connection limits)."},
    {"connections_evicted", "shadowtile_server_connections_evicted", "counter",
     "Pending connections closed to make room for a newcomer."},
    {"requests", "shadowtile_server_requests", "counter", "Request frames received after the handshake."},
    {"tiles_sent", "shadowtile_server_tiles_sent", "counter", "TileData frames written."},
    {"tile_bytes_sent", "shadowtile_server_tile_sent_bytes", "counter", "Tile payload bytes sent (stored size)."},
    {"bytes_sent", "shadowtile_server_sent_bytes", "counter", "Protocol bytes written to clients."},
    {"bytes_received", "shadowtile_server_received_bytes", "counter", "Protocol bytes read from clients."},
    {"tiles_cancelled", "shadowtile_server_tiles_cancelled", "counter", "Queued tiles a Cancel removed."},
    {"errors", "shadowtile_server_error_frames", "counter", "Error and TileError frames sent."},
    {"protocol_errors", "shadowtile_server_protocol_errors", "counter", "Protocol violations by clients."},
    {"timeouts", "shadowtile_server_timeouts", "counter", "Handshake, read and write timeouts."},
    {"auth_failures", "shadowtile_server_auth_failures", "counter", "Connections refused for a missing or wrong key."},
    {"tiles_corrupt", "shadowtile_server_tiles_corrupt", "counter", "Tiles whose read from the pack failed."},
    {"log_lines_suppressed", "shadowtile_server_log_lines_suppressed", "counter",
     "Repeated log lines dropped by the log rate limit."},
};

constexpr const char* kLatency = "shadowtile_server_tile_latency_seconds";

// A label value with \, " and newline escaped (exposition format).
std::string label_value(const std::string& v) {
  std::string out;
  for (char c : v) {
    if (c == '\\') out += "\\\\";
    else if (c == '"') out += "\\\"";
    else if (c == '\n') out += "\\n";
    else out += c;
  }
  return out;
}

// Microseconds as exact decimal seconds ("0.000127", "3", "0").
std::string us_as_seconds(uint64_t us) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%llu.%06llu", (unsigned long long)(us / 1000000), (unsigned long long)(us % 1000000));
  std::string s = buf;
  while (s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  return s;
}

void family(std::string& out, const char* name, const char* type, const char* help) {
  out += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " " + type + "\n";
}

}  // namespace

std::string prometheus_down_text(const std::string& server) {
  std::string out;
  family(out, "shadowtile_server_up", "gauge", "1 if the server answered the last GetStats, else 0.");
  out += "shadowtile_server_up{server=\"" + label_value(server) + "\"} 0\n";
  return out;
}

std::string prometheus_text(const ServerSample& s, const std::string& server) {
  const std::string label = "{server=\"" + label_value(server) + "\"}";
  std::string out;
  family(out, "shadowtile_server_up", "gauge", "1 if the server answered the last GetStats, else 0.");
  out += "shadowtile_server_up" + label + " 1\n";
  for (const MetricName& m : kMetrics) {
    auto it = s.counters.find(m.counter);
    if (it == s.counters.end()) continue;
    // Text format 0.0.4 (what node_exporter reads): a counter's HELP and TYPE lines name
    // the sample itself, _total included (as Prometheus' Go client writes them).
    const bool counter = std::strcmp(m.type, "counter") == 0;
    const std::string sample = std::string(m.name) + (counter ? "_total" : "");
    family(out, sample.c_str(), m.type, m.help);
    out += sample + label + " " + std::to_string(it->second) + "\n";
  }
  family(out, kLatency, "histogram", "Tile latency: GetTiles received to the end of the TileData write.");
  uint64_t cumulative = 0;
  for (size_t b = 0; b < s.latency_counts.size(); ++b) {
    cumulative += s.latency_counts[b];
    // The server's bucket bounds are inclusive integer microseconds (upper_bound), so
    // le = upper_bound µs counts exactly the same samples; the overflow bucket is +Inf.
    const bool last = b + 1 == s.latency_counts.size() || s.latency_upper_us[b] == ~uint64_t(0);
    const std::string le = last ? "+Inf" : us_as_seconds(s.latency_upper_us[b]);
    out += std::string(kLatency) + "_bucket{server=\"" + label_value(server) + "\",le=\"" + le + "\"} " +
           std::to_string(cumulative) + "\n";
    if (last) break;
  }
  auto sum = s.counters.find("latency_sum_us");
  if (sum != s.counters.end()) {
    // Exact: whole microseconds as decimal seconds.
    out += std::string(kLatency) + "_sum" + label + " " + us_as_seconds(sum->second) + "\n";
  }
  out += std::string(kLatency) + "_count" + label + " " + std::to_string(cumulative) + "\n";
  return out;
}

void write_textfile_atomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + "." + std::to_string(::getpid()) + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f << text;
    f.flush();
    if (!f) throw Error("--prometheus: cannot write '" + tmp + "'");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    std::remove(tmp.c_str());
    throw Error("--prometheus: cannot rename '" + tmp + "' to '" + path + "': " + std::strerror(e));
  }
}

}  // namespace st::loadgen

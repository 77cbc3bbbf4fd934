// A server's counters and latency histogram (GetStats, proto/PROTOCOL.md §4.12) in the
// Prometheus text exposition format (0.0.4), for node_exporter's textfile collector:
// `shadowtile stats --prometheus /var/lib/node_exporter/textfile/shadowtile.prom`.
//
// Names follow Prometheus' naming rules: prefix shadowtile_server_, base units (seconds,
// bytes), cumulative counters end in _total, the latency histogram is
// shadowtile_server_tile_latency_seconds with cumulative le buckets. Every sample carries
// the label server="HOST:PORT". shadowtile_server_up is 1 when the server answered the
// last GetStats, 0 (and nothing else) when it did not. Counters this table does not
// know (a later server's) are left out; the derived latency_p50_us / latency_p99_us are
// left out too (Prometheus computes quantiles from the buckets).
#pragma once
#include <string>

#include "loadgen/server_watch.hpp"

namespace st::loadgen {

// The exposition text of one answered sample.
std::string prometheus_text(const ServerSample& sample, const std::string& server);
// The text for a server that did not answer (shadowtile_server_up 0).
std::string prometheus_down_text(const std::string& server);

// Writes `text` to "<path>.<pid>.tmp" and renames it onto `path`, so a collector reading
// the file never sees half of it (the textfile collector's convention). st::Error naming
// the file on failure.
void write_textfile_atomically(const std::string& path, const std::string& text);

}  // namespace st::loadgen

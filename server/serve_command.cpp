#include "server/serve_command.hpp"

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "proto/auth.hpp"
#include "proto/limits.hpp"
#include "server/server.hpp"

namespace st::server {

void add_serve_options(CLI::App& app, ServeConfig& a) {
  app.add_option("packs", a.paths, "Pack files and/or directories of *.pack files")->required();
  app.add_option("--listen", a.listen, "Address to listen on, HOST:PORT (port 0: ephemeral)")
      ->capture_default_str();
  app.add_option("--threads", a.threads, "I/O threads")->capture_default_str()->check(CLI::Range(1u, 64u));
  app.add_option("--busy-poll-us", a.busy_poll_us,
                 "Low latency: each I/O thread polls this many microseconds after its last event before "
                 "it sleeps (uses up to a core per thread while clients are active; 0: sleep at once)")
      ->capture_default_str()->check(CLI::Range(0u, 1000000u));
  app.add_option("--stats-interval", a.stats_interval, "Print counters every S seconds (0: never)")
      ->capture_default_str()->check(CLI::Range(0.0, 86400.0));
  app.add_option("--max-connections", a.max_connections, "Connections served at once")
      ->capture_default_str()->check(CLI::Range(1u, 1000000u));
  app.add_option("--max-connections-per-address", a.max_connections_per_address,
                 "Connections from one client address at once (0: no bound)")
      ->capture_default_str()->check(CLI::Range(0u, 1000000u));
  app.add_option("--max-connections-per-prefix", a.max_connections_per_prefix,
                 "Connections that made a request, from one network (IPv4 /24, IPv6 /64) at once; the request "
                 "over it gets Error(overloaded) (0: no bound)")
      ->capture_default_str()->check(CLI::Range(0u, 1000000u));
  app.add_option("--tile-cache-mib", a.tile_cache_mib,
                 "Memory for stored tiles shared by all clients, read and CRC-checked once (0: no cache)")
      ->capture_default_str()->check(CLI::Range(0.0, 1048576.0));
  app.add_option("--max-pending-connections", a.max_pending_connections,
                 "Connections not yet authenticated or without a request yet, in all; past it the "
                 "oldest of the heaviest address is closed to make room (0: no bound)")
      ->capture_default_str()->check(CLI::Range(0u, 1000000u));
  app.add_option("--max-pending-per-address", a.max_pending_per_address,
                 "The same, from one client address (0: no bound)")
      ->capture_default_str()->check(CLI::Range(0u, 1000000u));
  app.add_option("--key-file", a.key_file,
                 "Require clients to prove this catalog key (hex or raw bytes; HMAC-SHA256 challenge)");
  app.add_option("--tls-cert", a.tls_cert, "Serve over TLS with this certificate chain (PEM); needs --tls-key");
  app.add_option("--tls-key", a.tls_key, "The certificate's private key (PEM)");
  app.add_option("--tls-handshake-rate", a.tls_handshake_rate,
                 "TLS handshakes each network (IPv4 /24, IPv6 /64) may start per second, twice that at once; "
                 "more are closed before the handshake (0: no limit)")
      ->capture_default_str()->check(CLI::Range(0.0, 1e6));
  app.add_option("--idle-timeout", a.idle_timeout, "Close connections idle this many seconds")
      ->capture_default_str()->check(CLI::Range(0.1, 86400.0));
  app.add_option("--max-frame-bytes", a.max_frame_bytes,
                 "Largest frame offered to clients, in bytes (a tile needs its stored size + 52); "
                 "0: 4 MiB, raised to fit the largest tile and map info")
      ->capture_default_str()
      ->check(CLI::IsMember({0u}) | CLI::Range(proto::kMinFrameBytes, proto::kMaxFrameBytesCeiling));
}

std::pair<std::string, uint16_t> parse_listen(const std::string& text) {
  std::string host, port;
  if (!text.empty() && text[0] == '[') {
    auto close = text.find(']');
    if (close == std::string::npos || close + 1 >= text.size() || text[close + 1] != ':')
      throw Error("--listen: '" + text + "' is not [IPv6]:PORT");
    host = text.substr(1, close - 1);
    port = text.substr(close + 2);
  } else {
    auto colon = text.rfind(':');
    if (colon == std::string::npos) throw Error("--listen: '" + text + "' is not HOST:PORT");
    host = text.substr(0, colon);
    port = text.substr(colon + 1);
  }
  size_t used = 0;
  unsigned long p = 0;
  try {
    p = std::stoul(port, &used);
  } catch (...) {
    used = 0;
  }
  if (port.empty() || used != port.size() || p > 65535 || host.empty())
    throw Error("--listen: '" + text + "' needs HOST:PORT with a port in 0..65535");
  return {host, uint16_t(p)};
}

void run_serve(const ServeConfig& a, const char* program) {
  auto catalog = Catalog::scan(a.paths, [program](const std::string& w) {
    std::fprintf(stderr, "%s: warning: %s\n", program, w.c_str());
  });
  ServerOptions o;
  std::tie(o.host, o.port) = parse_listen(a.listen);
  o.threads = a.threads;
  o.busy_poll = std::chrono::microseconds(a.busy_poll_us);
  o.max_connections = a.max_connections;
  o.max_connections_per_address = a.max_connections_per_address;
  o.max_connections_per_prefix = a.max_connections_per_prefix;
  o.tile_cache_bytes = size_t(a.tile_cache_mib * 1048576.0);
  o.max_pending_connections = a.max_pending_connections;
  o.max_pending_per_address = a.max_pending_per_address;
  o.stats_interval = std::chrono::milliseconds(int64_t(a.stats_interval * 1000));
  o.idle_timeout = std::chrono::milliseconds(int64_t(a.idle_timeout * 1000));
  if (a.max_frame_bytes != 0) {
    o.limits.max_frame_bytes = a.max_frame_bytes;
    o.fit_frame_to_catalog = false;
  }
  o.log = [program](const std::string& line) { std::fprintf(stderr, "%s: %s\n", program, line.c_str()); };
  if (!a.key_file.empty()) o.key = proto::load_key_file(a.key_file);
  o.tls_cert_file = a.tls_cert;
  o.tls_key_file = a.tls_key;
  o.tls_handshakes_per_second = a.tls_handshake_rate;
  o.tls_handshake_burst = std::max(1.0, 2 * a.tls_handshake_rate);
  const size_t maps = catalog.maps().size();
  Server srv(std::move(catalog), o);
  srv.start();
  std::fprintf(stderr, "%s: %zu map(s) on %s:%u (%u I/O thread(s), max frame %u bytes%s%s); Ctrl-C stops\n",
               program, maps, o.host.c_str(), unsigned(srv.port()), o.threads, unsigned(srv.max_frame_bytes()),
               o.key.empty() ? "" : ", key required", o.tls_cert_file.empty() ? "" : ", TLS");
  for (const auto& m : srv.catalog().maps())
    std::fprintf(stderr, "  %s  L=%u K=%u tiles=%u  %s\n", m->name().c_str(),
                 unsigned(m->entry().resolution_log2), unsigned(m->entry().skip_level),
                 unsigned(m->entry().tile_count), m->path().c_str());
  int sig = srv.wait_for_signal();
  std::fprintf(stderr, "%s: %s, stopped. %s\n", program, sig ? "signal received" : "stopped",
               srv.stats().line().c_str());
}

}  // namespace st::server

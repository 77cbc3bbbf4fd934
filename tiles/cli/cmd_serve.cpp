// `shadowtile serve PACK_OR_DIR... --listen HOST:PORT [--threads N] [--stats-interval S]`:
// serves the packs' tiles over the wire protocol until SIGINT/SIGTERM (server/server.hpp).
#include <cstdio>
#include <string>
#include <vector>

#include "proto/auth.hpp"
#include "server/server.hpp"
#include "tiles/cli/command.hpp"
#include "tiles/core/error.hpp"

namespace st::cli {
namespace {

struct ServeArgs {
  std::vector<std::string> paths;
  std::string listen = "127.0.0.1:7447";
  unsigned threads = 1;
  double stats_interval = 0;
  unsigned max_connections = 1024;
  unsigned max_connections_per_address = 256;
  double idle_timeout = 120;
  std::string key_file, tls_cert, tls_key;
};

// "HOST:PORT" or "[V6]:PORT" -> (host, port). Throws st::Error.
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

void run_serve(const ServeArgs& a) {
  auto catalog = server::Catalog::scan(a.paths, [](const std::string& w) {
    std::fprintf(stderr, "shadowtile serve: warning: %s\n", w.c_str());
  });
  server::ServerOptions o;
  std::tie(o.host, o.port) = parse_listen(a.listen);
  o.threads = a.threads;
  o.max_connections = a.max_connections;
  o.max_connections_per_address = a.max_connections_per_address;
  o.stats_interval = std::chrono::milliseconds(int64_t(a.stats_interval * 1000));
  o.idle_timeout = std::chrono::milliseconds(int64_t(a.idle_timeout * 1000));
  if (!a.key_file.empty()) o.key = proto::load_key_file(a.key_file);
  o.tls_cert_file = a.tls_cert;
  o.tls_key_file = a.tls_key;
  const size_t maps = catalog.maps().size();
  server::Server srv(std::move(catalog), o);
  srv.start();
  std::fprintf(stderr, "shadowtile serve: %zu map(s) on %s:%u (%u I/O thread(s)%s%s); Ctrl-C stops\n",
               maps, o.host.c_str(), unsigned(srv.port()), o.threads,
               o.key.empty() ? "" : ", key required", o.tls_cert_file.empty() ? "" : ", TLS");
  for (const auto& m : srv.catalog().maps())
    std::fprintf(stderr, "  %s  L=%u K=%u tiles=%u  %s\n", m->name().c_str(),
                 unsigned(m->entry().resolution_log2), unsigned(m->entry().skip_level),
                 unsigned(m->entry().tile_count), m->path().c_str());
  int sig = srv.wait_for_signal();
  std::fprintf(stderr, "shadowtile serve: %s, stopped. %s\n", sig ? "signal received" : "stopped",
               srv.stats().line().c_str());
}

Register reg{"serve", "Serve packs' tiles over TCP (the shadowtile wire protocol)", [](CLI::App& sub) {
  auto a = std::make_shared<ServeArgs>();
  sub.add_option("packs", a->paths, "Pack files and/or directories of *.pack files")->required();
  sub.add_option("--listen", a->listen, "Address to listen on, HOST:PORT (port 0: ephemeral)")
      ->capture_default_str();
  sub.add_option("--threads", a->threads, "I/O threads")->capture_default_str()->check(CLI::Range(1u, 64u));
  sub.add_option("--stats-interval", a->stats_interval, "Print counters every S seconds (0: never)")
      ->capture_default_str()->check(CLI::Range(0.0, 86400.0));
  sub.add_option("--max-connections", a->max_connections, "Connections served at once")
      ->capture_default_str()->check(CLI::Range(1u, 1000000u));
  sub.add_option("--max-connections-per-address", a->max_connections_per_address,
                 "Connections from one client address at once (0: no bound)")
      ->capture_default_str()->check(CLI::Range(0u, 1000000u));
  sub.add_option("--key-file", a->key_file,
                 "Require clients to prove this catalog key (hex or raw bytes; HMAC-SHA256 challenge)");
  sub.add_option("--tls-cert", a->tls_cert, "Serve over TLS with this certificate chain (PEM); needs --tls-key");
  sub.add_option("--tls-key", a->tls_key, "The certificate's private key (PEM)");
  sub.add_option("--idle-timeout", a->idle_timeout, "Close connections idle this many seconds")
      ->capture_default_str()->check(CLI::Range(0.1, 86400.0));
  sub.callback([a] { run_serve(*a); });
}};

}  // namespace
}  // namespace st::cli

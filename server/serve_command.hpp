// The server's command line, shared by `shadowtile-server` (server/main.cpp, what the
// image ships) and `shadowtile serve` (app/cmd_serve.cpp): the same options, defaults and
// messages in both.
#pragma once
#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace st::server {

struct ServeConfig {
  std::vector<std::string> paths;
  std::string listen = "127.0.0.1:7447";
  unsigned threads = 1;
  unsigned busy_poll_us = 0;
  double stats_interval = 0;
  unsigned max_connections = 1024;
  unsigned max_connections_per_address = 256;
  unsigned max_connections_per_prefix = 512;  // IPv4 /24, IPv6 /64
  // Connections not yet useful (server.hpp: before auth or their first request).
  unsigned max_pending_connections = 256;
  unsigned max_pending_per_address = 32;
  double idle_timeout = 120;
  double tile_cache_mib = 64;  // server.hpp: ServerOptions::tile_cache_bytes
  // 0: the protocol default (4 MiB), raised to fit the catalog's largest tile and map
  // info; else this cap exactly (65536..67108864), and what exceeds it is refused.
  uint32_t max_frame_bytes = 0;
  std::string key_file, tls_cert, tls_key;
  double tls_handshake_rate = 20;  // per network per second (server.hpp); burst twice that
};

// Adds the options (and the positional pack paths) to `app`, writing into `config`.
void add_serve_options(CLI::App& app, ServeConfig& config);

// "HOST:PORT" or "[V6]:PORT" -> (host, port). Throws st::Error naming --listen.
std::pair<std::string, uint16_t> parse_listen(const std::string& text);

// Scans the packs, serves them until SIGINT/SIGTERM, then prints the final counters.
// Progress and warnings go to stderr prefixed with `program` ("shadowtile serve").
// Throws st::Error on bad options, unreadable packs or a port that cannot be bound.
void run_serve(const ServeConfig& config, const char* program);

}  // namespace st::server

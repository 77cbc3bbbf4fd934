// The shadowtile tile server: serves the tiles of many packs (tiles/PACK.md) over
// the wire protocol (proto/PROTOCOL.md) with Boost.Asio.
//
// Shape (Asio http server example): Server owns the io_context, the acceptor and the
// catalog; each accepted socket becomes a Connection (connection.hpp) running one reader
// coroutine, one writer coroutine draining its queues (never two writes at once on a
// socket), and a watchdog enforcing every timeout. Tiles are read with pread from the
// pack and sent as the stored (zlib) bytes behind a header, in one gathered write.
//
// Thread safety: start()/stop()/port()/stats() may be called from any thread. The
// tile hook runs on I/O threads.
#pragma once
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "proto/limits.hpp"
#include "server/catalog.hpp"
#include "server/server_stats.hpp"
#include "server/tile_source.hpp"

namespace st::server {

struct ServerOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 7447;  // 0: an ephemeral port (see Server::port())
  unsigned threads = 1;  // I/O threads; one beat two on a 2-core machine for small blobs
  // Low-latency mode: after its last event an I/O thread keeps polling (epoll with a zero
  // timeout) this long before it sleeps, so a client that asks again within it is served
  // without a wake-up. Burns up to one core per I/O thread while clients are active;
  // 0 (the default): sleep at once.
  std::chrono::microseconds busy_poll{0};
  // The most this server grants any client; the handshake takes the smaller of each pair.
  proto::Limits limits{};
  // A tile is served only if its TileData frame (stored size + 52 bytes) fits the
  // negotiated max_frame_bytes, and a map opens only if its MapInfo frame does (PROTOCOL.md
  // §6). true: the server raises limits.max_frame_bytes at start to fit the largest of
  // these in its catalog (never above the protocol's 64 MiB) and logs the cap it offers.
  // false: limits.max_frame_bytes stays as given; what cannot fit is refused
  // (tile_too_large, limit_exceeded), and a warning at start says how much.
  bool fit_frame_to_catalog = true;
  size_t max_connections = 1024;         // beyond: Error(overloaded) and close
  // From one client address (IPv4 or IPv6): a client opening connections without end
  // is refused at this bound while other addresses are still served (0: no bound).
  size_t max_connections_per_address = 256;
  // Useful connections (past the pending budget below: they made a real request) from
  // one network (IPv4 /24, IPv6 /64): a few addresses of one network cannot take the
  // whole server. The request that would exceed it gets Error(overloaded) and a close
  // (0: no bound). Pending connections count against the pending budgets instead.
  size_t max_connections_per_prefix = 512;
  // Connections not yet useful (before auth, or before their first request after the
  // handshake): a budget of their own, so strangers cannot hold the slots authenticated
  // clients need. Over a budget, the oldest pending connection of the heaviest address in
  // its scope is closed to make room (server_core.hpp, PendingBudget). 0: no bound.
  size_t max_pending_connections = 256;
  size_t max_pending_per_address = 32;
  size_t max_pending_per_prefix = 128;   // IPv4 /24, IPv6 /64
  // A pending connection younger than this is never evicted (an honest handshake takes
  // a few round trips; a burst of them from one host must not evict itself).
  std::chrono::milliseconds pending_grace{1000};
  size_t max_open_maps = 64;             // per connection
  size_t max_control_frames = 64;        // queued non-tile answers; the reader waits beyond
  size_t max_control_bytes = 1u << 20;   // ... or beyond this many bytes of them (shared MapInfo bytes not counted)
  // All connections together: answer bytes queued or being written. Beyond, readers stop
  // taking requests and writers send one tile per write until it drains.
  size_t max_queued_bytes = 256u << 20;
  // Stored tile bytes kept in memory, shared by all connections (payload_cache.hpp): a
  // tile is read from disk and CRC-checked once, then sent from memory until evicted
  // (least recently used first). Bounded by this budget; a tile over 1/16 of it is never
  // kept. 0: no cache (every tile read and checked on every request).
  size_t tile_cache_bytes = 64u << 20;
  std::chrono::milliseconds handshake_timeout{5000};  // accept -> Hello received
  std::chrono::milliseconds idle_timeout{120000};     // no traffic and nothing owed
  std::chrono::milliseconds read_timeout{10000};      // a frame must complete this long after its first byte
  std::chrono::milliseconds write_timeout{10000};     // one write must complete
  std::string server_name = "shadowtile-server";
  // The catalog's key (proto/auth.hpp): when set, a client must prove it holds the key
  // (HMAC-SHA256 challenge-response) before it may list, open or read anything.
  std::vector<uint8_t> key;
  // TLS (Asio SSL streams, TLS 1.2 or later): both set, PEM files, or both empty (plain
  // TCP). The key file must not be a key clients know: it is the server's private key.
  std::string tls_cert_file, tls_key_file;
  // TLS handshakes each network (IPv4 /24, IPv6 /64) may start per second, and at once
  // (server/handshake_limiter.hpp): a connection over it is closed before its handshake
  // (counted in connections_rejected), so a handshake flood cannot take the I/O thread's
  // CPU from other clients. rate 0: no limit. Plain TCP: not used.
  double tls_handshakes_per_second = 20;
  double tls_handshake_burst = 40;
  // Periodic stats line (0: none), written through `log`.
  std::chrono::milliseconds stats_interval{0};
  std::function<void(const std::string&)> log;  // default: stderr
  // Where tiles' stored bytes come from (server/tile_source.hpp); null: the packs
  // themselves (PackTileSource). Shared by every connection, called from the I/O threads.
  std::shared_ptr<TileSource> tile_source;
};

class Server {
 public:
  // Validates options (st::Error on bad limits or zero threads).
  Server(Catalog catalog, ServerOptions options);
  ~Server();  // stop()
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds and listens (st::Error naming the address on failure), then runs the I/O
  // threads. Returns once the server accepts connections.
  void start();
  // Stops accepting, closes every connection, joins the I/O threads. Idempotent.
  void stop();
  // Blocks until stop() is called or SIGINT/SIGTERM arrives (then stops; returns the
  // signal number, or 0 for stop()).
  int wait_for_signal();

  uint16_t port() const;  // the bound port (after start())
  // The max_frame_bytes this server offers in every HelloAck (after fit_frame_to_catalog).
  uint32_t max_frame_bytes() const;
  StatsSnapshot stats() const;
  const Catalog& catalog() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace st::server

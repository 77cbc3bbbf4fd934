// State shared by the server and its connections (internal to server/).
#pragma once
#include <array>
#include <chrono>
#include <atomic>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>

#include "net/asio.hpp"

#include <boost/asio/ssl.hpp>

#include "server/catalog.hpp"
#include "server/handshake_limiter.hpp"
#include "server/log_throttle.hpp"
#include "server/payload_cache.hpp"
#include "server/server.hpp"
#include "server/server_stats.hpp"

namespace st::server {

namespace asio = net::asio;  // net/asio.hpp
using net::error_code;
using net::tcp;

class Connection;

// The budget of connections not yet useful: accepted but not authenticated, or
// authenticated (or keyless) without a single real request yet. They are the cheap way
// to fill a server, so they get a small budget of their own, per address, per prefix
// (IPv4 /24, IPv6 /64) and in all, and a newcomer over a budget evicts the oldest such
// connection of the heaviest address in that scope instead of being refused: whoever
// floods the budget evicts itself, a client that completes its handshake in a few round
// trips gets through. Only connections pending for longer than the grace (1 s) are
// evicted, so a burst of honest clients from one host (a NAT, a load test) is not made
// to evict itself; with no such victim the budget is soft until max_connections. There
// the grace no longer shields an address over its own budget: the newcomer evicts that
// address's oldest pending connection, however young (a flood reopened faster than the
// grace cannot hold the server full); only with no such address is it refused. Past
// twice the global budget (or at it when full) the grace shrinks to a quarter for every
// address: many addresses, each within its own budget, recycling connections faster than
// the grace cannot hold the budget either (an honest handshake is long done by then).
// Guarded by ServerCore::mu.
struct PendingBudget {
  using Prefix = std::array<uint8_t, 16>;
  static Prefix prefix_of(const asio::ip::address& a);
  struct Entry {
    std::weak_ptr<Connection> conn;
    asio::ip::address from;
    Prefix prefix;
    std::chrono::steady_clock::time_point since;
  };
  std::list<Entry> order;  // oldest first
  std::map<asio::ip::address, size_t> per_address;
  std::map<Prefix, size_t> per_prefix;

  std::list<Entry>::iterator add(std::weak_ptr<Connection> c, const asio::ip::address& from);
  void remove(std::list<Entry>::iterator it);
  // The connection to evict so that one from `from` fits (null: none needed, or none
  // pending for at least o.pending_grace), by the limits in `o`; `total_full` says the
  // server is at max_connections. Removes it from the budget.
  std::shared_ptr<Connection> victim_for(const asio::ip::address& from, const ServerOptions& o,
                                         bool total_full, std::chrono::steady_clock::time_point now);
};

struct ServerCore {
  ServerOptions options;
  Catalog catalog;
  std::unique_ptr<asio::ssl::context> tls;  // null: plain TCP
  ServerStats stats;
  // Verified stored tile bytes shared by every connection (options.tile_cache_bytes).
  PayloadCache payloads;

  std::mutex mu;  // guards connections and stopping
  std::set<std::shared_ptr<Connection>> connections;
  std::map<asio::ip::address, size_t> per_address;  // open connections by client address
  // Useful connections (past PendingBudget: their first real request) by the client's
  // /24 or /64, against ServerOptions::max_connections_per_prefix.
  std::map<PendingBudget::Prefix, size_t> useful_per_prefix;
  PendingBudget pending;
  HandshakeLimiter tls_handshakes{0, 1};  // set from options by Server's constructor
  size_t evicting = 0;
  // Answer bytes owned by connections (control frames queued, tile bytes being written)
  // against ServerOptions::max_queued_bytes.
  std::atomic<uint64_t> queued_bytes{0};  // evicted, not yet closed: not counted against max_connections
  bool stopping = false;

  LogThrottle throttle;

  void log(const std::string& line) const;
  // A line that an attacker or a failing disk can repeat at will: rate-limited per
  // `kind` (LogThrottle), the dropped ones counted in the stats.
  void log_repeated(const std::string& kind, const std::string& line);
};

}  // namespace st::server

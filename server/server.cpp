#include "server/server.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <condition_variable>
#include <cstdio>
#include <future>
#include <thread>

#include "proto/proto.hpp"
#include "net/asio.hpp"
#include "server/connection.hpp"
#include "common/error.hpp"

namespace st::server {

void ServerCore::log(const std::string& line) const {
  if (options.log) options.log(line);
  else std::fprintf(stderr, "shadowtile serve: %s\n", line.c_str());
}

void ServerCore::log_repeated(const std::string& kind, const std::string& line) {
  if (auto out = throttle.admit(kind, line)) log(*out);
  else stats.log_suppressed();
}

PendingBudget::Prefix PendingBudget::prefix_of(const asio::ip::address& a) {
  Prefix p{};
  asio::ip::address_v6 v6;
  if (a.is_v4()) {
    v6 = asio::ip::make_address_v6(asio::ip::v4_mapped, a.to_v4());
  } else {
    v6 = a.to_v6();
  }
  const auto bytes = v6.to_bytes();
  if (v6.is_v4_mapped()) {  // IPv4: the /24
    std::copy(bytes.begin(), bytes.begin() + 15, p.begin());
  } else {  // IPv6: the /64 (one subscriber's network)
    std::copy(bytes.begin(), bytes.begin() + 8, p.begin());
  }
  return p;
}

std::list<PendingBudget::Entry>::iterator PendingBudget::add(std::weak_ptr<Connection> c,
                                                             const asio::ip::address& from) {
  Entry e{std::move(c), from, prefix_of(from), std::chrono::steady_clock::now()};
  ++per_address[from];
  ++per_prefix[e.prefix];
  return order.insert(order.end(), std::move(e));
}

void PendingBudget::remove(std::list<Entry>::iterator it) {
  if (auto a = per_address.find(it->from); a != per_address.end() && --a->second == 0) per_address.erase(a);
  if (auto p = per_prefix.find(it->prefix); p != per_prefix.end() && --p->second == 0) per_prefix.erase(p);
  order.erase(it);
}

std::shared_ptr<Connection> PendingBudget::victim_for(const asio::ip::address& from,
                                                      const ServerOptions& o, bool total_full,
                                                      std::chrono::steady_clock::time_point now) {
  // The oldest pending connection past the grace of the address with the most pending
  // ones among those `in_scope`: the flooder pays for its flood, not the newcomer.
  // `flooders_too`: also within the grace, but only of addresses over their own budget.
  const auto old_enough = now - o.pending_grace;
  auto evict_heaviest = [&](auto in_scope, bool flooders_too,
                            std::chrono::steady_clock::time_point cutoff) -> std::shared_ptr<Connection> {
    // Candidates: addresses in scope with a connection past the grace (the list is
    // oldest first, so those are a prefix of it); the victim is the oldest connection of
    // the candidate holding the most pending connections.
    std::list<Entry>::iterator best = order.end();
    size_t most = 0;
    for (auto it = order.begin(); it != order.end(); ++it) {
      if (it->since > cutoff && !flooders_too) break;
      if (!in_scope(it->from)) continue;
      const size_t n = per_address.at(it->from);
      if (flooders_too && n <= o.max_pending_per_address) continue;
      if (n > most) most = n, best = it;  // first seen = oldest of that address
    }
    if (best == order.end()) return nullptr;
    auto c = best->conn.lock();
    remove(best);
    return c;
  };
  auto count = [](const auto& m, const auto& k) {
    auto it = m.find(k);
    return it == m.end() ? size_t(0) : it->second;
  };
  auto anyone = [](const asio::ip::address&) { return true; };
  std::shared_ptr<Connection> victim;
  const Prefix prefix = prefix_of(from);
  if (o.max_pending_per_address && count(per_address, from) >= o.max_pending_per_address)
    victim = evict_heaviest([&](const asio::ip::address& a) { return a == from; }, false, old_enough);
  else if (o.max_pending_per_prefix && count(per_prefix, prefix) >= o.max_pending_per_prefix)
    victim = evict_heaviest([&](const asio::ip::address& a) { return prefix_of(a) == prefix; }, false, old_enough);
  else if ((o.max_pending_connections && order.size() >= o.max_pending_connections) || total_full)
    victim = evict_heaviest(anyone, false, old_enough);
  // At max_connections with every pending connection inside the grace (a flood opened
  // faster than the grace, reopening what is evicted): the grace protects only
  // addresses within their budget, so the newcomer takes the slot of a flooder's
  // oldest pending connection instead of being refused.
  if (!victim && total_full) victim = evict_heaviest(anyone, true, old_enough);
  // Over the global pending budget with every pending connection inside the grace and
  // every address within its own budget: many addresses (each under its per-address and
  // per-prefix bounds) recycling connections faster than the grace. Past twice the
  // budget the grace shrinks to a quarter: a handshake takes round trips, not a quarter
  // of a second, so an honest burst has finished (and left the budget) by then, while a
  // connection still pending at that age is the churn's; at the budget with the server
  // full, it no longer applies at all. The newcomer takes the slot of the oldest such
  // connection of the address holding the most (a newcomer's address holds few, so it is
  // not the one evicted next).
  if (!victim && o.max_pending_connections && order.size() >= o.max_pending_connections &&
      (total_full || order.size() >= 2 * o.max_pending_connections))
    victim = evict_heaviest(anyone, false, total_full ? now : now - o.pending_grace / 4);
  return victim;
}

namespace {

// PROTOCOL.md §6: a tile of n stored bytes travels in a TileData frame of n + 52 bytes,
// a map's pack header and skip grid in one MapInfo frame. Raises the offered
// max_frame_bytes to fit the largest of these (fit_frame_to_catalog), and says what it
// offers and what cannot be served at all.
void fit_frame_limit(ServerCore& core) {
  uint64_t need = 0;
  std::string what;
  for (const auto& m : core.catalog.maps()) {
    if (m->largest_stored_tile() && m->largest_stored_tile() + proto::kTileDataPrefixBytes > need) {
      need = m->largest_stored_tile() + proto::kTileDataPrefixBytes;
      what = "the largest tile (" + std::to_string(m->largest_stored_tile()) + " bytes, map '" + m->name() + "')";
    }
    if (m->map_info_frame_bytes() > need) {
      need = m->map_info_frame_bytes();
      what = "the map info of map '" + m->name() + "'";
    }
  }
  uint32_t& cap = core.options.limits.max_frame_bytes;
  if (core.options.fit_frame_to_catalog && need > cap) {
    cap = uint32_t(std::min<uint64_t>(need, proto::kMaxFrameBytesCeiling));
    core.log("max_frame_bytes raised to " + std::to_string(cap) + " to fit " + what);
  }
  if (need <= cap) return;
  uint64_t tiles = 0, maps = 0;
  for (const auto& m : core.catalog.maps()) {
    maps += m->map_info_frame_bytes() > cap;
    for (const TileIndexEntry& t : m->pack().tiles())
      tiles += uint64_t(t.stored_size) + proto::kTileDataPrefixBytes > cap;
  }
  core.log("warning: max_frame_bytes " + std::to_string(cap) + " is too small for " + std::to_string(tiles) +
           " tile(s) (answered tile_too_large) and " + std::to_string(maps) +
           " map(s) (open_map answered limit_exceeded); " + what + " needs " + std::to_string(need));
}

// Runs `io` until it stops. With a busy-poll window, the thread keeps running ready
// handlers and polling the reactor without blocking until nothing has happened for
// `window`, and only then blocks for the next event (one handler), so back-to-back
// requests on a connection never pay a thread wake-up.
void run_io(asio::io_context& io, std::chrono::microseconds window) {
  if (window.count() <= 0) {
    io.run();
    return;
  }
  using Clock = std::chrono::steady_clock;
  auto last = Clock::now();
  while (!io.stopped()) {
    if (io.poll() > 0) {
      last = Clock::now();
      continue;
    }
    if (io.stopped()) break;
    if (Clock::now() - last < window) continue;
    io.run_one();  // blocks until one handler ran (or the context stopped)
    last = Clock::now();
  }
}

}  // namespace

struct Server::Impl {
  // One I/O thread: the io_context is told so (Asio then queues handlers posted from
  // its own thread without taking the scheduler's lock) and connections need no strand.
  explicit Impl(unsigned threads) : io(threads == 1 ? 1 : BOOST_ASIO_CONCURRENCY_HINT_DEFAULT), one_thread(threads == 1) {}
  ServerCore core;
  asio::io_context io;
  const bool one_thread;
  // The acceptor, stats timer and signal set share one strand, so shutdown (posted to
  // it) never races the accept loop when several I/O threads run.
  asio::strand<asio::io_context::executor_type> control{asio::make_strand(io)};
  tcp::acceptor acceptor{control};
  asio::steady_timer stats_timer{control};
  asio::signal_set signals{control};
  std::vector<std::thread> threads;
  uint16_t port = 0;
  // Held open so that, out of descriptors (EMFILE), the server can still accept one
  // client to tell it Error(overloaded) instead of leaving it hanging in the backlog.
  int spare_fd = -1;
  ~Impl() {
    if (spare_fd >= 0) ::close(spare_fd);
  }

  std::mutex state_mu;
  std::condition_variable state_cv;
  bool running = false, stopped = false;
  size_t threads_done = 0;  // I/O threads whose run() returned
  int signal = 0;

  asio::awaitable<void> accept_loop();
  asio::awaitable<void> stats_loop();
  // Counts a fresh socket against the budgets (evicting a pending connection if needed)
  // and starts its Connection, or refuses it with Error(overloaded).
  void admit(tcp::socket socket);
  void reject(tcp::socket socket, const char* why);
  // At max_connections with no pending connection to evict (core.mu held): the newcomer's
  // network holds little (at least 2 useful connections fewer than the network holding
  // the most), so it takes the slot of that network's longest-idle useful connection. So
  // useful-looking connections from a few networks cannot hold the server full against
  // every other network; they keep at most an even share. Null: no such victim.
  std::shared_ptr<Connection> useful_victim_locked(const asio::ip::address& from);
  void shutdown_on_io();  // runs on the io_context
  // EMFILE: frees the spare descriptor, accepts and refuses one client, takes it back.
  bool shed_one();  // true: one client was accepted and refused
};

// Descriptors the server needs besides its connections: the listening socket, the
// spare, the packs, the I/O threads' epoll and eventfds, stdio, and what a library may open.
namespace {

size_t fd_reserve(const Catalog& c) { return 64 + c.maps().size(); }

// Raises the soft descriptor limit to the hard one and lowers max_connections to what
// the limit leaves after the reserve, so the server refuses clients with an Error at its
// own limit before the kernel refuses it descriptors.
void fit_connections_to_fd_limit(ServerCore& core) {
  rlimit r{};
  if (::getrlimit(RLIMIT_NOFILE, &r) != 0) return;
  if (r.rlim_cur < r.rlim_max) {
    rlimit want = r;
    want.rlim_cur = r.rlim_max;
    if (::setrlimit(RLIMIT_NOFILE, &want) == 0) r = want;
  }
  if (r.rlim_cur == RLIM_INFINITY) return;
  const size_t reserve = fd_reserve(core.catalog);
  const size_t usable = r.rlim_cur > reserve + 1 ? size_t(r.rlim_cur) - reserve : 1;
  if (core.options.max_connections > usable) {
    core.log("max_connections lowered from " + std::to_string(core.options.max_connections) + " to " +
             std::to_string(usable) + " to fit the descriptor limit " + std::to_string(r.rlim_cur) +
             " (ulimit -n) less a reserve of " + std::to_string(reserve));
    core.options.max_connections = usable;
  }
}

}  // namespace

bool Server::Impl::shed_one() {
  if (spare_fd < 0) return false;
  ::close(spare_fd);
  spare_fd = -1;
  error_code ec;
  tcp::socket s(io);
  acceptor.non_blocking(true, ec);
  acceptor.accept(s, ec);
  error_code ignored;
  acceptor.non_blocking(false, ignored);
  if (!ec) {
    core.stats.connection_rejected();
    if (core.tls) s.close(ignored);
    else reject(std::move(s), "server out of file descriptors");
  }
  spare_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  return !ec;
}

asio::awaitable<void> Server::Impl::accept_loop() {
  using namespace std::chrono_literals;
  constexpr int kAcceptBurst = 63;
  auto backoff = 10ms;
  asio::steady_timer pause(control);
  {
    error_code ec;
    acceptor.non_blocking(true, ec);  // the burst's synchronous accepts never block
  }
  while (acceptor.is_open()) {
    error_code ec;
    // Each connection gets its own strand: its three coroutines never run concurrently.
    // With one I/O thread nothing runs concurrently anyway, and the strand's locking and
    // dispatch is a measurable share of an unpipelined request (bench_serve_vs_nginx).
    const asio::any_io_executor ex =
        one_thread ? asio::any_io_executor(io.get_executor()) : asio::any_io_executor(asio::make_strand(io));
    tcp::socket socket = co_await acceptor.async_accept(ex, asio::redirect_error(asio::use_awaitable, ec));
    if (ec) {
      if (!acceptor.is_open() || ec == asio::error::operation_aborted) break;
      if ((ec.value() == EMFILE || ec.value() == ENFILE) && shed_one()) {
        core.log_repeated("accept", "out of file descriptors (" + ec.message() +
                                        "): refusing clients with overloaded");
        continue;
      }
      // EMFILE/ENFILE/ENOBUFS...: back off instead of spinning on the failing accept.
      core.log_repeated("accept", "accept failed: " + ec.message() + "; retrying in " +
                                      std::to_string(backoff.count()) + " ms");
      pause.expires_after(backoff);
      co_await pause.async_wait(asio::redirect_error(asio::use_awaitable, ec));
      backoff = std::min(backoff * 2, std::chrono::milliseconds(1000));
      continue;
    }
    backoff = 10ms;
    admit(std::move(socket));
    // Drain what else waits in the backlog now (at most kAcceptBurst), without a trip
    // through the scheduler per connection: under a connection flood the backlog is a
    // FIFO of the attacker's connects (hundreds to thousands measured by scripts/attack),
    // and an honest client waits behind all of them before its Hello is even read.
    // Errors (would_block, EMFILE) end the burst; the next async_accept handles them.
    for (int i = 0; i < kAcceptBurst && acceptor.is_open(); ++i) {
      tcp::socket more = acceptor.accept(ex, ec);
      if (ec) break;
      admit(std::move(more));
    }
  }
}

void Server::Impl::admit(tcp::socket socket) {
  error_code ignored;
  socket.set_option(tcp::no_delay(true), ignored);
  const asio::ip::address from = socket.remote_endpoint(ignored).address();
  std::shared_ptr<Connection> conn, victim;
  const char* refused = nullptr;
  {
    std::lock_guard lock(core.mu);
    if (core.stopping) return;
    const size_t per_address_limit = core.options.max_connections_per_address;
    const auto here = core.per_address.find(from);
    const bool total_full = core.connections.size() - core.evicting >= core.options.max_connections;
    if (per_address_limit && here != core.per_address.end() && here->second >= per_address_limit) {
      refused = "too many connections from your address";
    } else if (core.tls &&
               !core.tls_handshakes.admit(PendingBudget::prefix_of(from), std::chrono::steady_clock::now())) {
      refused = "too many TLS handshakes from your network";
    } else {
      victim = core.pending.victim_for(from, core.options, total_full, std::chrono::steady_clock::now());
      if (total_full && !victim) victim = useful_victim_locked(from);
      if (total_full && !victim) {
        refused = "server at its connection limit";
      } else {
        if (victim) {
          victim->mark_evicted();  // under core.mu: leaves the count of live connections
          ++core.evicting;
        }
        conn = std::make_shared<Connection>(std::move(socket), core, from);
        core.connections.insert(conn);
        ++core.per_address[from];
        conn->enter_pending(core.pending.add(conn, from));
      }
    }
  }
  if (victim) {
    core.stats.connection_evicted();
    victim->stop();
  }
  if (!conn) {
    core.stats.connection_rejected();
    if (core.tls) socket.close(ignored);  // no TLS session yet: a plain Error would be garbage
    else reject(std::move(socket), refused);
    return;
  }
  core.stats.connection_opened();
  conn->start();
}

std::shared_ptr<Connection> Server::Impl::useful_victim_locked(const asio::ip::address& from) {
  if (core.useful_per_prefix.empty()) return nullptr;
  const PendingBudget::Prefix mine = PendingBudget::prefix_of(from);
  const auto here = core.useful_per_prefix.find(mine);
  const size_t held = here == core.useful_per_prefix.end() ? 0 : here->second;
  auto heaviest = core.useful_per_prefix.begin();
  for (auto it = core.useful_per_prefix.begin(); it != core.useful_per_prefix.end(); ++it)
    if (it->second > heaviest->second) heaviest = it;
  if (heaviest->first == mine || heaviest->second < held + 2) return nullptr;
  std::shared_ptr<Connection> idlest;
  for (const auto& c : core.connections)  // O(connections), only at max_connections
    if (c->evictable_useful() && c->prefix() == heaviest->first && (!idlest || c->last_read() < idlest->last_read()))
      idlest = c;
  return idlest;
}

// Over a connection limit: one Error(overloaded) frame, best effort, then close.
void Server::Impl::reject(tcp::socket socket, const char* why) {
  auto s = std::make_shared<tcp::socket>(std::move(socket));
  auto frame = std::make_shared<std::vector<uint8_t>>();
  proto::ErrorMessage e{proto::ErrorCode::overloaded, why};
  proto::Limits l;
  (void)proto::encode_message(e, proto::kNoRequest, proto::kFlagFinal, l, *frame);
  // Non-blocking single write: a fresh socket's send buffer always has room for ~60 bytes.
  error_code ec;
  s->non_blocking(true, ec);
  asio::write(*s, asio::buffer(*frame), ec);
  s->shutdown(tcp::socket::shutdown_both, ec);
  s->close(ec);
}

asio::awaitable<void> Server::Impl::stats_loop() {
  while (true) {
    error_code ec;
    stats_timer.expires_after(core.options.stats_interval);
    co_await stats_timer.async_wait(asio::redirect_error(asio::use_awaitable, ec));
    if (ec) break;
    core.log(core.stats.snapshot().line());
  }
}

void Server::Impl::shutdown_on_io() {
  error_code ignored;
  acceptor.close(ignored);
  stats_timer.cancel();
  signals.cancel(ignored);
  std::vector<std::shared_ptr<Connection>> conns;
  {
    std::lock_guard lock(core.mu);
    core.stopping = true;
    conns.assign(core.connections.begin(), core.connections.end());
  }
  for (auto& c : conns) c->shut_down();
}

Server::Server(Catalog catalog, ServerOptions options) {
  if (options.threads == 0) throw Error("serve: --threads must be at least 1");
  impl_ = std::make_unique<Impl>(options.threads);
  if (proto::Status s = proto::validate(options.limits); !s)
    throw Error("serve: bad limits: " + proto::to_string(s));
  if (options.max_control_frames == 0 || options.max_connections == 0)
    throw Error("serve: max_control_frames and max_connections must be > 0");
  if (options.tls_cert_file.empty() != options.tls_key_file.empty())
    throw Error("serve: TLS needs both --tls-cert and --tls-key");
  if (!options.tls_cert_file.empty()) {
    auto ctx = std::make_unique<asio::ssl::context>(asio::ssl::context::tls_server);
    net::allow_only_tls12_and_later(*ctx);
    error_code ec;
    ctx->use_certificate_chain_file(options.tls_cert_file, ec);
    if (ec) throw Error("serve: --tls-cert '" + options.tls_cert_file + "': " + ec.message());
    ctx->use_private_key_file(options.tls_key_file, asio::ssl::context::pem, ec);
    if (ec) throw Error("serve: --tls-key '" + options.tls_key_file + "': " + ec.message());
    if (!SSL_CTX_check_private_key(ctx->native_handle()))
      throw Error("serve: --tls-key '" + options.tls_key_file + "' does not match --tls-cert '" +
                  options.tls_cert_file + "'");
    impl_->core.tls = std::move(ctx);
  }
  if (!(options.tls_handshakes_per_second >= 0) || !(options.tls_handshake_burst >= 1))
    throw Error("serve: --tls-handshake-rate must be >= 0 and its burst >= 1");
  impl_->core.tls_handshakes = HandshakeLimiter(options.tls_handshakes_per_second, options.tls_handshake_burst);
  impl_->core.options = std::move(options);
  if (!impl_->core.options.tile_source) impl_->core.options.tile_source = std::make_shared<PackTileSource>();
  impl_->core.catalog = std::move(catalog);
  std::vector<size_t> tiles;
  for (const auto& m : impl_->core.catalog.maps()) tiles.push_back(m->pack().tiles().size());
  impl_->core.payloads.configure(impl_->core.options.tile_cache_bytes, tiles);
  fit_frame_limit(impl_->core);
}

Server::~Server() { stop(); }

void Server::start() {
  Impl& d = *impl_;
  {
    std::lock_guard lock(d.state_mu);
    if (d.running || d.stopped) throw Error("serve: server already started");
  }
  const auto& o = d.core.options;
  error_code ec;
  auto addr = asio::ip::make_address(o.host, ec);
  if (ec) throw Error("serve: --listen: '" + o.host + "' is not an IP address");
  tcp::endpoint ep(addr, o.port);
  const std::string where = o.host + ":" + std::to_string(o.port);
  d.acceptor.open(ep.protocol(), ec);
  if (!ec) d.acceptor.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) d.acceptor.bind(ep, ec);
  if (!ec) d.acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) throw Error("serve: cannot listen on " + where + ": " + ec.message());
  d.port = d.acceptor.local_endpoint().port();
  fit_connections_to_fd_limit(d.core);
  d.spare_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  asio::co_spawn(d.control, d.accept_loop(), asio::detached);
  if (o.stats_interval.count() > 0) asio::co_spawn(d.control, d.stats_loop(), asio::detached);
  {
    std::lock_guard lock(d.state_mu);
    d.running = true;
  }
  for (unsigned i = 0; i < o.threads; ++i)
    d.threads.emplace_back([&d] {
      try {
        run_io(d.io, d.core.options.busy_poll);
      } catch (const std::exception& e) {
        d.core.log(std::string("I/O thread: ") + e.what());
      }
      {
        std::lock_guard lock(d.state_mu);
        ++d.threads_done;
      }
      d.state_cv.notify_all();
    });
}

void Server::stop() {
  Impl& d = *impl_;
  {
    std::lock_guard lock(d.state_mu);
    if (d.stopped) return;
    d.stopped = true;
    if (!d.running) return;
  }
  asio::post(d.control, [&d] { d.shutdown_on_io(); });
  // Connections end their coroutines once their sockets close; run() then returns. A
  // coroutine stuck past the grace period (it should not happen) is cut off by io.stop().
  {
    std::unique_lock lock(d.state_mu);
    if (!d.state_cv.wait_for(lock, std::chrono::seconds(5), [&] { return d.threads_done == d.core.options.threads; }))
      d.io.stop();
  }
  for (auto& t : d.threads) t.join();
  d.threads.clear();
  {  // Sockets must go before their io_context (they would if io.stop() cut run() short).
    std::lock_guard lock(d.core.mu);
    d.core.connections.clear();
  }
  std::lock_guard lock(d.state_mu);
  d.running = false;
}

int Server::wait_for_signal() {
  Impl& d = *impl_;
  {
    std::lock_guard lock(d.state_mu);
    if (!d.running || d.stopped) return 0;
  }
  std::promise<int> got;
  auto fut = got.get_future();
  // The signal set lives on the control strand, like everything shutdown touches.
  asio::post(d.control, [&d, &got] {
    {
      std::lock_guard lock(d.core.mu);
      if (d.core.stopping) return got.set_value(0);  // stop() came first
    }
    error_code ec;
    d.signals.add(SIGINT, ec);
    d.signals.add(SIGTERM, ec);
    d.signals.async_wait([&d, &got](const error_code& e, int sig) {
      got.set_value(e ? 0 : sig);
      if (!e) d.shutdown_on_io();
    });
  });
  int sig = fut.get();
  stop();
  return sig;
}

uint16_t Server::port() const { return impl_->port; }
uint32_t Server::max_frame_bytes() const { return impl_->core.options.limits.max_frame_bytes; }
StatsSnapshot Server::stats() const { return impl_->core.stats.snapshot(); }
const Catalog& Server::catalog() const { return impl_->core.catalog; }

}  // namespace st::server

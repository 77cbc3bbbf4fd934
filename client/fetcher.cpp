#include "client/fetcher.hpp"

#include <unistd.h>

#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/redirect_error.hpp>
#include <future>

#include "common/error.hpp"

namespace st::client {

using proto::ErrorCode;
using proto::MessageType;

namespace {
constexpr size_t kReadChunk = 64 * 1024;

proto::Limits local_limits(const ClientOptions& o) {
  proto::Limits l;
  l.max_frame_bytes = o.max_frame_bytes;
  l.max_in_flight = o.max_in_flight;
  l.max_tiles_per_batch = std::max<uint16_t>(o.tiles_per_request, 1);
  return l;
}

proto::Limits handshake_limits(const ClientOptions& o) {
  proto::Limits l = local_limits(o);
  l.max_frame_bytes = proto::kMinFrameBytes;
  l.min_version = l.max_version = proto::kHandshakeVersion;
  return l;
}
}  // namespace

Fetcher::Fetcher(Endpoint endpoint, ClientOptions options)
    : endpoint_(std::move(endpoint)),
      options_(std::move(options)),
      notifier_(std::make_shared<Notifier>()),
      pool_(options_.io_pool),
      own_io_(pool_ ? nullptr : std::make_unique<asio::io_context>()),
      io_(pool_ ? pool_->next() : *own_io_) {
  if (proto::Status s = proto::validate(local_limits(options_)); !s)
    throw Error("client: bad options: " + proto::to_string(s));
  if (options_.cache_slots == 0 || options_.tiles_per_request == 0 || options_.want_capacity == 0)
    throw Error("client: cache_slots, tiles_per_request and want_capacity must be > 0");
  if (options_.backoff_initial.count() <= 0 || options_.backoff_max < options_.backoff_initial)
    throw Error("client: backoff_initial must be > 0 and <= backoff_max");
  if (options_.tls) {
    tls_ = std::make_unique<asio::ssl::context>(asio::ssl::context::tls_client);
    net::allow_only_tls12_and_later(*tls_);
    tls_->set_verify_mode(asio::ssl::verify_peer);
    error_code ec;
    if (options_.tls_ca_file.empty()) tls_->set_default_verify_paths(ec);
    else tls_->load_verify_file(options_.tls_ca_file, ec);
    if (ec)
      throw Error("client: TLS CA file '" + options_.tls_ca_file + "': " + ec.message());
  }
  rx_.resize(kReadChunk);
  int fd = ::dup(notifier_->fd());
  if (fd < 0) throw Error("client: dup(eventfd) failed");
  notify_desc_.assign(fd);
}

Fetcher::~Fetcher() { stop(); }

void Fetcher::hold() {
  std::lock_guard lock(live_mu_);
  ++live_;
}

void Fetcher::release() {
  // Notify under the lock: stop() may destroy this Fetcher as soon as it sees zero.
  std::lock_guard lock(live_mu_);
  if (--live_ == 0) live_cv_.notify_all();
}

void Fetcher::spawn(asio::awaitable<void> a) {
  hold();
  asio::co_spawn(io_, std::move(a), [this](std::exception_ptr) { release(); });
}

template <typename F>
void Fetcher::post(F&& f) {
  hold();
  asio::post(io_, [this, f = std::forward<F>(f)]() mutable {
    struct Release {
      Fetcher* self;
      ~Release() { self->release(); }
    } r{this};
    f();
  });
}

void Fetcher::start() {
  spawn(run());
  spawn(notifier_loop());
  if (pool_) return;  // the pool's thread runs io_
  thread_ = std::thread([this] {
    try {
      io_.run();
    } catch (...) {
      // Coroutines catch their own errors; nothing reaches here but bad_alloc. The maps
      // keep answering from their caches.
    }
  });
}

void Fetcher::stop() {
  if (stopped_.exchange(true)) return;
  post([this] {
    stopping_io_ = true;
    if (socket_) socket_->close();
    wake_timer_.cancel();
    backoff_timer_.cancel();
    for (auto* t : watchdog_timers_) t->cancel();  // end now, not at the next tick
    error_code ec;
    notify_desc_.close(ec);  // ends notifier_loop
    fail_controls(proto::ErrorMessage{ErrorCode::shutting_down, "client stopped"});
  });
  if (thread_.joinable()) {
    // Coroutines end once their sockets and timers are closed; the guard bounds the wait.
    std::promise<void> finished;
    auto done = finished.get_future();
    std::thread guard([this, &done] {
      if (done.wait_for(std::chrono::seconds(5)) != std::future_status::ready) io_.stop();
    });
    thread_.join();
    finished.set_value();
    guard.join();
  } else if (pool_) {
    // Coroutines end once their sockets and timers are closed (the stop handler above
    // closes and cancels them all); the pool's thread keeps running other fetchers.
    std::unique_lock lock(live_mu_);
    live_cv_.wait(lock, [this] { return live_ == 0; });
  }
}

uint32_t Fetcher::next_id() {
  if (++last_id_ == proto::kNoRequest) ++last_id_;
  return last_id_;
}

ClientStats Fetcher::stats() const {
  std::lock_guard lock(stats_mu_);
  ClientStats s = stats_;
  s.connected = connected_.load();
  s.refused = refused_.load();
  return s;
}

// ---------------------------------------------------------------- API calls

proto::Message Fetcher::call(const proto::Message& request) {
  if (stopped_) throw Error("client: stopped");
  if (refused_) {
    std::lock_guard lock(stats_mu_);
    throw Error("client: " + refusal_);
  }
  auto promise = std::make_shared<std::promise<proto::Message>>();
  auto future = promise->get_future();
  auto c = std::make_shared<Control>();
  c->request = request;
  c->done = [promise](proto::Message&& m) {
    try {
      promise->set_value(std::move(m));
    } catch (const std::future_error&) {  // already answered (stop raced an answer)
    }
  };
  post([this, c] {
    if (stopping_io_) return c->done(proto::ErrorMessage{ErrorCode::shutting_down, "client stopped"});
    if (refused_) return c->done(proto::ErrorMessage{ErrorCode::auth_failed, "authentication failed"});
    controls_.push_back(c);
    wake();
  });
  if (future.wait_for(options_.request_timeout) != std::future_status::ready) {
    post([this, c] {  // forget it: a late answer then finds no one waiting
      std::erase(controls_, c);
      for (auto it = controls_sent_.begin(); it != controls_sent_.end(); ++it)
        if (it->second == c) {
          controls_sent_.erase(it);
          break;
        }
    });
    std::string why;
    if (!connected_) {
      std::lock_guard lock(stats_mu_);
      why = " (not connected" + (last_failure_.empty() ? std::string() : ": " + last_failure_) + ")";
    }
    throw Error("client: no answer to " + std::string(proto::to_string(proto::type_of(request))) + " from " +
                endpoint_.host + ":" + std::to_string(endpoint_.port) + " within " +
                std::to_string(options_.request_timeout.count()) + " ms" + why);
  }
  proto::Message m = future.get();
  if (auto* e = std::get_if<proto::ErrorMessage>(&m))
    throw Error("client: server refused " + std::string(proto::to_string(proto::type_of(request))) + ": " +
                std::string(proto::to_string(e->code)) + ": " + e->message);
  return m;
}

std::shared_ptr<RemoteMap> Fetcher::open(const std::string& name) {
  if (proto::Status s = proto::validate_map_name(name); !s)
    throw Error("client: open('" + name + "'): " + proto::to_string(s));
  proto::Message m = call(proto::OpenMap{name});
  auto* info = std::get_if<proto::MapInfo>(&m);
  if (!info) throw Error("client: open('" + name + "'): unexpected answer");
  auto map = std::make_shared<RemoteMap>(name, std::move(info->pack_header), std::move(info->skip_grid),
                                         options_, notifier_);
  // Register on the I/O thread; the map id may belong to a connection that has since
  // dropped, so the map is (re)opened there by the same rules as after a reconnect.
  auto registered = std::make_shared<std::promise<std::shared_ptr<RemoteMap>>>();
  auto fut = registered->get_future();
  post([this, map, registered] {
    for (auto& s : maps_)
      if (s.map->name() == map->name()) return registered->set_value(s.map);
    maps_.push_back(MapSlot{map, 0});
    if (socket_ && connected_) reopen(maps_.back());
    registered->set_value(map);
  });
  if (fut.wait_for(options_.request_timeout) != std::future_status::ready)
    throw Error("client: open('" + name + "'): the fetcher thread did not answer");
  return fut.get();
}

// Sends OpenMap for a map on the current connection; its answer sets the map id, provided
// the pack is unchanged (same header bytes). A replaced pack leaves the map unopened:
// its lookups keep answering from what is cached.
void Fetcher::reopen(MapSlot& slot) {
  slot.map_id = 0;
  auto c = std::make_shared<Control>();
  c->request = proto::OpenMap{slot.map->name()};
  RemoteMap* target = slot.map.get();
  const uint64_t epoch = epoch_;
  c->done = [this, target, epoch](proto::Message&& m) {
    if (epoch != epoch_) return;
    auto* info = std::get_if<proto::MapInfo>(&m);
    if (!info || info->pack_header != target->header_bytes()) return;
    for (auto& s : maps_)
      if (s.map.get() == target) s.map_id = info->map_id;
    wake();
  };
  controls_.push_front(c);
  wake();
}

// ---------------------------------------------------------------- the session

asio::awaitable<void> Fetcher::run() {
  auto backoff = options_.backoff_initial;
  while (!stopping_io_) {
    const bool handshook = co_await session();
    if (stopping_io_ || refused_) break;
    if (handshook) backoff = options_.backoff_initial;
    error_code ec;
    backoff_timer_.expires_after(backoff);
    co_await backoff_timer_.async_wait(asio::redirect_error(asio::use_awaitable, ec));
    backoff = std::min(backoff * 2, options_.backoff_max);
  }
}

asio::awaitable<bool> Fetcher::write(net::Stream& sock, const std::vector<uint8_t>& bytes) {
  error_code ec;
  writing_ = true;
  write_started_ = Clock::now();
  co_await sock.write(asio::buffer(bytes), ec);
  writing_ = false;
  if (ec) co_return false;
  std::lock_guard lock(stats_mu_);
  stats_.bytes_sent += bytes.size();
  co_return true;
}

asio::awaitable<bool> Fetcher::read_frame(net::Stream& sock, proto::Frame& out) {
  for (;;) {
    if (rx_begin_ < rx_end_) {
      auto r = parser_->feed(std::span<const uint8_t>(rx_.data() + rx_begin_, rx_end_ - rx_begin_));
      rx_begin_ += r.consumed;
      if (r.state == proto::FrameParser::State::frame) {
        out = parser_->take_frame();
        std::lock_guard lock(stats_mu_);
        ++stats_.frames_received;
        co_return true;
      }
      if (r.state == proto::FrameParser::State::error) {
        std::lock_guard lock(stats_mu_);
        ++stats_.protocol_errors;
        co_return false;
      }
    }
    error_code ec;
    size_t n = co_await sock.read_some(asio::buffer(rx_), ec);
    if (ec) co_return false;
    rx_begin_ = 0;
    rx_end_ = n;
    last_rx_ = Clock::now();
    std::lock_guard lock(stats_mu_);
    stats_.bytes_received += n;
  }
}

void Fetcher::note_failure(const std::string& why) {
  std::lock_guard lock(stats_mu_);
  last_failure_ = why;
}

void Fetcher::refuse(const std::string& why) {
  {
    std::lock_guard lock(stats_mu_);
    if (refused_) return;
    refusal_ = why;
    refused_ = true;
  }
  fail_controls(proto::ErrorMessage{ErrorCode::auth_failed, proto::sanitize_text(why, 512)});
}

void Fetcher::fail_controls(const proto::ErrorMessage& e) {
  for (auto& c : controls_) c->done(proto::ErrorMessage(e));
  for (auto& [id, c] : controls_sent_) c->done(proto::ErrorMessage(e));
  controls_.clear();
  controls_sent_.clear();
}

// PROTOCOL.md §11: with a key, prove it (Auth) and check the server's proof (AuthOk);
// without one, there is nothing to do (a server wanting a key refused the Hello).
asio::awaitable<bool> Fetcher::authenticate(net::Stream& sock, const proto::HelloAck& ack) {
  const bool server_wants_key = (ack.features & proto::kFeatureAuth) != 0;
  if (options_.key.empty()) co_return true;  // check_hello_ack refused the bit unoffered
  const std::string server = "server " + endpoint_.host + ":" + std::to_string(endpoint_.port);
  if (!server_wants_key) {
    refuse(server + " does not ask for the key: refusing to trust it (the client has a key)");
    co_return false;
  }
  proto::Auth auth;
  auth.client_nonce = proto::random_nonce();
  auth.proof = proto::client_proof(options_.key, ack.nonce, auth.client_nonce);
  std::vector<uint8_t> out;
  const uint32_t id = next_id();
  if (!proto::encode_message(auth, id, proto::kFlagFinal, limits_, out)) co_return false;
  if (!co_await write(sock, out)) co_return false;
  proto::Frame f;
  if (!co_await read_frame(sock, f)) co_return false;
  proto::Message m;
  if (!proto::decode_message(f, limits_, m)) co_return false;
  if (auto* e = std::get_if<proto::ErrorMessage>(&m)) {  // request id 0: the server closes
    if (e->code == ErrorCode::auth_failed || e->code == ErrorCode::auth_required)
      refuse(server + " refused the key: " + std::string(proto::to_string(e->code)) + ": " + e->message);
    co_return false;
  }
  auto* ok = std::get_if<proto::AuthOk>(&m);
  if (!ok || f.header.request_id != id) co_return false;
  if (!proto::proofs_equal(ok->proof, proto::server_proof(options_.key, ack.nonce, auth.client_nonce))) {
    refuse(server + " proved a different key: not the server this client was given a key for");
    co_return false;
  }
  co_return true;
}

asio::awaitable<bool> Fetcher::session() {
  auto sock = std::make_shared<net::Stream>(tcp::socket(io_), tls_.get());
  socket_ = sock;
  ++epoch_;
  const uint64_t epoch = epoch_;
  rx_begin_ = rx_end_ = 0;
  limits_ = handshake_limits(options_);
  parser_ = std::make_unique<proto::FrameParser>(limits_, proto::Receiver::client);
  last_rx_ = Clock::now();
  spawn(watchdog(sock, epoch));

  auto fail_connect = [&] {
    std::lock_guard lock(stats_mu_);
    ++stats_.connect_failures;
  };
  // Connect (the watchdog bounds it by connect_timeout).
  error_code ec;
  tcp::resolver resolver(io_);
  auto endpoints = co_await resolver.async_resolve(endpoint_.host, std::to_string(endpoint_.port),
                                                   asio::redirect_error(asio::use_awaitable, ec));
  if (!ec) co_await asio::async_connect(sock->socket(), endpoints, asio::redirect_error(asio::use_awaitable, ec));
  if (!ec) sock->socket().set_option(tcp::no_delay(true), ec);
  if (!ec && sock->tls()) {
    // TLS: SNI and the certificate checked against the CA file for the expected name.
    const std::string& name = options_.tls_server_name.empty() ? endpoint_.host : options_.tls_server_name;
    SSL_set_tlsext_host_name(sock->tls_stream()->native_handle(), name.c_str());
    sock->tls_stream()->set_verify_callback(asio::ssl::host_name_verification(name));
    co_await sock->handshake(asio::ssl::stream_base::client, ec);
    if (ec) note_failure("TLS handshake: " + ec.message());
  } else if (ec) {
    note_failure(ec.message());
  }
  if (ec || stopping_io_) {
    fail_connect();
    end_session();
    co_return false;
  }

  // Handshake (PROTOCOL.md §5).
  proto::Hello hello = proto::make_hello(local_limits(options_), options_.client_name);
  if (!options_.key.empty()) hello.features |= proto::kFeatureAuth;
  std::vector<uint8_t> out;
  proto::Frame f;
  proto::HelloAck ack;
  proto::Limits negotiated;
  // One step per statement: g++ 12 miscompiles co_await inside && chains.
  bool ok = bool(proto::encode_message(hello, next_id(), proto::kFlagFinal, limits_, out));
  if (ok) ok = co_await write(*sock, out);
  if (ok) ok = co_await read_frame(*sock, f);
  if (ok && f.header.type == MessageType::error) {
    // A server that wants a key we do not have says so in the handshake: final.
    proto::ErrorMessage e;
    if (proto::decode_payload(f.payload, limits_, e) &&
        (e.code == ErrorCode::auth_required || e.code == ErrorCode::auth_failed))
      refuse("server " + endpoint_.host + ":" + std::to_string(endpoint_.port) + " refused the connection: " +
             std::string(proto::to_string(e.code)) + ": " + e.message);
    ok = false;
  }
  ok = ok && f.header.type == MessageType::hello_ack && proto::decode_payload(f.payload, limits_, ack) &&
       proto::check_hello_ack(hello, ack, negotiated);
  if (ok) {
    limits_ = negotiated;
    parser_->set_limits(negotiated);
  }
  if (ok) ok = co_await authenticate(*sock, ack);
  if (!ok || stopping_io_) {
    fail_connect();
    end_session();
    co_return false;
  }
  connected_ = true;
  {
    std::lock_guard lock(stats_mu_);
    ++stats_.connects;
  }
  // Maps and control requests survive reconnects: re-open, re-send.
  for (auto& [id, c] : controls_sent_) {
    c->request_id = 0;
    controls_.push_back(c);
  }
  controls_sent_.clear();
  for (auto& s : maps_) reopen(s);

  spawn(reader(sock));

  // The pump: the only writer on this socket.
  std::vector<WantedTile> wanted;
  std::vector<uint64_t> cancels;
  while (sock->is_open() && !stopping_io_) {
    out.clear();
    bool encode_ok = true;
    while (!controls_.empty() && controls_sent_.size() + tile_requests_.size() < limits_.max_in_flight) {
      auto c = controls_.front();
      controls_.pop_front();
      c->request_id = next_id();
      if (!proto::encode_message(c->request, c->request_id, proto::kFlagFinal, limits_, out)) {
        c->done(proto::ErrorMessage{ErrorCode::invalid_field, "request does not encode"});
        continue;
      }
      controls_sent_[c->request_id] = c;
    }
    for (auto& s : maps_) {
      if (s.map_id == 0) continue;
      cancels.clear();
      s.map->take_cancels(cancels);
      for (size_t i = 0; i < cancels.size(); i += limits_.max_tiles_per_batch) {
        proto::Cancel cancel;
        cancel.map_id = s.map_id;
        cancel.tile_ids.assign(cancels.begin() + i,
                               cancels.begin() + std::min(cancels.size(), i + limits_.max_tiles_per_batch));
        encode_ok &= bool(proto::encode_message(cancel, proto::kNoRequest, proto::kFlagFinal, limits_, out));
      }
    }
    // Round-robin over maps, one batch each, while in-flight slots remain.
    bool progress = true;
    const size_t batch = std::min<size_t>(options_.tiles_per_request, limits_.max_tiles_per_batch);
    while (progress && controls_sent_.size() + tile_requests_.size() < limits_.max_in_flight) {
      progress = false;
      for (auto& s : maps_) {
        if (s.map_id == 0 || controls_sent_.size() + tile_requests_.size() >= limits_.max_in_flight) continue;
        wanted.clear();
        s.map->take_wanted(batch, wanted);
        if (wanted.empty()) continue;
        proto::GetTiles get;
        get.map_id = s.map_id;
        TileRequest tr{s.map.get(), s.map_id, {}};
        for (auto& w : wanted) {
          get.tiles.push_back({w.tile, w.priority});
          tr.tiles.push_back(w.tile);
        }
        const uint32_t id = next_id();
        encode_ok &= bool(proto::encode_message(get, id, proto::kFlagFinal, limits_, out));
        tile_requests_.emplace(id, std::move(tr));
        progress = true;
      }
    }
    if (!encode_ok) break;  // cannot happen with validated limits; reconnect if it does
    if (!out.empty()) {
      if (!co_await write(*sock, out)) break;
      continue;
    }
    wake_timer_.expires_at(Clock::time_point::max());
    co_await wake_timer_.async_wait(asio::redirect_error(asio::use_awaitable, ec));
  }
  end_session();
  co_return true;
}

void Fetcher::end_session() {
  if (socket_) socket_->close();
  if (connected_.exchange(false)) {
    std::lock_guard lock(stats_mu_);
    ++stats_.disconnects;
  }
  tile_requests_.clear();
  for (auto& s : maps_) {
    s.map_id = 0;
    s.map->connection_lost();  // sent tiles are queued again
  }
}

asio::awaitable<void> Fetcher::reader(std::shared_ptr<net::Stream> sock) {
  proto::Frame f;
  while (sock->is_open()) {
    const bool got = co_await read_frame(*sock, f);
    if (!got) break;
    handle(std::move(f));
  }
  sock->close();
  wake();  // the pump sees the closed socket and ends the session
}

void Fetcher::answer_control(uint32_t request_id, proto::Message&& m) {
  auto it = controls_sent_.find(request_id);
  if (it == controls_sent_.end()) return;
  auto c = it->second;
  controls_sent_.erase(it);
  c->done(std::move(m));
  wake();
}

// PROTOCOL.md §3, §7.2: a payload that does not decode, an answer to a tile request not
// in flight, or a connection-level Error ends the connection (run() reconnects and the
// maps re-request what was in flight). Late answers to control calls that timed out are
// dropped quietly: the API already gave up on them.
void Fetcher::handle(proto::Frame&& f) {
  const uint32_t id = f.header.request_id;
  auto protocol_error = [&] {
    {
      std::lock_guard lock(stats_mu_);
      ++stats_.protocol_errors;
    }
    if (socket_) socket_->close();
  };
  auto end_tile_request = [&] {
    if (f.header.final() && tile_requests_.erase(id)) wake();
  };
  if (f.header.type == MessageType::tile_data || f.header.type == MessageType::tile_error) {
    auto it = tile_requests_.find(id);
    if (it == tile_requests_.end()) return protocol_error();
    if (f.header.type == MessageType::tile_data) {
      proto::TileMeta meta;
      std::span<const uint8_t> bytes;
      if (!proto::decode_tile_data_view(f.payload, meta, bytes) || meta.map_id != it->second.map_id)
        return protocol_error();
      it->second.map->tile_arrived(meta, bytes);
    } else {
      proto::TileError te;
      if (!proto::decode_payload(f.payload, limits_, te) || te.map_id != it->second.map_id)
        return protocol_error();
      it->second.map->tile_refused(te.tile_id, te.code);
    }
    return end_tile_request();
  }
  proto::Message m;
  if (!proto::decode_message(f, limits_, m)) return protocol_error();
  if (f.header.type == MessageType::error && (id == proto::kNoRequest || tile_requests_.count(id))) {
    // The server gave up on the connection, or refused a tile batch as a whole
    // (overloaded, shutting down): reconnect, and re-request after the backoff.
    if (socket_) socket_->close();
    return;
  }
  if (f.header.type == MessageType::ping) return;  // v1 servers do not ping
  answer_control(id, std::move(m));
}

asio::awaitable<void> Fetcher::watchdog(std::shared_ptr<net::Stream> sock, uint64_t epoch) {
  const auto tick = std::clamp<std::chrono::milliseconds>(
      std::min(options_.connect_timeout, options_.io_timeout) / 8, std::chrono::milliseconds(2),
      std::chrono::milliseconds(250));
  const auto started = Clock::now();
  asio::steady_timer t(io_);
  watchdog_timers_.push_back(&t);
  struct Unlist {
    std::vector<asio::steady_timer*>& list;
    asio::steady_timer* t;
    ~Unlist() { std::erase(list, t); }
  } unlist{watchdog_timers_, &t};
  while (epoch == epoch_ && !stopping_io_) {
    error_code ec;
    t.expires_after(tick);
    co_await t.async_wait(asio::redirect_error(asio::use_awaitable, ec));
    if (epoch != epoch_ || !sock->is_open()) break;
    const auto now = Clock::now();
    const bool owed = !tile_requests_.empty() || !controls_sent_.empty();
    bool stuck = false;
    if (!connected_ && now - started > options_.connect_timeout) stuck = true;  // connect + handshake
    if (writing_ && now - write_started_ > options_.io_timeout) stuck = true;
    if (connected_ && owed && now - last_rx_ > options_.io_timeout) stuck = true;
    if (stuck) {
      sock->close();
      wake();
      break;
    }
  }
}

asio::awaitable<void> Fetcher::notifier_loop() {
  uint64_t value = 0;
  while (!stopping_io_ && notify_desc_.is_open()) {
    error_code ec;
    co_await notify_desc_.async_read_some(asio::buffer(&value, sizeof value), asio::redirect_error(asio::use_awaitable, ec));
    if (ec && ec != asio::error::would_block && ec != asio::error::try_again) break;
    notifier_->clear();
    wake();
  }
}

}  // namespace st::client

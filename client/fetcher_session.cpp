// The Fetcher's connection side (fetcher.hpp): run() and its sessions (connect,
// handshake, pump), the reader dispatching answers, the watchdog and the eventfd wake-up.
#include "client/fetcher.hpp"

#include <boost/asio/redirect_error.hpp>

#include "common/error.hpp"

namespace st::client {

using proto::ErrorCode;
using proto::MessageType;

asio::awaitable<void> Fetcher::run() {
  auto backoff = options_.backoff_initial;
  while (!stopping_io_) {
    const bool handshook = co_await session();
    if (stopping_io_ || refused_) break;
    if (handshook) backoff = options_.backoff_initial;
    // The session failed or dropped: the next one goes to the next replica (what was in
    // flight was queued again by end_session and is re-requested there).
    if (endpoints_.size() > 1) current_ = (current_.load() + 1) % endpoints_.size();
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
        parser_failed_ = true;
        parser_error_ = proto::to_string(parser_->status());
        note_failure("the server sent bytes that are not a frame of this protocol: " + parser_error_);
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
    session_rx_ += n;
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
  const std::string server = "server " + endpoint_name();
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

// One connection: connect, handshake, then the pump until the socket closes. True if the
// handshake succeeded (run() then restarts its backoff).
asio::awaitable<bool> Fetcher::session() {
  auto sock = std::make_shared<net::Stream>(tcp::socket(io_), tls_.get());
  socket_ = sock;
  ++epoch_;
  rx_begin_ = rx_end_ = 0;
  session_rx_ = 0;
  handshake_timed_out_ = parser_failed_ = false;
  limits_ = proto::handshake_limits(local_limits(options_));
  parser_ = std::make_unique<proto::FrameParser>(limits_, proto::Receiver::client);
  last_rx_ = Clock::now();
  spawn(watchdog(sock, epoch_));  // bounds connect + handshake by connect_timeout

  // One step per statement: g++ 12 miscompiles co_await inside && chains.
  bool ok = co_await connect(*sock);
  if (ok && !stopping_io_) ok = co_await handshake(*sock);
  if (!ok || stopping_io_) {
    {
      std::lock_guard lock(stats_mu_);
      ++stats_.connect_failures;
    }
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
  co_await pump(*sock);
  end_session();
  co_return true;
}

// Resolve, TCP connect and, with TLS, the TLS handshake (SNI and the certificate checked
// against the CA file for the expected name). A failure is noted for error messages.
asio::awaitable<bool> Fetcher::connect(net::Stream& sock) {
  error_code ec;
  tcp::resolver resolver(io_);
  const Endpoint ep = endpoint();
  auto endpoints = co_await resolver.async_resolve(ep.host, std::to_string(ep.port),
                                                   asio::redirect_error(asio::use_awaitable, ec));
  if (!ec) co_await asio::async_connect(sock.socket(), endpoints, asio::redirect_error(asio::use_awaitable, ec));
  if (!ec) sock.socket().set_option(tcp::no_delay(true), ec);
  if (ec) {
    note_failure(ec.message());
    co_return false;
  }
  if (!sock.tls()) co_return true;
  const std::string name = options_.tls_server_name.empty() ? ep.host : options_.tls_server_name;
  SSL_set_tlsext_host_name(sock.tls_stream()->native_handle(), name.c_str());
  sock.tls_stream()->set_verify_callback(asio::ssl::host_name_verification(name));
  co_await sock.handshake(asio::ssl::stream_base::client, ec);
  if (ec) {
    note_failure("TLS handshake: " + ec.message());
    co_return false;
  }
  co_return true;
}

// Hello / HelloAck (PROTOCOL.md §5), then the key proofs; on success limits_ and the
// parser hold the negotiated limits. A server refusing for want of a key is final.
asio::awaitable<bool> Fetcher::handshake(net::Stream& sock) {
  proto::Hello hello = proto::make_hello(local_limits(options_), options_.client_name);
  if (!options_.key.empty()) hello.features |= proto::kFeatureAuth;
  std::vector<uint8_t> out;
  proto::Frame f;
  bool ok = bool(proto::encode_message(hello, next_id(), proto::kFlagFinal, limits_, out));
  if (ok) ok = co_await write(sock, out);
  if (ok) ok = co_await read_frame(sock, f);
  if (!ok) {
    const std::string bound = std::to_string(options_.connect_timeout.count()) + " ms (connect_timeout)";
    if (handshake_timed_out_)  // the watchdog closed it: the server was silent, not gone
      note_failure(session_rx_ == 0 ? "the server sent nothing within " + bound + " after the Hello"
                                    : "the server sent " + std::to_string(session_rx_) +
                                          " bytes but no whole HelloAck within " + bound);
    else if (parser_failed_)
      note_failure("the server's answer to the Hello is not a frame of this protocol (" + parser_error_ + ")");
    else
      note_failure(sock.tls() ? "the server closed the connection before its HelloAck"
                              : "the server closed the connection before its HelloAck (a TLS server? then "
                                "the client needs TLS too)");
    co_return false;
  }
  if (f.header.type == MessageType::error) {
    // A server that wants a key we do not have says so in the handshake: final.
    proto::ErrorMessage e;
    if (!proto::decode_payload(f.payload, limits_, e)) {
      note_failure("the server answered the Hello with an Error that does not decode");
      co_return false;
    }
    const std::string why = "server " + endpoint_name() +
                            " refused the connection: " + std::string(proto::to_string(e.code)) + ": " +
                            proto::sanitize_text(e.message, 512);
    note_failure(why);  // overloaded, shutting_down, timeout: retried, and named if it lasts
    if (e.code == ErrorCode::auth_required || e.code == ErrorCode::auth_failed) refuse(why);
    co_return false;
  }
  proto::HelloAck ack;
  proto::Limits negotiated;
  if (f.header.type != MessageType::hello_ack || !proto::decode_payload(f.payload, limits_, ack) ||
      !proto::check_hello_ack(hello, ack, negotiated)) {
    note_failure("the server answered the Hello with a " + std::string(proto::to_string(f.header.type)) +
                 " that is not a valid HelloAck for this client's Hello");
    co_return false;
  }
  limits_ = negotiated;
  parser_->set_limits(negotiated);
  const bool authenticated = co_await authenticate(sock, ack);
  co_return authenticated;
}

// The only writer on the socket: each round encodes what is due (control requests,
// Cancels, GetTiles batches) into one buffer and writes it, or sleeps until woken (a
// queued tile, an answer freeing an in-flight slot, an API call, the socket closing).
asio::awaitable<void> Fetcher::pump(net::Stream& sock) {
  std::vector<uint8_t> out;
  while (sock.is_open() && !stopping_io_) {
    out.clear();
    encode_controls(out);
    // Validated limits always encode; if one did not, reconnect rather than lose it.
    if (!encode_cancels(out) || !encode_tile_batches(out)) break;
    if (!out.empty()) {
      if (!co_await write(sock, out)) break;
      continue;
    }
    error_code ec;
    wake_timer_.expires_at(Clock::time_point::max());
    co_await wake_timer_.async_wait(asio::redirect_error(asio::use_awaitable, ec));
  }
}

bool Fetcher::in_flight_slot_free() const {
  return controls_sent_.size() + tile_requests_.size() < limits_.max_in_flight;
}

void Fetcher::encode_controls(std::vector<uint8_t>& out) {
  while (!controls_.empty() && in_flight_slot_free()) {
    auto c = controls_.front();
    controls_.pop_front();
    c->request_id = next_id();
    if (!proto::encode_message(c->request, c->request_id, proto::kFlagFinal, limits_, out)) {
      c->done(proto::ErrorMessage{ErrorCode::invalid_field, "request does not encode"});
      continue;
    }
    controls_sent_[c->request_id] = c;
  }
}

bool Fetcher::encode_cancels(std::vector<uint8_t>& out) {
  bool ok = true;
  std::vector<uint64_t> cancels;
  for (auto& s : maps_) {
    if (s.map_id == 0) continue;
    cancels.clear();
    s.map->take_cancels(cancels);
    for (size_t i = 0; i < cancels.size(); i += limits_.max_tiles_per_batch) {
      proto::Cancel cancel;
      cancel.map_id = s.map_id;
      cancel.tile_ids.assign(cancels.begin() + i,
                             cancels.begin() + std::min(cancels.size(), i + limits_.max_tiles_per_batch));
      ok &= bool(proto::encode_message(cancel, proto::kNoRequest, proto::kFlagFinal, limits_, out));
    }
  }
  return ok;
}

// Round-robin over the maps, one batch each, while in-flight slots remain.
bool Fetcher::encode_tile_batches(std::vector<uint8_t>& out) {
  bool ok = true, progress = true;
  const size_t batch = std::min<size_t>(options_.tiles_per_request, limits_.max_tiles_per_batch);
  while (progress && in_flight_slot_free()) {
    progress = false;
    for (auto& s : maps_) {
      if (s.map_id == 0 || !in_flight_slot_free()) continue;
      proto::GetTiles get;
      get.map_id = s.map_id;
      // The id is taken only if the map had tiles to send in it.
      const uint32_t id = upcoming_id();
      s.map->take_wanted(batch, id, get.tiles);
      if (get.tiles.empty()) continue;
      next_id();
      ok &= bool(proto::encode_message(get, id, proto::kFlagFinal, limits_, out));
      tile_requests_.emplace(id, GetTilesRequest{s.map.get(), s.map_id, uint32_t(get.tiles.size()), 0});
      progress = true;
    }
  }
  return ok;
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
    if (!f.header.final()) return;
    auto it = tile_requests_.find(id);
    if (it == tile_requests_.end()) return;
    if (it->second.answered < it->second.sent) it->second.map->request_ended(id);
    tile_requests_.erase(it);
    wake();
  };
  if (f.header.type == MessageType::tile_data || f.header.type == MessageType::tile_error) {
    auto it = tile_requests_.find(id);
    if (it == tile_requests_.end()) return protocol_error();
    if (f.header.type == MessageType::tile_data) {
      proto::TileMeta meta;
      std::span<const uint8_t> bytes;
      if (!proto::decode_tile_data_view(f.payload, meta, bytes) || meta.map_id != it->second.map_id)
        return protocol_error();
      it->second.answered += it->second.map->tile_arrived(meta, id, bytes);
    } else {
      proto::TileError te;
      if (!proto::decode_payload(f.payload, limits_, te) || te.map_id != it->second.map_id)
        return protocol_error();
      it->second.answered += it->second.map->tile_refused(te.tile_id, id, te.code);
    }
    return end_tile_request();
  }
  proto::Message m;
  if (proto::Status st = proto::decode_message(f, limits_, m); !st) {
    // The waiting call learns what was malformed, rather than waiting out its timeout
    // while the connection is dropped and its request re-sent to the same server.
    const std::string why = "the server's " + std::string(proto::to_string(f.header.type)) + " does not decode: " +
                            proto::to_string(st);
    note_failure(why);
    if (auto c = controls_sent_.find(id); c != controls_sent_.end()) {
      auto control = c->second;
      controls_sent_.erase(c);
      control->malformed = why;
      control->done(proto::ErrorMessage{ErrorCode::invalid_field, why});
    }
    return protocol_error();
  }
  if (f.header.type == MessageType::error && (id == proto::kNoRequest || tile_requests_.count(id))) {
    // The server gave up on the connection, or refused a tile batch as a whole
    // (overloaded, shutting down): reconnect, and re-request after the backoff.
    if (proto::ErrorMessage* e = std::get_if<proto::ErrorMessage>(&m); e && id == proto::kNoRequest)
      note_failure("the server closed the connection: " + std::string(proto::to_string(e->code)) + ": " +
                   proto::sanitize_text(e->message, 512));
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
    if (!connected_ && now - started > options_.connect_timeout) stuck = handshake_timed_out_ = true;  // connect + handshake
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

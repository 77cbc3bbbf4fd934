// The Fetcher's lifecycle and API side (fetcher.hpp): construction, start/stop, the
// calls API threads make (call, open) and map registration. The connection side is in
// fetcher_session.cpp.
#include "client/fetcher.hpp"

#include <unistd.h>

#include <boost/asio/posix/stream_descriptor.hpp>
#include <boost/asio/redirect_error.hpp>
#include <future>

#include "client/call_error.hpp"
#include "common/error.hpp"

namespace st::client {

using proto::ErrorCode;
using proto::MessageType;

namespace {
constexpr size_t kReadChunk = 64 * 1024;
}  // namespace

proto::Limits Fetcher::local_limits(const ClientOptions& o) {
  proto::Limits l;
  l.max_frame_bytes = o.max_frame_bytes;
  l.max_in_flight = o.max_in_flight;
  l.max_tiles_per_batch = std::max<uint16_t>(o.tiles_per_request, 1);
  return l;
}

Fetcher::Fetcher(std::vector<Endpoint> endpoints, size_t first, ClientOptions options)
    : endpoints_(std::move(endpoints)),
      current_(endpoints_.empty() ? 0 : first % endpoints_.size()),
      options_(std::move(options)),
      notifier_(std::make_shared<Notifier>()),
      pool_(options_.io_pool),
      own_io_(pool_ ? nullptr : std::make_unique<asio::io_context>()),
      io_(pool_ ? pool_->next() : *own_io_) {
  if (endpoints_.empty()) throw Error("client: no server endpoint given");
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

uint32_t Fetcher::upcoming_id() const {
  const uint32_t id = last_id_ + 1;
  return id == proto::kNoRequest ? id + 1 : id;
}

uint32_t Fetcher::next_id() { return last_id_ = upcoming_id(); }

ClientStats Fetcher::stats() const {
  std::lock_guard lock(stats_mu_);
  ClientStats s = stats_;
  s.connected = connected_.load();
  s.refused = refused_.load();
  return s;
}

// ---------------------------------------------------------------- API calls

proto::Message Fetcher::call(const proto::Message& request) {
  if (stopped_) throw CallError(CallFailure::stopped, "client: stopped");
  if (refused_) {
    std::lock_guard lock(stats_mu_);
    throw CallError(CallFailure::refused, "client: " + refusal_);
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
    {
      std::lock_guard lock(stats_mu_);
      if (!connected_) why = " (not connected" + (last_failure_.empty() ? std::string() : ": " + last_failure_) + ")";
      else if (!last_failure_.empty()) why = " (last failure: " + last_failure_ + ")";
    }
    throw CallError(CallFailure::timeout,
                    "client: no answer to " + std::string(proto::to_string(proto::type_of(request))) + " from " +
                        endpoint_name() + " within " + std::to_string(options_.request_timeout.count()) + " ms" +
                        why);
  }
  proto::Message m = future.get();
  if (!c->malformed.empty())  // set on the I/O thread before the answer: the future orders it
    throw Error("client: " + std::string(proto::to_string(proto::type_of(request))) + " to " + endpoint_name() +
                ": " + c->malformed);
  if (auto* e = std::get_if<proto::ErrorMessage>(&m))
    throw CallError(e->code == ErrorCode::auth_failed ? CallFailure::refused : CallFailure::server_error,
                    "client: server refused " + std::string(proto::to_string(proto::type_of(request))) + ": " +
                        std::string(proto::to_string(e->code)) + ": " + e->message,
                    e->code);
  return m;
}

std::shared_ptr<RemoteMap> Fetcher::open(const std::string& name) {
  if (proto::Status s = proto::validate_map_name(name); !s)
    throw CallError(CallFailure::bad_argument, "client: open('" + name + "'): " + proto::to_string(s));
  proto::Message m = call(proto::OpenMap{name});
  auto* info = std::get_if<proto::MapInfo>(&m);
  if (!info) throw CallError(CallFailure::unexpected_answer, "client: open('" + name + "'): unexpected answer");
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
    throw CallError(CallFailure::timeout, "client: open('" + name + "'): the fetcher thread did not answer");
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

}  // namespace st::client

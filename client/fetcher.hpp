// The client's network side (internal to client/): one thread running an io_context with
//   run()      - one session after another, with exponential backoff between them
//                (back to the initial delay after a successful handshake); with several
//                endpoints (replicas) each session after a failed or dropped one goes
//                to the next endpoint in turn;
//   session    - connect (TCP, TLS), handshake (Hello, key proofs), then the pump;
//   pump       - the session's only writer: control requests (OpenMap, ListMaps, GetStats),
//                Cancels, and GetTiles batches taken highest priority first from every
//                map while fewer than the negotiated max_in_flight are unanswered;
//   reader     - feeds the FrameParser; hands tiles to their RemoteMap, answers to the
//                waiting API call, frees in-flight slots on FINAL;
//   watchdog   - closes a connection that makes no progress (connect, write, or no
//                answer for io_timeout while answers are owed); run() then reconnects;
//   notifier   - reads the eventfd lookups poke when they queue a tile.
// Everything runs on that one thread, so the session state needs no locks; API calls
// reach it with asio::post. With ClientOptions::io_pool the io_context is one of the
// pool's (io_pool.hpp), still run by a single thread; then stop() cannot join a thread of
// its own, so every coroutine and posted handler is counted (live_) and stop() waits
// until the count drops to zero before the Fetcher may be destroyed.
#pragma once
#include "net/asio.hpp"

#include <boost/asio/posix/stream_descriptor.hpp>
#include <chrono>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <thread>
#include <unordered_map>
#include <vector>

#include "shadowtile/client.hpp"
#include "client/io_pool.hpp"
#include "net/stream.hpp"
#include "client/remote_map.hpp"
#include "proto/proto.hpp"

namespace st::client {

namespace asio = net::asio;  // net/asio.hpp
using net::error_code;
using net::tcp;

class Fetcher : public std::enable_shared_from_this<Fetcher> {
 public:
  // endpoints: one or more replicas serving the same packs; the first session goes to
  // endpoints[first % size].
  Fetcher(std::vector<Endpoint> endpoints, size_t first, ClientOptions options);
  ~Fetcher();
  void start();  // the thread (separate from the constructor: shared_from_this)
  void stop();

  // Sends `request` once connected and waits for its answer (request_timeout). Error
  // answers, timeouts and a stopped client throw st::Error.
  proto::Message call(const proto::Message& request);
  std::shared_ptr<RemoteMap> open(const std::string& name);

  ClientStats stats() const;
  bool connected() const { return connected_.load(); }

 private:
  using Clock = std::chrono::steady_clock;
  struct Control {
    proto::Message request;
    std::function<void(proto::Message&&)> done;  // runs on the I/O thread
    uint32_t request_id = 0;                     // 0: not sent on this connection
    std::string malformed;  // set (before done) when the answer did not decode: why
  };
  struct MapSlot {
    std::shared_ptr<RemoteMap> map;
    uint32_t map_id = 0;  // on the current connection; 0: (re)opening
  };
  // One GetTiles in flight: whose answers they are (the tiles' own request state lives
  // in the map's request table) and, by its count, an in-flight slot taken.
  struct GetTilesRequest {
    RemoteMap* map;
    uint32_t map_id;
    uint32_t sent = 0, answered = 0;  // tiles in it; answers naming one of them (fewer at FINAL: request_ended)
  };

  // What this client proposes in its Hello (and validates its options by).
  static proto::Limits local_limits(const ClientOptions& o);

  asio::awaitable<void> run();
  asio::awaitable<bool> session();  // true if the handshake succeeded
  asio::awaitable<bool> connect(net::Stream& sock);
  asio::awaitable<bool> handshake(net::Stream& sock);
  asio::awaitable<void> pump(net::Stream& sock);
  // The pump's parts: each appends frames to `out`; false if a frame did not encode.
  void encode_controls(std::vector<uint8_t>& out);
  bool encode_cancels(std::vector<uint8_t>& out);
  bool encode_tile_batches(std::vector<uint8_t>& out);
  bool in_flight_slot_free() const;
  asio::awaitable<void> reader(std::shared_ptr<net::Stream> sock);
  asio::awaitable<void> watchdog(std::shared_ptr<net::Stream> sock, uint64_t epoch);
  asio::awaitable<void> notifier_loop();
  asio::awaitable<bool> write(net::Stream& sock, const std::vector<uint8_t>& bytes);
  asio::awaitable<bool> read_frame(net::Stream& sock, proto::Frame& out);

  void handle(proto::Frame&& f);
  void answer_control(uint32_t request_id, proto::Message&& m);
  void reopen(MapSlot& slot);
  void end_session();
  // Final: authentication failed one way or the other (I/O thread).
  void refuse(const std::string& why);
  void note_failure(const std::string& why);
  // Answers every waiting API call (queued or sent) with `e` and forgets them (I/O thread).
  void fail_controls(const proto::ErrorMessage& e);  // why the last connect failed (for messages)
  asio::awaitable<bool> authenticate(net::Stream& sock, const proto::HelloAck& ack);
  void wake() { wake_timer_.cancel(); }
  uint32_t upcoming_id() const;  // what next_id() will return
  uint32_t next_id();
  // co_spawn / post on io_, counted in live_ (released when the coroutine or handler ends).
  void spawn(asio::awaitable<void> a);
  template <typename F>
  void post(F&& f);
  void hold();
  void release();

  // The endpoint the current (or next) session uses; changes only on the I/O thread.
  const Endpoint& endpoint() const { return endpoints_[current_.load() % endpoints_.size()]; }
  std::string endpoint_name() const { return endpoint().host + ":" + std::to_string(endpoint().port); }

  const std::vector<Endpoint> endpoints_;
  std::atomic<size_t> current_{0};
  const ClientOptions options_;
  std::shared_ptr<Notifier> notifier_;

  std::shared_ptr<IoPool> pool_;             // shared I/O threads, or null
  std::unique_ptr<asio::io_context> own_io_;  // without a pool: run by thread_
  asio::io_context& io_;
  asio::steady_timer wake_timer_{io_};
  asio::steady_timer backoff_timer_{io_};
  asio::posix::stream_descriptor notify_desc_{io_};
  std::thread thread_;

  // I/O-thread state.
  std::unique_ptr<asio::ssl::context> tls_;  // ClientOptions::tls (outlives the streams)
  std::shared_ptr<net::Stream> socket_;
  uint64_t epoch_ = 0;  // sessions so far
  proto::Limits limits_;
  std::unique_ptr<proto::FrameParser> parser_;
  std::vector<uint8_t> rx_;
  size_t rx_begin_ = 0, rx_end_ = 0;
  std::deque<std::shared_ptr<Control>> controls_;
  std::unordered_map<uint32_t, std::shared_ptr<Control>> controls_sent_;
  std::unordered_map<uint32_t, GetTilesRequest> tile_requests_;
  std::vector<MapSlot> maps_;
  uint32_t last_id_ = 0;
  bool writing_ = false, stopping_io_ = false;
  std::vector<asio::steady_timer*> watchdog_timers_;  // live watchdogs' ticks (stop() cancels them)
  Clock::time_point write_started_, last_rx_;
  uint64_t session_rx_ = 0;           // bytes read on this session (error messages)
  bool handshake_timed_out_ = false;  // the watchdog closed this session before its handshake ended
  bool parser_failed_ = false;        // this session's bytes broke the framing (parser_error_ says how)
  std::string parser_error_;

  std::atomic<bool> connected_{false}, stopped_{false}, refused_{false};
  std::string refusal_;       // why, once refused_ (guarded by stats_mu_)
  std::string last_failure_;  // guarded by stats_mu_
  std::mutex live_mu_;
  std::condition_variable live_cv_;
  uint64_t live_ = 0;  // coroutines and handlers not yet finished on io_
  mutable std::mutex stats_mu_;
  ClientStats stats_;
};

}  // namespace st::client

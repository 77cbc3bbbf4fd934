// One client connection (internal to server/; Asio http server's `connection`, with the
// cpp20 coroutine examples' shape):
//   reader   - reads, feeds the incremental FrameParser, handles each frame; it stops
//              reading while the control queue is full (backpressure, bounded memory);
//   writer   - the only coroutine that writes: drains the control queue first (handshake,
//              map info, errors, pongs, stats, cancelled-tile answers), then the tile
//              queue highest priority first, one gathered write per tile;
//   watchdog - enforces the handshake, idle, read (a frame must finish within the read
//              timeout of its first byte, however the bytes trickle in) and
//              write timeouts. The first three queue Error(timeout) with request id 0,
//              which the writer sends before closing (PROTOCOL.md §4.11); a write
//              timeout, or a TLS handshake still under way, closes the socket at once.
//              Closing the socket ends the other two coroutines.
// All three run on the connection's strand, so its state needs no locks.
//
// Limits per connection, so one slow or greedy client cannot starve the others: the
// negotiated max frame and max in flight (excess requests get too_many_in_flight), a
// tile queue bounded by max_in_flight x max_tiles_per_batch, a bounded control queue,
// and the timeouts.
#pragma once
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <vector>

#include "net/stream.hpp"
#include "proto/auth.hpp"
#include "proto/proto.hpp"
#include "net/asio.hpp"
#include "server/server_core.hpp"
#include "server/tile_queue.hpp"

namespace st::server {

class Connection : public std::enable_shared_from_this<Connection> {
 public:
  using Clock = std::chrono::steady_clock;
  // `from`: the client's address, counted in core.per_address until the end.
  Connection(tcp::socket socket, ServerCore& core, asio::ip::address from);
  // Spawns the coroutines. The connection removes itself from core.connections at the end.
  void start();
  // Closes the socket from any thread (posted to the strand).
  void stop();
  // Server shutdown, from any thread: Error(shutting_down) after the frame being
  // written (never mid-frame), then close; closed anyway after kShutdownGrace.
  void shut_down();
  static constexpr std::chrono::milliseconds kShutdownGrace{1000};
  // Under core.mu: the connection counts in core.pending until it leaves it (its first
  // real request after the handshake, or its end); mark_evicted: it was closed to make
  // room and no longer counts against max_connections (core.evicting instead).
  void enter_pending(std::list<PendingBudget::Entry>::iterator it) {
    pending_it_ = it;
    pending_ = true;
  }
  void mark_evicted() {
    pending_ = false;
    evicted_ = true;
  }
  // Under core.mu: a useful connection (counted in core.useful_per_prefix) not already
  // evicted, of network `prefix()`, idle since `last_read()` (Server::Impl::admit evicts
  // the longest idle of the network holding the most when the server is full).
  bool evictable_useful() const { return useful_counted_ && !evicted_; }
  const PendingBudget::Prefix& prefix() const { return prefix_; }
  Clock::time_point last_read() const {
    return Clock::time_point(Clock::duration(last_read_ticks_.load(std::memory_order_relaxed)));
  }

 private:

  asio::awaitable<void> reader(std::shared_ptr<Connection> self);
  asio::awaitable<void> writer(std::shared_ptr<Connection> self);
  asio::awaitable<void> watchdog(std::shared_ptr<Connection> self);

  void handle(proto::Frame&& frame);
  void on_hello(const proto::Frame& f, const proto::Hello& m);
  void on_open_map(uint32_t request_id, const proto::OpenMap& m);
  void on_get_tiles(uint32_t request_id, const proto::GetTiles& m);
  void on_cancel(const proto::Cancel& m);
  void on_get_stats(uint32_t request_id);
  void on_auth(uint32_t request_id, const proto::Auth& m);

  // Queues a whole frame answering `request_id` (FINAL); the request leaves in_flight_
  // once the frame is written.
  void answer(const proto::Message& m, uint32_t request_id);
  // `last`: a connection-level Error (request id 0): the writer closes once it is written,
  // sending nothing queued after it.
  void answer_error(uint32_t request_id, proto::ErrorCode code, const std::string& message,
                    bool last = false);
  // Admits a request into in_flight_ (PROTOCOL.md §6-7): false if refused (too many:
  // answered with Error; duplicate id: the connection fails).
  bool admit(uint32_t request_id);
  // Connection-level failure: Error with request id 0, then close once it is written.
  void fail(proto::ErrorCode code, const std::string& message);
  void close();
  // The first real request (not Hello, Auth, Ping): the connection leaves core.pending
  // and counts in core.useful_per_prefix; false (nothing changed) if its network is at
  // max_connections_per_prefix.
  bool leave_pending();
  void wake_writer();
  // What the parser accepts from the client after HelloAck: the handshake frame limit
  // until the client is authenticated, then the largest message a client may send.
  proto::Limits receive_limits() const;
  bool mid_frame() const { return parser_.stream_offset() > frame_end_offset_; }

  struct TileFrame {
    bool is_data = false;
    std::array<uint8_t, proto::kTileDataPrefixBytes> prefix{};
    // TileData: the stored bytes, shared with the server's payload cache (or this
    // frame's own, read past the cache); released once written.
    PayloadCache::Bytes stored;
    std::vector<uint8_t> error;   // TileError: the whole frame
    Clock::time_point received{};
  };
  static constexpr size_t kTilesPerWrite = 16;
  static constexpr size_t kBytesPerWrite = 256 * 1024;
  // Builds one tile's answer (TileData from the pack, or TileError).
  void prepare_tile(const PoppedTile& p, TileFrame& out);
  // The stored bytes of the tile at `pos` in the pack's tile index of catalog map
  // `map_index` (st::Error if they do not match the index).
  PayloadCache::Bytes load_stored(const CatalogMap& map, uint32_t map_index, const TileIndexEntry& entry,
                                  uint32_t pos);
  // Pops up to `max_tiles` tiles (and kBytesPerWrite) into batch_ and bufs_, in priority
  // order, ending the requests whose FINAL tile is among them; returns the count.
  size_t fill_batch(size_t max_tiles, size_t& bytes);
  // Counts the first n frames of batch_ as sent (tiles, latency) and lets go of their
  // payloads (an evicted cache entry is freed once no write references it).
  void count_batch(size_t n);
  // The reader's fast path (plain TCP, writer idle, only tiles owed): writes one batch
  // with a non-blocking gathered send right after the request that asked for it, instead
  // of waking the writer coroutine (two scheduler round trips and an extra epoll_wait
  // per unpipelined request). What the socket does not take goes to spill_, which the
  // writer sends before anything else. Returns false if it did not apply.
  bool write_tiles_inline();
  asio::awaitable<bool> write_buffers(const std::vector<asio::const_buffer>& bufs, size_t bytes,
                                      bool count = true);
  std::vector<TileFrame> batch_;  // kTilesPerWrite frames, reused: buffers keep their capacity
  std::vector<asio::const_buffer> bufs_;
  std::vector<uint8_t> spill_;  // the unsent tail of an inline write (bytes of frames begun)
  bool writer_idle_ = false;    // the writer waits on writer_wake_ (batch_ is free)
  bool in_chunk_ = false;       // the reader handles a chunk: wake_writer() only notes it
  bool wake_deferred_ = false;

  net::Stream stream_;  // plain TCP or TLS (core.tls)
  ServerCore& core_;
  const asio::ip::address from_;
  const ServerOptions& opt_;
  TileSource& source_;  // opt_.tile_source (the packs' unless the server was given one)
  asio::steady_timer writer_wake_, reader_wake_, watchdog_timer_;

  proto::Limits limits_;  // handshake limits until HelloAck, then the negotiated ones
  proto::FrameParser parser_;
  proto::InFlight in_flight_;
  TileQueue tiles_;
  struct ControlFrame {
    std::vector<uint8_t> bytes;
    uint32_t ends_request = 0;  // in_flight_ id released once written (0: none)
    bool last = false;          // a connection-level Error: close once written
    // Sent after `bytes`: immutable bytes shared with other answers (MapInfo's header
    // and skip grid, CatalogMap::map_info_tail), not counted as this connection's.
    std::shared_ptr<const std::vector<uint8_t>> shared;
  };
  // Queues a control frame, counting its own bytes in control_bytes_ and the server's
  // queued_bytes (the reader stops past either budget).
  void queue_control(ControlFrame f);
  // The reader may take more requests: room in the control queue (frames and bytes)
  // and in the server's budget of queued bytes.
  bool may_read() const;
  std::deque<ControlFrame> control_;
  size_t control_bytes_ = 0;
  std::vector<const CatalogMap*> open_maps_;  // map_id = index + 1
  std::vector<uint32_t> open_map_index_;      // ... and their catalog positions

  bool handshaken_ = false;
  bool tls_ready_ = false;  // plain TCP, or the TLS handshake is done: frames can be written
  bool tile_kind_ = false;  // kFeatureTileKind granted: TileData flags mark index tiles
  bool timed_out_ = false;  // Error(timeout) queued; the writer closes after it
  bool authed_ = false;  // no key configured, or the client proved it holds the key
  proto::Nonce server_nonce_{};
  bool closing_ = false;  // write what is queued, then close
  bool useful_ = false;   // left core.pending (strand-local copy of !pending_), counted in useful_per_prefix
  // Guarded by core.mu:
  std::list<PendingBudget::Entry>::iterator pending_it_{};
  bool pending_ = false, evicted_ = false;
  bool useful_counted_ = false;  // useful_, as core.mu sees it
  const PendingBudget::Prefix prefix_;
  // last_read_ for other threads (admit, under core.mu): steady-clock ticks.
  std::atomic<Clock::rep> last_read_ticks_{0};
  Clock::time_point shutdown_deadline_ = Clock::time_point::max();
  bool closed_ = false;
  bool writing_ = false;
  uint64_t frame_end_offset_ = 0;
  Clock::time_point accepted_, last_read_, last_activity_, write_started_;
  // When the frame being received began: a client dripping one byte a second keeps
  // last_read_ fresh but not this, so the read timeout still cuts it off.
  Clock::time_point frame_started_;
};

}  // namespace st::server

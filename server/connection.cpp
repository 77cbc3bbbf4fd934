#include "server/connection.hpp"

#include <algorithm>
#include <array>
#include <exception>

#include "common/error.hpp"
#include "proto/tile_prefix.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::server {

using proto::ErrorCode;
using proto::MessageType;

namespace {

// Requests are small frames (GetTiles of a few hundred bytes), so 16 KiB per read keeps
// the per-connection cost low (1,000 connections: scripts/soak) without more syscalls.
constexpr size_t kReadChunk = 16 * 1024;

// The tile's entry in a pack's tile index (sorted by id; PackReader::find's search, but
// giving the position, which addresses the payload cache); null if absent.
const TileIndexEntry* find_tile(const std::vector<TileIndexEntry>& index, uint64_t id) {
  auto it = std::lower_bound(index.begin(), index.end(), id,
                             [](const TileIndexEntry& e, uint64_t v) { return e.id < v; });
  return it == index.end() || it->id != id ? nullptr : &*it;
}

}  // namespace

Connection::Connection(tcp::socket socket, ServerCore& core, asio::ip::address from)
    : stream_(std::move(socket), core.tls.get()),
      core_(core),
      from_(std::move(from)),
      opt_(core.options),
      source_(*core.options.tile_source),
      writer_wake_(stream_.get_executor()),
      reader_wake_(stream_.get_executor()),
      watchdog_timer_(stream_.get_executor()),
      limits_(proto::handshake_limits(core.options.limits)),  // until HelloAck
      parser_(limits_, proto::Receiver::server),
      in_flight_(core.options.limits.max_in_flight),
      tiles_(size_t(core.options.limits.max_in_flight) * core.options.limits.max_tiles_per_batch),
      prefix_(PendingBudget::prefix_of(from_)) {
  accepted_ = last_read_ = last_activity_ = frame_started_ = Clock::now();
  last_read_ticks_.store(last_read_.time_since_epoch().count(), std::memory_order_relaxed);
  authed_ = core.options.key.empty();
  tls_ready_ = core.tls == nullptr;
  writer_wake_.expires_at(Clock::time_point::max());
  reader_wake_.expires_at(Clock::time_point::max());
  batch_.resize(kTilesPerWrite);
}

void Connection::start() {
  auto ex = stream_.get_executor();
  if (!stream_.tls()) {
    // Synchronous sends (write_tiles_inline) return would_block instead of blocking;
    // Asio's asynchronous operations are unaffected.
    error_code ec;
    stream_.socket().non_blocking(true, ec);
  }
  auto self = shared_from_this();
  asio::co_spawn(ex, reader(self), asio::detached);
  asio::co_spawn(ex, writer(self), asio::detached);
  asio::co_spawn(ex, watchdog(self), asio::detached);
}

void Connection::stop() {
  asio::post(stream_.get_executor(), [self = shared_from_this()] { self->close(); });
}

void Connection::shut_down() {
  asio::post(stream_.get_executor(), [self = shared_from_this()] {
    if (self->closed_) return;
    self->shutdown_deadline_ = Clock::now() + kShutdownGrace;
    if (!self->tls_ready_ || self->closing_) return self->close();  // no session to speak on
    self->fail(ErrorCode::shutting_down, "server shutting down");
  });
}

bool Connection::leave_pending() {
  if (useful_) return true;
  std::lock_guard lock(core_.mu);
  size_t& n = core_.useful_per_prefix[PendingBudget::prefix_of(from_)];
  if (opt_.max_connections_per_prefix && n >= opt_.max_connections_per_prefix) return false;
  ++n;
  useful_ = useful_counted_ = true;
  if (pending_) core_.pending.remove(pending_it_);
  pending_ = false;
  return true;
}

void Connection::close() {
  if (closed_) return;
  closed_ = true;
  stream_.close();
  writer_wake_.cancel();
  reader_wake_.cancel();
  watchdog_timer_.cancel();
}

void Connection::wake_writer() {
  if (in_chunk_) {
    wake_deferred_ = true;  // the reader wakes it (or writes inline) after the chunk
    return;
  }
  writer_wake_.cancel();
}

// ---------------------------------------------------------------- reader

asio::awaitable<void> Connection::reader(std::shared_ptr<Connection> /*keep alive*/) {
  std::vector<uint8_t> buf(kReadChunk);
  try {
    if (stream_.tls()) {  // bounded by the handshake timeout (watchdog)
      error_code ec;
      co_await stream_.handshake(asio::ssl::stream_base::server, ec);
      if (ec) {
        core_.stats.protocol_error();
        close();
      } else {
        tls_ready_ = true;
      }
    }
    while (!closed_ && !closing_) {
      // Backpressure: a client that sends requests faster than it reads answers stops
      // being read once its control queue is full (TCP then pushes back on it).
      while (!closed_ && !closing_ && !may_read()) {
        error_code ec;
        // Woken by the writer when its own queue drains; the server-wide budget drains
        // elsewhere, so that wait polls.
        reader_wake_.expires_at(control_.size() >= opt_.max_control_frames || control_bytes_ >= opt_.max_control_bytes
                                    ? Clock::time_point::max()
                                    : Clock::now() + std::chrono::milliseconds(5));
        co_await reader_wake_.async_wait(asio::redirect_error(asio::use_awaitable, ec));
      }
      if (closed_ || closing_) break;
      error_code ec;
      size_t n = co_await stream_.read_some(asio::buffer(buf), ec);
      if (ec) break;  // EOF, reset, or closed by the watchdog / stop()
      last_read_ = last_activity_ = Clock::now();
      last_read_ticks_.store(last_read_.time_since_epoch().count(), std::memory_order_relaxed);
      core_.stats.received(n);
      const uint64_t chunk_start = parser_.stream_offset();
      const bool was_mid_frame = mid_frame();
      std::span<const uint8_t> rest(buf.data(), n);
      in_chunk_ = true;
      wake_deferred_ = false;
      while (!rest.empty() && !closing_ && !closed_) {
        auto r = parser_.feed(rest);
        rest = rest.subspan(r.consumed);
        if (r.state == proto::FrameParser::State::frame) {
          frame_end_offset_ = parser_.stream_offset();
          handle(parser_.take_frame());
        } else if (r.state == proto::FrameParser::State::error) {
          core_.stats.protocol_error();
          fail(parser_.status().code, proto::to_string(parser_.status()));
        }
      }
      in_chunk_ = false;
      if (wake_deferred_) {
        write_tiles_inline();
        if (closing_ || closed_ || !spill_.empty() || !control_.empty() || !tiles_.empty()) writer_wake_.cancel();
      }
      // A frame that began in this chunk (none pending before it, or one completed in it
      // and the next begun) started now; one continued from before keeps its start.
      if (mid_frame() && (!was_mid_frame || frame_end_offset_ >= chunk_start)) frame_started_ = last_read_;
    }
  } catch (const std::exception& e) {
    core_.log_repeated("connection", std::string("connection reader: ") + e.what());
    close();
  }
  in_chunk_ = false;
  // A client that half-closes after its requests still gets its answers: only close
  // once the writer has nothing left (closing_ tells it to finish).
  closing_ = true;
  wake_writer();
}

void Connection::handle(proto::Frame&& frame) {
  const uint32_t id = frame.header.request_id;
  proto::Message msg;
  if (proto::Status s = proto::decode_message(frame, limits_, msg); !s) {
    // A payload that does not decode: the peer broke the protocol (PROTOCOL.md §3).
    core_.stats.protocol_error();
    return fail(s.code, proto::to_string(s));
  }
  if (!handshaken_) {
    if (auto* h = std::get_if<proto::Hello>(&msg)) return on_hello(frame, *h);
    core_.stats.protocol_error();
    return fail(ErrorCode::handshake_required,
                std::string("expected hello, got ") + std::string(proto::to_string(frame.header.type)));
  }
  switch (frame.header.type) {
    case MessageType::hello:
      core_.stats.protocol_error();
      return fail(ErrorCode::unexpected_type, "hello after the handshake");
    case MessageType::error:
      // The client gave up on the connection (PROTOCOL.md: the sender closes).
      return close();
    case MessageType::cancel:
      if (id != proto::kNoRequest) {  // PROTOCOL.md §4.10: it is no request, gets no answer
        core_.stats.protocol_error();
        return fail(ErrorCode::invalid_field,
                    "cancel sent with request id " + std::to_string(id) + "; it must carry request id 0");
      }
      return on_cancel(std::get<proto::Cancel>(msg));
    case MessageType::pong: return;  // answer to a ping we never send; harmless
    default: break;
  }
  if (!authed_ && frame.header.type != MessageType::auth) {
    // Nothing (not even whether a map exists) before the key is proven (PROTOCOL.md §11).
    core_.stats.auth_failure();
    return fail(ErrorCode::auth_required, "this server requires a key: send auth first");
  }
  // Everything else is a request: it holds an in-flight slot until its FINAL answer.
  core_.stats.request();
  if (frame.header.type != MessageType::ping && frame.header.type != MessageType::auth && !leave_pending()) {
    core_.stats.connection_rejected();
    return fail(ErrorCode::overloaded, "too many connections from your network");
  }
  if (!admit(id)) return;
  switch (frame.header.type) {
    case MessageType::list_maps: {
      proto::MapList list;
      for (const auto& m : core_.catalog.maps()) {
        if (list.maps.size() >= proto::kMaxMapsListed) break;
        list.maps.push_back(m->entry());
      }
      return answer(list, id);
    }
    case MessageType::open_map: return on_open_map(id, std::get<proto::OpenMap>(msg));
    case MessageType::get_tiles: return on_get_tiles(id, std::get<proto::GetTiles>(msg));
    case MessageType::ping: {
      proto::Pong pong;
      pong.echo_timestamp = std::get<proto::Ping>(msg).timestamp;
      pong.responder_timestamp = uint64_t(
          std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count());
      return answer(pong, id);
    }
    case MessageType::get_stats: return on_get_stats(id);
    case MessageType::auth: return on_auth(id, std::get<proto::Auth>(msg));
    default:
      return answer_error(id, ErrorCode::unexpected_type,
                          std::string(proto::to_string(frame.header.type)) + " is not a request");
  }
}

proto::Limits Connection::receive_limits() const {
  proto::Limits receive = limits_;
  receive.max_frame_bytes = authed_ ? proto::max_client_frame_bytes(limits_) : proto::kMinFrameBytes;
  return receive;
}

bool Connection::admit(uint32_t id) {
  proto::Status s = in_flight_.begin(id);
  if (s) return true;
  core_.stats.protocol_error();
  if (s.code == ErrorCode::too_many_in_flight) {
    // Refused as a whole; the id is not in the tracker, so nothing to release later.
    core_.stats.error();
    proto::ErrorMessage e{s.code, proto::to_string(s)};
    std::vector<uint8_t> out;
    if (proto::encode_message(e, id, proto::kFlagFinal, limits_, out)) queue_control({std::move(out), 0, false, {}});
    wake_writer();
    return false;
  }
  fail(s.code, proto::to_string(s));  // duplicate id or id 0: the client lost track
  return false;
}

void Connection::on_hello(const proto::Frame& f, const proto::Hello& m) {
  if (f.header.request_id == proto::kNoRequest) {  // PROTOCOL.md §5: a Hello is a request
    core_.stats.protocol_error();
    return fail(ErrorCode::invalid_field, "hello sent with request id 0; it needs a request id != 0");
  }
  proto::HelloAck ack;
  proto::Limits negotiated;
  // Without a key the nonce stays zero (unused); with one it is the fresh challenge.
  if (!opt_.key.empty()) server_nonce_ = proto::random_nonce();
  proto::Status s = proto::accept_hello(m, opt_.limits, server_nonce_, opt_.server_name, ack, negotiated);
  if (s && !opt_.key.empty()) {
    s = proto::require_auth(m, ack);
    if (!s) core_.stats.auth_failure();
  }
  if (!s) return fail(s.code, proto::to_string(s));
  // This server can mark index tiles in TileData flags: granted to a client that asks.
  ack.features |= m.features & proto::kFeatureTileKind;
  tile_kind_ = (ack.features & proto::kFeatureTileKind) != 0;
  std::vector<uint8_t> out;
  s = proto::encode_message(ack, f.header.request_id, proto::kFlagFinal, limits_, out);
  if (!s) return fail(ErrorCode::internal, proto::to_string(s));
  queue_control({std::move(out), 0, false, {}});
  limits_ = negotiated;
  // The negotiated max_frame_bytes exists for tiles (S->C); what the server buffers from
  // the client is bounded by the largest message a client may send (PROTOCOL.md §6), and
  // before the client proved it holds the key by the handshake frame limit (Auth is 64
  // bytes): a stranger cannot make the server buffer megabytes.
  parser_.set_limits(receive_limits());
  in_flight_.set_capacity(negotiated.max_in_flight);
  handshaken_ = true;
  wake_writer();
}

void Connection::on_auth(uint32_t id, const proto::Auth& m) {
  if (authed_) {
    core_.stats.protocol_error();
    return fail(ErrorCode::unexpected_type,
                opt_.key.empty() ? "this server takes no key" : "already authenticated");
  }
  const proto::Proof want = proto::client_proof(opt_.key, server_nonce_, m.client_nonce);
  if (!proto::proofs_equal(want, m.proof)) {
    core_.stats.auth_failure();
    core_.log_repeated("auth", "connection from " + from_.to_string() + " refused: wrong key");
    return fail(ErrorCode::auth_failed, "wrong key");
  }
  authed_ = true;
  parser_.set_limits(receive_limits());  // the post-handshake limit, from the next frame
  proto::AuthOk ok;
  ok.proof = proto::server_proof(opt_.key, server_nonce_, m.client_nonce);
  answer(ok, id);
}

void Connection::on_open_map(uint32_t id, const proto::OpenMap& m) {
  const size_t index = core_.catalog.index_of(m.name);
  if (index == Catalog::npos) return answer_error(id, ErrorCode::unknown_map, "no map named '" + m.name + "'");
  const CatalogMap* map = core_.catalog.maps()[index].get();
  auto it = std::find(open_maps_.begin(), open_maps_.end(), map);
  if (it == open_maps_.end()) {
    if (open_maps_.size() >= opt_.max_open_maps)
      return answer_error(id, ErrorCode::limit_exceeded,
                          "more than " + std::to_string(opt_.max_open_maps) + " open maps");
    open_maps_.push_back(map);
    open_map_index_.push_back(uint32_t(index));
    it = open_maps_.end() - 1;
  }
  // MapInfo (PROTOCOL.md §4.6) as a header and map id of its own followed by the
  // catalog's shared bytes: 64 pipelined OpenMaps of a big skip grid cost 64 x 28 bytes.
  const uint32_t map_id = uint32_t(it - open_maps_.begin()) + 1;
  const auto& tail = map->map_info_tail();
  std::array<uint8_t, 4> id_bytes{uint8_t(map_id), uint8_t(map_id >> 8), uint8_t(map_id >> 16),
                                  uint8_t(map_id >> 24)};
  const uint64_t payload = id_bytes.size() + tail->size();
  if (payload > limits_.max_payload_bytes())  // refused before any pass over the bytes
    return answer_error(id, ErrorCode::limit_exceeded,
                        "answer does not fit: map_info payload of " + std::to_string(payload) +
                            " bytes exceeds the limit " + std::to_string(limits_.max_payload_bytes()) +
                            " (propose a larger max_frame_bytes in the Hello)");
  proto::FrameHeader h;
  h.flags = proto::kFlagFinal;
  h.type = MessageType::map_info;
  h.request_id = id;
  h.payload_length = uint32_t(payload);
  h.payload_crc32 = map->map_info_crc(map_id);
  std::array<uint8_t, proto::kHeaderSize> header{};
  proto::write_header(h, header);
  ControlFrame f;
  f.bytes.assign(header.begin(), header.end());
  f.bytes.insert(f.bytes.end(), id_bytes.begin(), id_bytes.end());
  f.ends_request = id;
  f.shared = tail;
  queue_control(std::move(f));
  wake_writer();
}

void Connection::queue_control(ControlFrame f) {
  control_bytes_ += f.bytes.size();
  core_.queued_bytes.fetch_add(f.bytes.size(), std::memory_order_relaxed);
  control_.push_back(std::move(f));
}

bool Connection::may_read() const {
  return control_.size() < opt_.max_control_frames && control_bytes_ < opt_.max_control_bytes &&
         core_.queued_bytes.load(std::memory_order_relaxed) < opt_.max_queued_bytes;
}

void Connection::on_get_tiles(uint32_t id, const proto::GetTiles& m) {
  if (m.map_id == 0 || m.map_id > open_maps_.size())
    return answer_error(id, ErrorCode::unknown_map_id,
                        "map_id " + std::to_string(m.map_id) + " was not opened on this connection");
  const auto now = Clock::now();
  for (const auto& t : m.tiles) {
    PendingTile p;
    p.request_id = id;
    p.map_id = m.map_id;
    p.tile = t.tile_id;
    p.priority = t.priority;
    p.received = now;
    // Cannot fail: capacity is max_in_flight x max_tiles_per_batch and the decoder
    // capped the batch; checked anyway, since the bound is the whole point.
    if (!tiles_.push(p)) {
      tiles_.cancel_request(id);  // the ones queued still get their answer and FINAL
      break;
    }
  }
  wake_writer();
}

void Connection::on_cancel(const proto::Cancel& m) {
  size_t n = 0;
  for (uint32_t r : m.request_ids) n += tiles_.cancel_request(r);
  if (!m.tile_ids.empty()) n += tiles_.cancel_tiles(m.map_id, m.tile_ids);
  core_.stats.tiles_cancelled(n);
}

void Connection::on_get_stats(uint32_t id) {
  const StatsSnapshot snap = core_.stats.snapshot();
  proto::Stats st;
  for (auto& [name, value] : snap.named()) st.counters.push_back({name, value});
  proto::Histogram h;
  h.name = "latency_us";
  for (uint32_t b = 0; b < kLatencyBuckets; ++b)
    h.buckets.push_back({b == kLatencyBuckets - 1 ? ~uint64_t(0) : (uint64_t(1) << b) - 1,
                         snap.latency_us[b]});
  st.histograms.push_back(std::move(h));
  answer(st, id);
}

void Connection::answer(const proto::Message& m, uint32_t request_id) {
  std::vector<uint8_t> out;
  proto::Status s = proto::encode_message(m, request_id, proto::kFlagFinal, limits_, out);
  if (!s) return answer_error(request_id, s.code == ErrorCode::oversized_frame ? ErrorCode::limit_exceeded : s.code,
                              "answer does not fit: " + proto::to_string(s));
  queue_control({std::move(out), request_id, false, {}});
  wake_writer();
}

void Connection::answer_error(uint32_t request_id, ErrorCode code, const std::string& message,
                              bool last) {
  core_.stats.error();
  std::vector<uint8_t> out;
  proto::ErrorMessage e{code, proto::sanitize_text(message, proto::kMaxErrorMessageBytes)};
  if (proto::encode_message(e, request_id, proto::kFlagFinal, limits_, out))
    queue_control({std::move(out), request_id, last, {}});
  else if (last)
    queue_control({{}, 0, true, {}});  // cannot happen (bounded text); still close after
  wake_writer();
}

void Connection::fail(ErrorCode code, const std::string& message) {
  if (closing_) return;
  answer_error(proto::kNoRequest, code, message, true);
  closing_ = true;  // the writer sends what was queued before the Error, the Error, then closes
  wake_writer();
}

// ---------------------------------------------------------------- writer

asio::awaitable<bool> Connection::write_buffers(const std::vector<asio::const_buffer>& bufs,
                                                size_t bytes, bool count) {
  error_code ec;
  writing_ = true;
  write_started_ = Clock::now();
  co_await stream_.write(bufs, ec);
  writing_ = false;
  if (ec) co_return false;
  last_activity_ = Clock::now();
  if (count) core_.stats.sent(bytes);
  co_return true;
}

size_t Connection::fill_batch(size_t max_tiles, size_t& bytes) {
  size_t n = 0;
  bytes = 0;
  bufs_.clear();
  while (n < max_tiles && bytes < kBytesPerWrite) {
    auto p = tiles_.pop();
    if (!p) break;
    if (p->last_of_request) in_flight_.end(p->tile.request_id);
    TileFrame& f = batch_[n++];
    prepare_tile(*p, f);
    if (f.is_data) {
      bufs_.push_back(asio::buffer(f.prefix));
      bufs_.push_back(asio::buffer(*f.stored));
      bytes += f.prefix.size() + f.stored->size();
    } else {
      bufs_.push_back(asio::buffer(f.error));
      bytes += f.error.size();
    }
  }
  return n;
}

void Connection::count_batch(size_t n) {
  const auto now = Clock::now();
  for (size_t i = 0; i < n; ++i)
    if (batch_[i].is_data) {
      core_.stats.tile_sent(batch_[i].stored->size());
      core_.stats.latency(
          uint64_t(std::chrono::duration_cast<std::chrono::microseconds>(now - batch_[i].received).count()));
      batch_[i].stored.reset();
    }
}

bool Connection::write_tiles_inline() {
  if (stream_.tls() || closed_ || closing_ || !writer_idle_ || !spill_.empty() || !control_.empty() ||
      tiles_.empty())
    return false;
  const bool tight = core_.queued_bytes.load(std::memory_order_relaxed) >= opt_.max_queued_bytes;
  size_t bytes = 0;
  const size_t n = fill_batch(tight ? 1 : kTilesPerWrite, bytes);
  error_code ec;
  size_t done = 0;
  while (done < bytes) {  // a loopback socket usually takes the whole batch at once
    const size_t k = stream_.socket().write_some(bufs_, ec);
    if (ec) break;
    done += k;
    if (done < bytes) {  // drop what went out from the front of bufs_
      size_t skip = k;
      auto it = bufs_.begin();
      while (it != bufs_.end() && skip >= it->size()) skip -= it++->size();
      bufs_.erase(bufs_.begin(), it);
      if (!bufs_.empty()) bufs_.front() += skip;
    }
  }
  if (ec && ec != asio::error::would_block && ec != asio::error::try_again) {
    close();  // reset or broken pipe: the reader and writer end
    return true;
  }
  if (done < bytes) {
    // The socket's buffer is full: the rest of the frames begun goes first in the writer.
    for (const auto& b : bufs_) {
      const auto* p = static_cast<const uint8_t*>(b.data());
      spill_.insert(spill_.end(), p, p + b.size());
    }
    core_.queued_bytes.fetch_add(spill_.size(), std::memory_order_relaxed);
  }
  last_activity_ = Clock::now();
  core_.stats.sent(bytes);
  count_batch(n);
  return true;
}

// A tile's stored bytes: from the payload cache, or read from the tile source (the pack's:
// pread, then the pack index's CRC check, st::Error on a mismatch) and cached. A source
// that does not answer checked pack bytes is read every time and nothing is cached.
PayloadCache::Bytes Connection::load_stored(const CatalogMap& map, uint32_t map_index,
                                            const TileIndexEntry& entry, uint32_t pos) {
  if (!source_.answers_checked_pack_bytes())
    return std::make_shared<const std::vector<uint8_t>>(source_.read(map.pack(), entry.id));
  if (auto hit = core_.payloads.find(map_index, pos)) return hit;
  auto bytes = std::make_shared<const std::vector<uint8_t>>(source_.read(map.pack(), entry.id));
  core_.payloads.insert(map_index, pos, bytes);
  return bytes;
}

// One tile's answer frame, built in `out`: TileData as prefix (header + fixed fields)
// followed by the stored bytes as they lie in the pack, or a TileError frame.
void Connection::prepare_tile(const PoppedTile& p, TileFrame& out) {
  const uint8_t flags = p.last_of_request ? proto::kFlagFinal : 0;
  const CatalogMap* map = open_maps_[p.tile.map_id - 1];
  out.is_data = false;
  out.error.clear();
  ErrorCode code = ErrorCode::ok;
  std::string why;
  proto::TileMeta meta;
  if (p.tile.cancelled) {
    code = ErrorCode::cancelled;
    why = "cancelled";
  } else if (const TileIndexEntry* entry = find_tile(map->pack().tiles(), p.tile.tile); !entry) {
    code = ErrorCode::unknown_tile;
    why = "map '" + map->name() + "' has no tile " + std::to_string(p.tile.tile);
  } else {
    try {
      out.stored = load_stored(*map, open_map_index_[p.tile.map_id - 1], *entry,
                               uint32_t(entry - map->pack().tiles().data()));
      meta.tile_id = p.tile.tile;
      meta.map_id = p.tile.map_id;
      meta.flags = proto::kTileFlagZlib;
      if (tile_kind_ && entry->kind == TileKind::index) meta.flags |= proto::kTileFlagIndex;
      meta.uncompressed_size = entry->raw_size;
      meta.payload_crc32 = entry->crc;  // end to end: the client checks what the builder wrote
    } catch (const Error& e) {
      // Truncated or bit-flipped on disk since the server started: this tile fails alone
      // (the client answers from the coarser level); the rest are still served.
      code = ErrorCode::internal;
      why = std::string("corrupt tile: ") + e.what();
      core_.stats.tile_corrupt();
      core_.log_repeated("tile", std::string("tile read failed: ") + e.what());
    }
  }
  if (code == ErrorCode::ok) {
    // Bytes checked against the pack index's CRC (cache or read): the frame's payload
    // CRC is combined from it, not recomputed over the bytes; another source's bytes are
    // summed as they are.
    proto::Status s =
        source_.answers_checked_pack_bytes()
            ? proto::encode_tile_data_prefix(meta, uint32_t(out.stored->size()), meta.payload_crc32,
                                             p.tile.request_id, flags, limits_, out.prefix)
            : proto::encode_tile_data_prefix(meta, *out.stored, p.tile.request_id, flags, limits_, out.prefix);
    if (s) {
      out.is_data = true;
      out.received = p.tile.received;
      return;
    }
    code = s.code;
    why = proto::to_string(s);
  }
  out.stored.reset();
  if (code != ErrorCode::cancelled) core_.stats.error();
  proto::TileError te;
  te.tile_id = p.tile.tile;
  te.map_id = p.tile.map_id;
  te.code = code;
  te.message = proto::sanitize_text(why, proto::kMaxErrorMessageBytes);
  if (!proto::encode_message(te, p.tile.request_id, flags, limits_, out.error)) {
    // Cannot happen (the message is bounded); never leave a tile unanswered silently.
    te.message.clear();
    (void)proto::encode_message(te, p.tile.request_id, flags, limits_, out.error);
  }
}

asio::awaitable<void> Connection::writer(std::shared_ptr<Connection> self) {
  try {
    while (!closed_) {
      if (!spill_.empty()) {  // the tail of an inline write: frames already begun on the wire
        std::vector<uint8_t> tail = std::move(spill_);
        spill_.clear();
        std::vector<asio::const_buffer> tail_buf;
        tail_buf.push_back(asio::buffer(tail));
        const bool ok = co_await write_buffers(tail_buf, tail.size(), false);
        core_.queued_bytes.fetch_sub(tail.size(), std::memory_order_relaxed);
        if (!ok) break;
        continue;
      }
      if (!control_.empty()) {
        ControlFrame frame = std::move(control_.front());
        control_.pop_front();
        std::vector<asio::const_buffer> bufs{asio::buffer(frame.bytes)};
        size_t bytes = frame.bytes.size();
        if (frame.shared) {
          bufs.push_back(asio::buffer(*frame.shared));
          bytes += frame.shared->size();
        }
        const bool ok = co_await write_buffers(bufs, bytes);
        control_bytes_ -= frame.bytes.size();  // held until written: it is memory until then
        core_.queued_bytes.fetch_sub(frame.bytes.size(), std::memory_order_relaxed);
        reader_wake_.cancel();  // room in the control queue again
        if (!ok) break;
        if (frame.ends_request) in_flight_.end(frame.ends_request);  // FINAL written
        if (frame.last) break;  // a connection-level Error is the last frame (PROTOCOL.md §4.3)
        continue;
      }
      if (!tiles_.empty()) {
        // Several small tiles per gathered write (one syscall, not one per tile), still in
        // priority order; bounded in count and bytes so urgent later requests wait little.
        // Over the server's budget of queued bytes: one tile per write until it drains.
        const bool tight = core_.queued_bytes.load(std::memory_order_relaxed) >= opt_.max_queued_bytes;
        size_t bytes = 0;
        const size_t n = fill_batch(tight ? 1 : kTilesPerWrite, bytes);
        struct Held {  // the batch counts against the server's budget until written
          std::atomic<uint64_t>& total;
          size_t n;
          Held(std::atomic<uint64_t>& t, size_t b) : total(t), n(b) { total.fetch_add(n, std::memory_order_relaxed); }
          ~Held() { total.fetch_sub(n, std::memory_order_relaxed); }
        };
        bool ok;
        {
          Held held(core_.queued_bytes, bytes);
          ok = co_await write_buffers(bufs_, bytes);
        }
        if (!ok) break;
        count_batch(n);
        continue;
      }
      if (closing_) break;  // everything owed is written
      error_code ec;
      writer_wake_.expires_at(Clock::time_point::max());
      writer_idle_ = true;
      co_await writer_wake_.async_wait(asio::redirect_error(asio::use_awaitable, ec));
      writer_idle_ = false;
    }
  } catch (const std::exception& e) {
    core_.log_repeated("connection", std::string("connection writer: ") + e.what());
  }
  close();
  writer_idle_ = false;
  core_.queued_bytes.fetch_sub(control_bytes_ + spill_.size(), std::memory_order_relaxed);  // never written
  spill_.clear();
  control_bytes_ = 0;
  control_.clear();
  {
    std::lock_guard lock(core_.mu);
    if (pending_) core_.pending.remove(pending_it_);
    pending_ = false;
    if (evicted_) --core_.evicting;
    core_.connections.erase(self);
    if (auto it = core_.per_address.find(from_); it != core_.per_address.end() && --it->second == 0)
      core_.per_address.erase(it);
    if (useful_)
      if (auto it = core_.useful_per_prefix.find(PendingBudget::prefix_of(from_));
          it != core_.useful_per_prefix.end() && --it->second == 0)
        core_.useful_per_prefix.erase(it);
  }
  core_.stats.connection_closed();
}

// ---------------------------------------------------------------- watchdog

asio::awaitable<void> Connection::watchdog(std::shared_ptr<Connection> /*keep alive*/) {
  using std::chrono::milliseconds;
  const auto shortest = std::min({opt_.handshake_timeout, opt_.idle_timeout, opt_.read_timeout,
                                  opt_.write_timeout});
  const auto tick = std::clamp<milliseconds>(shortest / 8, milliseconds(2), milliseconds(250));
  while (!closed_) {
    error_code ec;
    watchdog_timer_.expires_after(tick);
    co_await watchdog_timer_.async_wait(asio::redirect_error(asio::use_awaitable, ec));
    if (closed_) break;
    const auto now = Clock::now();
    if (now >= shutdown_deadline_) {  // shutting down, and the client does not read
      close();
      break;
    }
    if (timed_out_) {
      // Error(timeout) is queued: the writer sends it and closes; only a stuck write
      // still needs cutting off.
      if (writing_ && now - write_started_ > opt_.write_timeout) close();
      continue;
    }
    const bool owed = !control_.empty() || !tiles_.empty() || !spill_.empty();
    const char* why = nullptr;
    if ((!handshaken_ || !authed_) && now - accepted_ > opt_.handshake_timeout) why = "handshake";
    else if (writing_ && now - write_started_ > opt_.write_timeout) why = "write";
    else if (mid_frame() && now - frame_started_ > opt_.read_timeout) why = "read";
    else if (!owed && !writing_ && now - last_activity_ > opt_.idle_timeout) why = "idle";
    if (why) {
      const std::string what(why);
      if (what != "idle") core_.stats.timeout();
      if (what == "write" || closing_ || !tls_ready_) {
        close();  // no way (or no point) to write an Error first
      } else {
        // PROTOCOL.md §4.11: the client learns why the connection ends.
        timed_out_ = true;
        const auto limit = what == "handshake" ? opt_.handshake_timeout
                           : what == "read"    ? opt_.read_timeout
                                               : opt_.idle_timeout;
        fail(ErrorCode::timeout, what + " timeout (" + std::to_string(limit.count()) + " ms)");
      }
    }
  }
}

}  // namespace st::server

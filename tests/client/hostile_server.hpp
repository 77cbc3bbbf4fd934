// A hostile (or just unusual) server for client tests: plain blocking sockets on
// 127.0.0.1, the real protocol codec, and a script of lies (a MapInfo it is given, however
// wrong; tiles refused, answered under wrong ids, or never answered; a silent handshake).
// One thread accepts; each connection gets a thread. Every wait polls a stop flag every
// 20 ms, so the destructor ends it all within a fraction of a second; it ends only the
// threads and sockets it made.
#pragma once
#include <poll.h>
#include <sys/socket.h>
#include <netinet/in.h>
#include <arpa/inet.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "proto/proto.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st::looptest {

class HostileServer {
 public:
  enum class Tiles {
    honest,        // each tile's bytes from `pack`, as the real server sends them
    unknown_tile,  // every tile refused with TileError(unknown_tile)
    wrong_id,      // every tile answered with the bytes of another tile, under that other id
    none,          // GetTiles never answered at all
  };
  struct Script {
    bool silent_hello = false;          // read the Hello, never answer it
    std::vector<uint8_t> header, grid;  // the MapInfo's pack header and grid section, sent as given
    bool trailing_byte = false;         // the MapInfo payload one byte too long (does not decode)
    Tiles tiles = Tiles::honest;
    std::shared_ptr<const PackReader> pack;  // tile bytes (honest, wrong_id)
  };

  explicit HostileServer(Script s) : script_(std::move(s)) {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const int one = 1;
    ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(listen_fd_, 64) != 0)
      throw std::runtime_error("hostile server: cannot listen on 127.0.0.1");
    socklen_t n = sizeof a;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &n);
    port_ = ntohs(a.sin_port);
    acceptor_ = std::thread([this] { accept_loop(); });
  }
  ~HostileServer() {
    stop_ = true;
    acceptor_.join();
    for (std::thread& t : connections_) t.join();
    ::close(listen_fd_);
  }
  HostileServer(const HostileServer&) = delete;
  HostileServer& operator=(const HostileServer&) = delete;

  uint16_t port() const { return port_; }
  uint64_t tiles_asked() const { return asked_.load(); }
  uint64_t get_tiles_requests() const { return requests_.load(); }
  // The most times one tile id was asked for.
  uint64_t most_asks_of_one_tile() const {
    std::lock_guard lock(mu_);
    uint64_t m = 0;
    for (const auto& [id, n] : per_tile_) m = std::max(m, n);
    return m;
  }

 private:
  void accept_loop() {
    while (!stop_) {
      pollfd p{listen_fd_, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) continue;
      if (connections_.size() >= 256) {  // bounded: a test never needs more
        ::close(fd);
        continue;
      }
      connections_.emplace_back([this, fd] {
        serve(fd);
        ::close(fd);
      });
    }
  }

  bool send_all(int fd, const std::vector<uint8_t>& b) {
    size_t done = 0;
    while (done < b.size() && !stop_) {
      pollfd p{fd, POLLOUT, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      const ssize_t n = ::send(fd, b.data() + done, b.size() - done, MSG_NOSIGNAL);
      if (n <= 0) return false;
      done += size_t(n);
    }
    return done == b.size();
  }

  void serve(int fd) {
    proto::Limits local;
    local.max_frame_bytes = 64u << 20;
    local.max_tiles_per_batch = 4096;
    local.max_in_flight = 4096;
    proto::Limits limits = proto::handshake_limits(local);
    proto::FrameParser parser(limits, proto::Receiver::server);
    std::vector<uint8_t> buf(64 * 1024);
    while (!stop_) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      const ssize_t n = ::recv(fd, buf.data(), buf.size(), 0);
      if (n <= 0) return;
      std::span<const uint8_t> in(buf.data(), size_t(n));
      while (!in.empty()) {
        const auto r = parser.feed(in);
        in = in.subspan(r.consumed);
        if (r.state == proto::FrameParser::State::error) return;
        if (r.state != proto::FrameParser::State::frame) continue;
        proto::Frame f = parser.take_frame();
        proto::Message m;
        if (!proto::decode_message(f, limits, m)) return;
        std::vector<uint8_t> out;
        const uint32_t id = f.header.request_id;
        if (auto* hello = std::get_if<proto::Hello>(&m)) {
          if (script_.silent_hello) continue;
          proto::HelloAck ack;
          proto::Limits negotiated;
          if (!proto::accept_hello(*hello, local, {}, "hostile", ack, negotiated)) return;
          proto::encode_message(ack, id, proto::kFlagFinal, limits, out);
          limits = negotiated;
          parser.set_limits(negotiated);
        } else if (std::get_if<proto::OpenMap>(&m)) {
          proto::MapInfo info;
          info.pack_header = script_.header;
          info.skip_grid = script_.grid;
          std::vector<uint8_t> payload;
          proto::encode_payload(info, limits, payload);
          if (script_.trailing_byte) payload.push_back(0);
          proto::append_frame(proto::MessageType::map_info, proto::kFlagFinal, id, payload, limits, out);
        } else if (auto* get = std::get_if<proto::GetTiles>(&m)) {
          ++requests_;
          if (script_.tiles == Tiles::none) continue;
          answer_tiles(*get, id, limits, out);
        } else if (std::get_if<proto::Cancel>(&m)) {
          continue;
        } else {
          proto::encode_message(proto::make_error(proto::ErrorCode::invalid_field, "not scripted"), id,
                                proto::kFlagFinal, limits, out);
        }
        if (!out.empty() && !send_all(fd, out)) return;
      }
    }
  }

  void answer_tiles(const proto::GetTiles& get, uint32_t id, const proto::Limits& limits, std::vector<uint8_t>& out) {
    const auto& all = script_.pack ? script_.pack->tiles() : std::vector<TileIndexEntry>{};
    for (size_t i = 0; i < get.tiles.size(); ++i) {
      const uint64_t tile = get.tiles[i].tile_id;
      ++asked_;
      {
        std::lock_guard lock(mu_);
        ++per_tile_[tile];
      }
      const uint8_t flags = i + 1 == get.tiles.size() ? proto::kFlagFinal : 0;
      uint64_t send_id = tile;
      if (script_.tiles == Tiles::wrong_id && !all.empty()) {  // a tile of the index this request did not name
        auto named = [&](uint64_t t) {
          for (const proto::TileRequest& r : get.tiles)
            if (r.tile_id == t) return true;
          return false;
        };
        size_t k = 0;
        while (k < all.size() && all[k].id != tile) ++k;
        for (size_t step = 1; step <= all.size(); ++step) {
          send_id = all[(k + step) % all.size()].id;
          if (!named(send_id)) break;
        }
        if (named(send_id)) send_id = tile ^ 1;
      }
      std::optional<TileIndexEntry> e;
      if (script_.tiles != Tiles::unknown_tile && script_.pack) e = script_.pack->find(send_id);
      if (!e) {
        proto::TileError te;
        te.tile_id = tile;
        te.map_id = get.map_id;
        te.code = proto::ErrorCode::unknown_tile;
        te.message = "no such tile (scripted)";
        proto::encode_message(te, id, flags, limits, out);
        continue;
      }
      proto::TileData td;
      td.meta.tile_id = send_id;
      td.meta.map_id = get.map_id;
      td.meta.uncompressed_size = e->raw_size;
      td.meta.payload_crc32 = e->crc;
      td.payload = script_.pack->read_stored(send_id);
      proto::encode_message(td, id, flags, limits, out);
    }
  }

  Script script_;
  int listen_fd_ = -1;
  uint16_t port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread acceptor_;
  std::vector<std::thread> connections_;  // touched by the acceptor only, joined after it
  std::atomic<uint64_t> asked_{0}, requests_{0};
  mutable std::mutex mu_;
  std::map<uint64_t, uint64_t> per_tile_;
};

}  // namespace st::looptest

// Helpers of the loopback tests: small packs built from random interval fields, an
// in-process server on 127.0.0.1:0, bounded waits, and a raw blocking socket for
// sending hostile bytes. Every wait is bounded so a broken build fails, never hangs.
#pragma once
#include <chrono>
#include <cstdint>
#include <functional>
#include <span>
#include <memory>
#include <string>
#include <vector>

#include "client/map_access.hpp"
#include "proto/proto.hpp"
#include "server/server.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st::looptest {

bool small_scale();  // SHADOWTILE_TEST_SCALE=small (the asan preset)

// The packs' own tile source, with each tile's stored bytes handed to `see` (which may
// wait, record or alter them) before they are sent: a slow, watched or corrupting disk
// (ServerOptions::tile_source). The server sums such bytes and caches none.
class WatchedTiles final : public server::TileSource {
 public:
  using See = std::function<void(uint64_t tile_id, std::span<uint8_t> bytes)>;
  explicit WatchedTiles(See see) : see_(std::move(see)) {}
  std::vector<uint8_t> read(const PackReader& pack, uint64_t tile_id) override {
    std::vector<uint8_t> bytes = pack_.read(pack, tile_id);
    see_(tile_id, bytes);
    return bytes;
  }

 private:
  server::PackTileSource pack_;
  See see_;
};

// A random field of 2^level texels a side: constant blocks (no tiles below them), noisy
// blocks (big tiles, index tiles when tile_bytes is small), smooth slopes, lit border.
IntervalTile random_field(uint32_t level, uint64_t seed);

struct TestPack {
  std::string path;
  std::shared_ptr<PackReader> reader;
  Hierarchy hierarchy;
};
// Builds "<tmp>/<name>.pack" from random_field(level, seed).
TestPack build_pack(const std::string& name, uint32_t level, uint64_t seed, Encoding e, uint32_t skip,
                    uint32_t tile_bytes);
std::vector<Encoding> available_encodings();  // packtest::available_encodings
Encoding first_encoding();                     // the first of them (ST_CHECK: there is one)

// Client options for loopback tests: quick reconnects (5 ms doubling to 100 ms) and a
// generous request timeout, so a slow sanitizer build fails on answers, never on time.
client::ClientOptions quick_options();

struct TestServer {
  std::unique_ptr<server::Server> server;
  uint16_t port = 0;
  void stop() { if (server) server->stop(); }
};
TestServer start_server(const std::vector<std::string>& paths, server::ServerOptions o = {});

// Polls `pred` every millisecond until true or `timeout`; returns its last value.
bool wait_until(const std::function<bool()>& pred, std::chrono::milliseconds timeout = std::chrono::seconds(20));

// A blocking TCP connection with receive/send timeouts (SO_RCVTIMEO/SO_SNDTIMEO).
class RawSocket {
 public:
  // `source`: the local IPv4 address to connect from (any of 127.0.0.0/8 works on
  // loopback), so a test can play clients at different addresses.
  RawSocket(uint16_t port, std::chrono::milliseconds timeout = std::chrono::seconds(5),
            const char* source = nullptr);
  ~RawSocket();
  RawSocket(const RawSocket&) = delete;
  RawSocket& operator=(const RawSocket&) = delete;
  bool send(const std::vector<uint8_t>& bytes);
  // SO_RCVBUF: a fixed, small receive buffer (no autotuning), so that a test can fill
  // the connection with little data.
  void set_receive_buffer(int bytes);
  // Reads until `n` bytes or EOF/timeout; returns what it got.
  std::vector<uint8_t> recv(size_t n);
  // True if the peer closed (EOF or reset) within the timeout.
  bool wait_closed();
  void close();

 private:
  int fd_ = -1;
};

// One frame (header + payload) read from a raw socket; ok false if none came whole.
struct RawFrame {
  proto::FrameHeader header;
  std::vector<uint8_t> payload;
  bool ok = false;
};
RawFrame read_frame(RawSocket& s);
proto::ErrorCode error_code_of(const RawFrame& f);  // ok if the payload is no Error

// Frames for raw tests (version 1, handshake limits).
std::vector<uint8_t> hello_frame(uint32_t request_id = 1);
std::vector<uint8_t> open_map_frame(const std::string& name, uint32_t request_id);

}  // namespace st::looptest

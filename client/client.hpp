// shadowtile client library: stream a remote shadow map's tiles into a fixed-size tile
// cache and answer shadow lookups from it without ever stalling (DESIGN.md "What it is").
//
//   st::client::Client client({"127.0.0.1", 7447});
//   st::client::Map map = client.open("city");          // header + skip grid
//   map.request_region(level, x0, y0, w, h, priority);   // prefetch what cameras see
//   float lit = map.visibility(world_point, pcf_radius); // 0..1, never blocks
//   float d = map.depth(level, x, y);
//   st::client::MapStats s = map.stats();
//
// How it works: a fetcher thread (or, with ClientOptions::io_pool, one of a few threads
// shared by many Clients: io_pool.hpp) owns the TCP connection (connect with retry and
// exponential backoff, handshake, reconnect on failure); it keeps up to the negotiated
// number of GetTiles requests in flight, highest priority first, cancels requests no
// longer wanted, checks every tile's end-to-end CRC-32 against the pack index (refetch on
// mismatch), decompresses into a slot of the tile cache (tile_cache.hpp) and opens it.
// Lookups walk skip grid -> index tiles -> tile in the cache; where a tile is not
// resident they answer with the value of the deepest node they reached (every level of
// the hierarchy is a complete shadow map, DESIGN.md "Multiresolution") and queue the
// tile's fetch.
//
// Error model (exceptions never cross this boundary unexpectedly):
//   - Client's constructor throws st::Error only for bad options; it never waits for or
//     fails on the network (it connects in the background and keeps retrying).
//   - open(), list_maps(), server_stats() throw st::Error with a one-line message on an
//     unknown map, a malformed answer, or no answer within ClientOptions::request_timeout.
//   - Map lookups (depth, pcf, lit, visibility) and request_region/cancel_outside/stats
//     are noexcept: they never block on the network, never allocate, never throw. A tile
//     that cannot be had (corrupt after retries, unknown to the server) keeps answering
//     from the coarser level and is counted in MapStats.
// Thread safety: every method of Client and Map may be called from any thread. A Map
// stays valid (answering from its cache) after its Client is destroyed.
#pragma once
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/tile_cache.hpp"
#include "proto/messages.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/tile_cut_grid.hpp"
#include "tiles/core/vec.hpp"

namespace st::client {

struct Endpoint {
  std::string host = "127.0.0.1";
  uint16_t port = 7447;
};

class IoPool;  // io_pool.hpp

struct ClientOptions {
  uint32_t cache_slots = 256;               // tile cache slots per map
  uint32_t max_slot_bytes = 16u << 20;      // refuse maps whose tile bound exceeds this
  uint32_t want_capacity = 8192;            // queued (not yet sent) tile requests per map
  uint16_t max_in_flight = 64;              // GetTiles requests proposed in the Hello
  uint16_t tiles_per_request = 8;           // tiles per GetTiles (small: priorities stay fresh)
  uint32_t max_frame_bytes = 4u << 20;      // proposed in the Hello
  uint32_t max_tile_retries = 3;            // CRC or decode failures before giving up a tile
  uint16_t miss_priority = 1;               // priority of fetches queued by lookups
  std::chrono::milliseconds connect_timeout{2000};
  std::chrono::milliseconds io_timeout{10000};   // no progress with answers owed: reconnect
  std::chrono::milliseconds request_timeout{10000};  // open(), list_maps(), server_stats()
  std::chrono::milliseconds backoff_initial{20};
  std::chrono::milliseconds backoff_max{2000};
  std::string client_name = "shadowtile-client";
  // The catalog's key (proto/auth.hpp; proto::load_key_file reads one). When set, the
  // client proves it to the server and requires the server's proof back: a server that
  // does not ask for the key, or proves a different one, is refused. A refusal either way
  // is final: the client stops reconnecting and open()/list_maps()/server_stats() throw
  // st::Error saying why; maps already open keep answering from their caches.
  std::vector<uint8_t> key;
  // TLS (server started with --tls-cert/--tls-key): the server's certificate must chain to
  // tls_ca_file (PEM; empty: the system's trust store) and name tls_server_name (empty:
  // the endpoint's host) in its subjectAltName. A failed handshake is retried like a
  // failed connect; its reason appears in the timeout errors of open() and friends.
  bool tls = false;
  std::string tls_ca_file, tls_server_name;
  // Opens one encoded tile (the bytes stay in their cache slot while the evaluator
  // lives). Empty: st::open_encoded(the pack's encoding).
  std::function<std::unique_ptr<Evaluator>(std::span<const uint8_t>)> open_tile;
  // Shared I/O threads (io_pool.hpp) for processes with many connections; null: this
  // Client's fetcher runs on a thread of its own.
  std::shared_ptr<IoPool> io_pool;
};

struct MapStats {
  CacheStats cache;                  // hits, misses, evictions, inserts, slots in use
  uint64_t tiles_requested = 0;      // tile fetches sent
  uint64_t tiles_received = 0;       // tiles made resident
  uint64_t bytes_received = 0;       // stored (compressed) tile bytes received
  uint64_t crc_errors = 0;           // end-to-end CRC mismatches (each refetched)
  uint64_t decode_errors = 0;        // zlib or tile format failures
  uint64_t tiles_failed = 0;         // given up (retries exhausted or refused by the server)
  uint64_t tiles_cancelled = 0;
  uint64_t cache_full = 0;           // a tile arrived while every slot was pinned
  uint64_t queue_full = 0;           // a wanted tile could not be queued (want_capacity)
  uint64_t coarse_answers = 0;       // lookups answered above the level asked for
};

struct ClientStats {
  uint64_t connects = 0, connect_failures = 0, disconnects = 0;
  uint64_t frames_received = 0, bytes_received = 0, bytes_sent = 0;
  uint64_t protocol_errors = 0;
  bool connected = false;
  bool refused = false;  // authentication failed (see ClientOptions::key); final
};

class RemoteMap;
class Fetcher;

// A handle to an opened map (cheap to copy; all copies share one cache).
class Map {
 public:
  Map() = default;
  bool valid() const noexcept { return bool(map_); }
  const std::string& name() const noexcept;
  const PackHeader& header() const noexcept;
  const CutGrid& skip_grid() const noexcept;
  uint32_t finest_level() const noexcept;

  // The evaluator over the cache (st::Evaluator: depth / pcf / lit / pcf_footprint).
  const Evaluator& evaluator() const noexcept;
  float depth(uint32_t level, uint64_t x, uint64_t y) const noexcept;
  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const noexcept;
  bool lit(uint64_t x, uint64_t y, float receiver_depth) const noexcept;
  // Fraction lit (0..1) of a world point: light space from the pack header, PCF over a
  // (2 * pcf_radius + 1)^2 kernel at the finest level (pcf_radius <= 4). Points outside
  // the light's box are lit (1).
  float visibility(const Vec3d& world, uint32_t pcf_radius = 0) const noexcept;

  // Queues the fetch of every tile under texels [x0, x0+w) x [y0, y0+h) of `level`
  // (clamped to the map), walking index tiles as they arrive. Larger priority = sooner.
  // Returns the number of tiles newly queued.
  size_t request_region(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h,
                        uint16_t priority) noexcept;
  // Cancels queued and in-flight fetches of tiles outside the region.
  size_t cancel_outside(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) noexcept;
  // True when every tile under the region is resident (lookups there are exact).
  bool region_resident(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) const noexcept;

  MapStats stats() const noexcept;
  // The cache's pool (what a renderer uploads): slot i at i * slot_bytes().
  uint32_t slot_bytes() const noexcept;

 private:
  friend class Client;
  explicit Map(std::shared_ptr<RemoteMap> m) : map_(std::move(m)) {}
  std::shared_ptr<RemoteMap> map_;
};

class Client {
 public:
  explicit Client(Endpoint endpoint, ClientOptions options = {});
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Opens a map by name (waits for the connection up to request_timeout). st::Error.
  Map open(const std::string& name);
  std::vector<proto::MapEntry> list_maps();
  proto::Stats server_stats();

  bool connected() const noexcept;
  ClientStats stats() const noexcept;

 private:
  std::shared_ptr<Fetcher> fetcher_;
};

}  // namespace st::client

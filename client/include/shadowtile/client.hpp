// shadowtile client library: the whole public API, in one header that includes only the
// C++ standard library. A game links shadowtile::client and includes this file; nothing
// of the wire protocol, the pack format, Asio, Embree, assimp or OpenEXR comes with it.
//
//   st::client::Client client({"127.0.0.1", 7447});
//   st::client::Map map = client.open("city");           // header + skip grid
//   map.request_region(level, x0, y0, w, h, priority);    // prefetch what cameras see
//   float lit = map.visibility({x, y, z}, 3);             // 0..1 (3x3 PCF), never blocks
//   map.visibility(points, out, 3);                       // a batch: one lock, one walk per tile
//   float d = map.depth(level, x, y);
//   st::client::MapStats s = map.stats();
//
// What a map answers. The server holds a shadow map of 2^L x 2^L texels (L = finest
// level) as a hierarchy: every level l <= L is itself a complete shadow map of 2^l texels
// a side. depth(l, x, y) is the light-space depth (0 at the light's near plane, 1 at the
// far plane) stored for texel (x, y) of level l; a receiver at light-space depth d is lit
// there when d <= depth. Texels are integers (exact up to level 20). A texel outside the
// map (l > L, or x, y >= 2^l) is lit: depth answers 1, PCF counts the tap lit.
//
// How it works. A fetcher (a thread of its own, or one of a few threads shared by many
// Clients: make_io_pool) owns the TCP connection: it connects with retry and exponential
// backoff, handshakes (optional key proof and TLS), keeps up to max_in_flight tile
// requests on the wire, highest priority first, cancels requests no longer wanted,
// checks each tile's end-to-end CRC-32, decompresses it into a slot of a fixed-size tile
// cache (cache_slots slots of the pack's tile bound) and opens it. Lookups walk the page
// table (skip grid, index tiles) into the cache; where a tile is not resident they answer
// from a coarser level of the same map (the map preview's node at level K + p that came
// with the skip grid, else the deepest node they reached) and queue the tile's fetch at
// miss_priority.
//
// Error model. Exceptions never escape except where stated:
//   - Client's constructor throws std::runtime_error for bad options only; it never waits
//     for or fails on the network (it connects in the background and keeps retrying).
//   - open(), list_maps(), server_stats() throw std::runtime_error with a one-line message
//     on an unknown map, a malformed answer, a refused key, or no answer within
//     ClientOptions::request_timeout.
//   - Map lookups (depth, pcf, lit, visibility) and request_region, cancel_outside,
//     region_resident, stats are noexcept: they never block on the network, never
//     allocate, never throw. A tile that cannot be had (corrupt after max_tile_retries,
//     refused by the server) keeps answering from the coarser level for good and is
//     counted in MapStats::tiles_failed.
//   - PCF (every lookup and every tool takes one unit, the kernel side): an odd side
//     1, 3, 5, 7 or 9 (kMaxPcfSide), 1 a single tap. A lookup given any other side
//     (0, even, above 9) answers NaN (every out[i] of a batch), so a wrong unit shows at
//     once and never passes as a plausible shadow; pcf_side_valid() checks one first.
//   - A default-constructed Map is valid() == false and answers like an empty map: depth
//     1 (lit), pcf and visibility 1 (for a valid side), no tiles, zero stats.
// Thread safety: every method of Client and Map may be called from any thread. Lookups on
// many threads run at once (they share the cache's lock and change nothing another
// lookup reads); a tile arriving holds them up only for O(1) bookkeeping, never for its
// decompression. A lookup costs a lock and a page-table walk: call the batched overloads
// (hundreds to thousands of points per call, neighbours next to each other) on hot paths. A Map
// stays valid (answering from its cache) after its Client is destroyed.
//
// Files named in these comments (tiles/core/..., client/README.md, proto/PROTOCOL.md) are
// installed under share/doc/shadowtile/ with the same relative paths. The C API over this
// one is <shadowtile/shadowtile.h>.
#pragma once
#include <array>
#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "shadowtile/export.h"  // SHADOWTILE_API: what libshadowtile.so exports
namespace st {
class LightSpace;  // the pack's light (tiles/core/light.hpp), behind LightTransform
}

namespace st::client {

struct Endpoint {
  std::string host = "127.0.0.1";
  uint16_t port = 7447;
};

// A few I/O threads shared by many Clients (a process with hundreds of connections).
class IoPool;
// threads in [1, 64]; throws std::runtime_error otherwise. The pool outlives the Clients
// using it (they hold it); destroy the Clients before the last reference goes.
SHADOWTILE_API std::shared_ptr<IoPool> make_io_pool(unsigned threads);

struct ClientOptions {
  // Tile cache slots per map when cache_bytes is 0: exactly this many hold tiles (at least
  // 1); a DAG-MH pack's dictionary is held beside them (MapStats::dictionary_bytes).
  uint32_t cache_slots = 256;
  uint32_t max_slot_bytes = 16u << 20;      // refuse maps whose tile bound exceeds this
  // Memory per map in bytes (0: cache_slots slots instead). The slot count then follows
  // from it: the map's metadata (skip grid, preview, DAG-MH dictionary, request table)
  // is taken first, then every slot costs its size (the pack's tile bound, at least an
  // index tile's 2,396 bytes) plus kSlotOverheadBytes for what each slot holds besides
  // (its opened tile, page-table and bookkeeping entries). open() refuses, in one line
  // naming the sizes and the budget to set, a map whose metadata (the dictionary
  // included) and kMinTileSlots slots do not fit: never a silent shrink. The client
  // tools (load, render, view, report) set this from --cache-mb: memory follows the
  // budget, whatever tile_bytes is.
  uint64_t cache_bytes = 0;
  uint32_t want_capacity = 8192;            // queued (not yet sent) tile requests per map
  uint16_t max_in_flight = 64;              // tile requests proposed in the handshake
  uint16_t tiles_per_request = 8;           // tiles per request (small: priorities stay fresh)
  // Proposed in the handshake: the protocol's ceiling, so maps with big skip grids open
  // (a MapInfo is 9.8 MB at skip level 10); frames are buffered as their bytes arrive.
  uint32_t max_frame_bytes = 64u << 20;
  uint32_t max_tile_retries = 3;            // CRC or decode failures before giving up a tile
  uint16_t miss_priority = 1;               // priority of fetches queued by lookups
  std::chrono::milliseconds connect_timeout{2000};
  std::chrono::milliseconds io_timeout{10000};       // no progress with answers owed: reconnect
  std::chrono::milliseconds request_timeout{10000};  // open(), list_maps(), server_stats()
  std::chrono::milliseconds backoff_initial{20};
  std::chrono::milliseconds backoff_max{2000};
  std::string client_name = "shadowtile-client";
  // The catalog's key (the server's --key-file; raw bytes). When set, the client proves
  // it to the server and requires the server's proof back: a server that does not ask
  // for the key, or proves a different one, is refused. A refusal either way is final:
  // the client stops reconnecting and open()/list_maps()/server_stats() throw saying why;
  // maps already open keep answering from their caches.
  std::vector<uint8_t> key;
  // TLS (a server started with --tls-cert/--tls-key): the server's certificate must chain
  // to tls_ca_file (PEM; empty: the system's trust store) and name tls_server_name
  // (empty: the endpoint's host) in its subjectAltName. A failed handshake is retried
  // like a failed connect; its reason appears in the timeout errors of open() and friends.
  bool tls = false;
  std::string tls_ca_file, tls_server_name;
  // Shared I/O threads (make_io_pool); null: this Client's fetcher has a thread of its own.
  std::shared_ptr<IoPool> io_pool;
};

// A world-space point (right-handed, +Y up), in the units of the scene the map was built from.
struct WorldPoint {
  double x = 0, y = 0, z = 0;
};
struct WorldBox {
  WorldPoint lo, hi;  // lo > hi on some axis: empty
};

// A point in light space: u, v in [0, 1) across the map's image plane (outside: not
// covered), d the light-space depth (0 at the near plane, 1 at the far plane; a spot's is
// linear in the distance along its axis).
struct LightCoord {
  double u = 0, v = 0, d = 0;
};
// An integer texel of one level (0 <= x, y < 2^level).
struct Texel {
  uint64_t x = 0, y = 0;
};

// The map's light: how world points become texels and depths. It is the pack's own light
// (the same object and the same double arithmetic the server's pack and the lookups use),
// so a point's texel and depth here are bit for bit those visibility() tests. A sun is an
// orthographic box (parallel rays; `sun-ground` frames of sun-path stacks are oblique but
// parallel too), a spot a perspective frustum. Cheap to copy; a default-constructed one
// is invalid() and maps every point to (0, 0, 0), texel size 0.
class SHADOWTILE_API LightTransform {
 public:
  LightTransform() = default;
  bool valid() const noexcept { return bool(space_); }
  bool orthographic() const noexcept;  // parallel rays (sun); false: perspective (spot)
  const char* kind_name() const noexcept;  // "sun", "spot", "sun-ground", "spot-window"
  // The frame, in world units: sun: origin is the near plane's corner (u, v) = (0, 0),
  // extent the box's side, near 0 and far the box's depth; spot: origin is the eye,
  // extent the image plane's width at distance 1, near/far distances along forward.
  WorldPoint origin() const noexcept;
  WorldPoint axis_u() const noexcept;
  WorldPoint axis_v() const noexcept;
  WorldPoint forward() const noexcept;
  double extent() const noexcept;
  double near_plane() const noexcept;
  double far_plane() const noexcept;
  // The world box holding the light's volume (the ortho box, or the frustum from near to
  // far): every surface the map was built from lies in it.
  WorldBox volume_bounds() const noexcept;
  LightCoord to_light(const WorldPoint& p) const noexcept;
  // The texel of `level` holding p (or c), clamped to the map's edges (levels <= 30).
  Texel texel(uint32_t level, const WorldPoint& p) const noexcept;
  Texel texel(uint32_t level, const LightCoord& c) const noexcept;
  // The side, in world units, of one texel of `level` at p (a spot's grows with p's
  // distance from the eye). A pixel covering f world units there needs the level where
  // this is about f (MH 2016 §3.3; visibility_filtered picks its levels so).
  double texel_size(const WorldPoint& p, uint32_t level) const noexcept;
  // The world point at light coordinates c (to_light's inverse, up to rounding).
  WorldPoint to_world(const LightCoord& c) const noexcept;
  // The light as the pack header stores it (tiles/PACK.md: kind 0 sun, 1 spot, 2
  // sun-ground, 3 spot-window; 18 doubles): a program can rebuild it exactly.
  uint8_t kind_id() const noexcept;
  std::array<double, 18> to_array() const noexcept;

 private:
  friend class Map;
  std::shared_ptr<const st::LightSpace> space_;
};

// Where the map's surfaces lie, from its skip grid (every level-K texel's stored depth
// put back on its light ray): `bounds` holds every such point; ground (5th percentile
// height), top (98th) and the x, z footprint (1st to 99th percentiles) are what a camera
// path or a receiver plane wants. `points` < 4: nothing was hit at level K and the values
// come from the light box's lowest face.
struct SceneExtent {
  WorldBox bounds;
  double ground = 0, top = 1;
  double x0 = 0, x1 = 1, z0 = 0, z1 = 1;
  uint64_t points = 0;
};

// A camera for Map::request_view. POD, C-friendly.
struct ViewOptions {
  // Screen samples cast per call (samples_x * samples_y <= kMaxViewSamples): each finds
  // its receiver where its ray meets the plane y = receiver_height, and needs the tile
  // under it at the level whose texel is about its pixel's footprint.
  uint32_t samples_x = 64, samples_y = 36;
  double receiver_height = std::numeric_limits<double>::quiet_NaN();  // NaN: MapInfo::scene.ground
  double max_distance = 0;   // receivers farther than this need nothing (0: 1.5 x the scene's span)
  uint16_t priority = 60000; // the nearest tile's fetch priority; each next tile one lower
  // Look-ahead from the camera's motion: `time` is this frame's time in seconds on the
  // caller's clock (NaN: motion unknown). With the time and matrix of the view's previous
  // request (0 < dt <= 1 s), the matrix is extrapolated up to `lookahead` seconds on and
  // the tiles those poses need are asked for after the view's own (ViewStats::ahead), so
  // that tiles enter the view already resident or on their way.
  double time = std::numeric_limits<double>::quiet_NaN();
  double lookahead = 0.25;
};
// One screen sample of a view on its receiver plane (Map::view_samples): where its ray
// meets the plane, the side of its pixel's footprint there in world units (what
// visibility_filtered takes) and its distance from the eye.
struct ViewSample {
  WorldPoint point;
  float footprint = 0;
  float distance = 0;
};
// What a view needs and holds (Map::request_view, Map::view_stats).
struct ViewStats {
  bool ok = false;        // false: no such view, or the request was refused (see request_view)
  uint32_t wanted = 0;    // distinct tiles the view needs
  uint32_t kept = 0;      // those it holds (nearest first; the rest answer from coarser levels)
  uint32_t resident = 0;  // of the kept, resident now (== kept: every lookup the view makes is exact)
  uint32_t queued = 0;    // request_view: fetches newly queued or raised
  uint32_t cancelled = 0; // request_view: fetches cancelled because their tiles left every view
  uint32_t ahead = 0;     // tiles held for the camera's motion (ViewOptions::time), not needed yet
};
inline constexpr uint32_t kMaxViews = 16;
inline constexpr uint32_t kMaxViewSamples = 16384;

struct CacheCounters {
  uint64_t hits = 0;       // lookups that found their tile resident
  uint64_t misses = 0;     // lookups that found it absent or on its way
  uint64_t evictions = 0;  // resident tiles dropped to make room
  uint64_t inserts = 0;    // tiles made resident
  uint32_t resident = 0, pinned = 0, free = 0;  // slots now
};

struct MapStats {
  CacheCounters cache;
  uint64_t tiles_requested = 0;      // tile fetches sent
  uint64_t tiles_received = 0;       // tiles made resident
  uint64_t bytes_received = 0;       // stored (compressed) tile bytes received
  uint64_t crc_errors = 0;           // end-to-end CRC mismatches (each refetched)
  uint64_t decode_errors = 0;        // zlib or tile format failures
  uint64_t tiles_failed = 0;         // given up (retries exhausted or refused by the server)
  uint64_t tiles_cancelled = 0;
  // Tiles a finished GetTiles never answered (a server that breaks the protocol: answers
  // under wrong ids, or none): each asked again up to max_tile_retries, then given up.
  uint64_t tiles_unanswered = 0;
  uint64_t cache_full = 0;           // a tile arrived while every slot was pinned
  uint64_t queue_full = 0;           // a wanted tile could not be queued (want_capacity)
  uint64_t coarse_answers = 0;       // lookups answered above the level asked for
  // A DAG-MH pack's shared dictionary (0: none), fetched with the map and resident for
  // its life. With cache_bytes it comes out of the budget: dictionary_slots is exactly
  // the tile slots it displaces (tile_slots + dictionary_slots is what the same budget
  // gives a map without it). With cache_slots it lies beside the slots: dictionary_slots
  // is 0 and tile_slots == cache_slots.
  uint64_t dictionary_bytes = 0;
  // The memory this map accounts for: metadata (the dictionary included) + slots x (slot
  // bytes + kSlotOverheadBytes); within ClientOptions::cache_bytes when that is set.
  uint64_t accounted_bytes = 0;
  // Where the resident tiles' bytes are now, within the slots' part of accounted_bytes
  // (arena_bytes + slot_bytes_written <= tile_slots x (slot bytes + 64)): a 2D map's
  // tiles packed tightly for the CPU lookups (arena_bytes, whole chunks of a slot's size,
  // never more chunks than tiles in them), and the slot bytes written (index tiles, stack
  // cells; a slot whose tile is in the arena is never written: its pages are the system's
  // zero pages).
  uint64_t arena_bytes = 0;
  uint64_t slot_bytes_written = 0;
  uint32_t dictionary_slots = 0;
  uint32_t tile_slots = 0;           // slots for tiles
  // Views (Map::request_view). view_slots: the slots views may hold (tile_slots less a
  // headroom for arrivals and lookups' own misses). view_tiles_wanted: the distinct tiles
  // the registered views needed at their last requests; view_tiles_over: how many of
  // those did not fit in view_slots (0: the working set fits; else the farthest are
  // answered from coarser levels and this many more slots would hold them all; size
  // cache_slots by it). view_overflows counts requests that did not fit.
  // view_refetches counts tiles that were resident, stayed in a view, and were found
  // evicted (each is fetched again): 0 while the working set fits.
  uint32_t views = 0;
  uint32_t view_slots = 0;
  uint64_t view_tiles_wanted = 0;
  uint64_t view_tiles_over = 0;
  uint64_t view_overflows = 0;
  uint64_t view_refetches = 0;
};

// What one cache slot costs beyond its tile bytes (ClientOptions::cache_bytes).
inline constexpr uint64_t kSlotOverheadBytes = 4096;
// The fewest tile slots a byte budget (ClientOptions::cache_bytes) must leave beside the
// metadata: a view's least working set (MapStats::view_slots) plus the headroom kept for
// arrivals and lookups' own misses. A smaller budget is an error at open().
inline constexpr uint32_t kMinTileSlots = 8;

struct ClientStats {
  uint64_t connects = 0, connect_failures = 0, disconnects = 0;
  uint64_t frames_received = 0, bytes_received = 0, bytes_sent = 0;
  uint64_t protocol_errors = 0;
  bool connected = false;
  bool refused = false;  // authentication failed (see ClientOptions::key); final
};

// What a map is, from its header.
struct MapInfo {
  std::string name;
  std::string encoding;       // "mh", "mmh", "dagmh" or "vsdag"
  uint32_t finest_level = 0;  // L: the map is 2^L texels a side
  uint32_t skip_level = 0;    // K: the page table's dense top grid is 2^K a side
  uint32_t tile_bytes = 0;    // bound on one tile's decoded size (a cache slot)
  uint64_t tile_count = 0;
  uint64_t scene_hash = 0;    // of the scene the map was built from
  bool sun = true;            // directional light (orthographic, or a sun path's ground frame); false: spot (perspective)
  LightTransform light;       // world -> texels and depth (a stack map: its first light sample's)
  SceneExtent scene;          // where the surfaces lie (from the skip grid)
  std::vector<LightTransform> slice_lights;  // a stack map's light samples, slice w's at [w]; 2D: empty
};

// One map of the server's catalog (list_maps).
struct MapListing {
  std::string name;
  std::string encoding;
  uint32_t resolution_log2 = 0;  // L
  uint32_t skip_level = 0;       // K
  uint32_t tile_count = 0;
  uint64_t pack_bytes = 0;
};

// The server's counters and histograms (server_stats), as the server names them.
struct SHADOWTILE_API ServerStats {
  struct Counter {
    std::string name;
    uint64_t value = 0;
  };
  struct Bucket {
    uint64_t upper_bound = 0;  // inclusive
    uint64_t count = 0;
  };
  struct Histogram {
    std::string name;  // with its unit ("latency_us")
    std::vector<Bucket> buckets;
  };
  std::vector<Counter> counters;
  std::vector<Histogram> histograms;
  // The named counter's value, or 0 when the server has none of that name.
  uint64_t counter(const std::string& name) const noexcept;
};


// PCF kernel sides: odd, 1..kMaxPcfSide (1: a single tap, 3: 3x3, ..., 9: 9x9).
inline constexpr uint32_t kMaxPcfSide = 9;
constexpr bool pcf_side_valid(uint32_t side) noexcept { return side >= 1 && side <= kMaxPcfSide && side % 2 == 1; }

// Per-channel transmittance (1: nothing partial between the light and the point).
struct Transmittance {
  float r = 1, g = 1, b = 1;
  bool operator==(const Transmittance&) const = default;
};

class RemoteMap;
struct MapAccess;

// A handle to an opened map (cheap to copy; all copies share one cache).
class SHADOWTILE_API Map {
 public:
  Map() = default;
  bool valid() const noexcept { return bool(map_); }
  MapInfo info() const;  // may allocate (strings); throws nothing but std::bad_alloc
  uint32_t finest_level() const noexcept;

  float depth(uint32_t level, uint64_t x, uint64_t y) const noexcept;
  // Fraction of the side x side kernel around texel (x, y) of `level` (texels x - side/2
  // .. x + side/2 on each axis, clamped to the map's edges) whose taps are lit for
  // `receiver`. side: odd, 1..9 (pcf_side_valid); any other answers NaN.
  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t side, float receiver) const noexcept;
  bool lit(uint64_t x, uint64_t y, float receiver_depth) const noexcept;  // at the finest level
  // Fraction lit (0..1) of a world point: light space from the map's header, PCF over a
  // pcf_side x pcf_side kernel at the finest level (1: one tap, the exact lit test; an
  // invalid side answers NaN, see "PCF" above). Points outside the light's box are lit (1).
  float visibility(const WorldPoint& world, uint32_t pcf_side = 1) const noexcept;
  // Hierarchical filtering (MH 2016 §3.3): `footprint` is the side, in world units, of
  // the area the receiver's pixel covers; the kernel is applied at the two levels where
  // one texel is about that size and blended trilinearly (tiles/core/filter_level.hpp
  // states the arithmetic). footprint <= one finest texel: the finest level, as above.
  float visibility_filtered(const WorldPoint& world, float footprint, uint32_t pcf_side = 1) const noexcept;
  // Batches: out[i] = visibility(points[i], pcf_side) (or visibility_filtered(points[i],
  // footprints[i], pcf_side)) for i below the
  // smallest of the spans' sizes, bit for bit, under one shared lock, with the page-table
  // walk skipped while consecutive points stay inside one tile. Nothing allocates.
  void visibility(std::span<const WorldPoint> points, std::span<float> out, uint32_t pcf_side = 1) const noexcept;
  void visibility_filtered(std::span<const WorldPoint> points, std::span<const float> footprints,
                           std::span<float> out, uint32_t pcf_side = 1) const noexcept;
  // The same with the receiver's surface normal (unit length, facing the light; one far
  // from unit length is normalized): receiver-plane depth bias, what `shadowtile render
  // --filter` and the shaders' st_receiver_slope do. The lookup point is `world` moved
  // along the normal by 1.5 finest texels (`closed`: 0.5, for a surface of a closed
  // object), and each PCF tap compares the receiver's plane over its own texel (slopes
  // from the normal through the light, at most 4 texels of depth per texel) with the
  // stored value, so sloped ground keeps no acne and no rings at coarse levels. Bit for
  // bit render's filtered answer for the same point, normal and footprint
  // (tiles/core/receiver_plane.hpp). footprint <= 0: the finest level.
  float visibility_filtered(const WorldPoint& world, const WorldPoint& normal, float footprint, uint32_t pcf_side = 1,
                            bool closed = false) const noexcept;
  void visibility_filtered(std::span<const WorldPoint> points, std::span<const WorldPoint> normals,
                           std::span<const float> footprints, std::span<float> out, uint32_t pcf_side = 1,
                           bool closed = false) const noexcept;

  // Partial occluders (semi-transparent surfaces, alpha-tested cards, volumes), held in the
  // pack's deep shadow map (Lokovic and Veach 2000) next to the opaque map: the light
  // reaching a point is visibility(...) times transmittance(...), per channel.
  // has_deep(): the map has a deep part (else transmittance is always 1). A point no deep
  // tile covers answers 1; so does a point whose deep tile is not resident yet (its fetch
  // is queued, at miss_priority; the partial shadow appears once it arrives). The
  // filtered form averages over a footprint `footprint` world units wide with the deep
  // tile's mip levels (DSM 2000 §3.4, §5.3). Never blocks; never throws.
  bool has_deep() const noexcept;
  Transmittance transmittance(const WorldPoint& world) const noexcept;
  Transmittance transmittance_filtered(const WorldPoint& world, float footprint) const noexcept;
  // True once the deep directory arrived and every deep tile under the light-space
  // rectangle [u0, u1) x [v0, v1) (map units, 0..1: the light's image plane) is resident
  // (tests, prefetch loops); queues the missing ones. False for a map without a deep part.
  bool deep_resident(double u0, double v0, double u1, double v1) const noexcept;
  // The deep map's level (its texels: 2^level a side; 0 until its directory arrived, and
  // for a map without a deep part), and transmittance_filtered at light coordinates
  // (LightTransform::to_light) with the footprint in map units (0: unfiltered): for
  // renderers that carry light-space points. Never block; never throw.
  uint32_t deep_level() const noexcept;
  Transmittance transmittance_at(const LightCoord& c, double footprint_uv = 0) const noexcept;

  // Queues the fetch of every tile under texels [x0, x0+w) x [y0, y0+h) of `level`
  // (clamped to the map), walking index tiles as they arrive: a region is remembered until
  // its tiles are resident (up to 1,024 pending at once; past that the oldest quarter is
  // forgotten, and asking again brings them back). Larger priority = sooner. Returns the
  // number of tiles newly queued.
  size_t request_region(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h,
                        uint16_t priority) noexcept;
  // Cancels queued and in-flight fetches of tiles outside the region.
  size_t cancel_outside(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) noexcept;
  // True when every tile under the region is resident (lookups there are exact).
  bool region_resident(uint32_t level, uint64_t x0, uint64_t y0, uint64_t w, uint64_t h) const noexcept;

  // Cameras. request_view registers or updates view `view_id` (any number; up to
  // kMaxViews at once per map) from its view-projection matrix (16 doubles, column-major
  // as OpenGL and glm store it: clip = M * (x, y, z, 1), element (row r, column c) at
  // [c * 4 + r]; perspective or orthographic; NDC depth may be [-1, 1] or [0, 1],
  // reversed-Z included) and its viewport in pixels. It casts options' screen samples,
  // finds each one's receiver (on the plane y = receiver_height), picks the level whose
  // texel matches the pixel's footprint there (LightTransform::texel_size; distant pixels
  // need coarse levels, and levels the skip grid and the map preview answer exactly need
  // no fetch) and queues the
  // tiles under them, nearest first (priority counts down from options.priority). The
  // views' tiles are kept resident while in some view (eviction takes other tiles
  // first); fetches of tiles that left every view are cancelled; a view whose tiles do
  // not fit (MapStats::view_slots, shared by views in order of priority) keeps its
  // nearest and counts the rest in ViewStats::wanted - kept and MapStats::view_tiles_over.
  // Refused (ok false, nothing changes): kMaxViews other views registered, a viewport or
  // sample grid of 0 or samples over kMaxViewSamples, a matrix with a non-finite entry
  // or not invertible, a stack map. noexcept; the first request of a view allocates its
  // bounded storage (kMaxViewSamples entries) once, later ones never allocate. Call it
  // every frame for each camera; remove_view when a camera goes away (false: no such view).
  ViewStats request_view(uint32_t view_id, const double view_projection[16], uint32_t width, uint32_t height,
                         const ViewOptions& options = {}) noexcept;
  bool remove_view(uint32_t view_id) noexcept;
  // The view's counts now (resident == kept: the view's lookups are exact); ok false for
  // a view not registered.
  ViewStats view_stats(uint32_t view_id) const noexcept;
  // The receivers request_view's screen samples meet (the same rays, in row order, sky and
  // samples past max_distance left out) into `out`; returns how many were written (at
  // most out.size(); 0 when request_view would refuse the camera). Lookups at these
  // points with their footprints read exactly the tiles the view holds.
  size_t view_samples(const double view_projection[16], uint32_t width, uint32_t height, const ViewOptions& options,
                      std::span<ViewSample> out) const noexcept;

  // Stack maps: packs built with a light set (`build --light sun-path:...` or `area:...`,
  // MH 2016 §4): N shadow maps, one per light sample (slice w = sample w). On a stack map
  // the 2D lookups above answer lit; on a 2D map the ones below do (slices() == 0).
  // Contract (tiles/core/stack_lookup.hpp): time_visibility(p, t), t in [0, 1] (clamped,
  // NaN as 0), sample w at t = w / (N - 1), is exactly the sample's lit test at the
  // samples and blends the two nearest linearly between them (no pop as the sun moves);
  // soft_visibility(p) is the fraction of the N samples that are lit (an area light's
  // soft shadow). Where a tile is not resident the cell's coarser value answers and the
  // tile is queued at miss_priority; request_slices prefetches the tiles of slices
  // [w0, w1] (the next ones a day-night cycle needs) and slices_resident says when the
  // answers there are exact. noexcept, no allocation, as the 2D lookups.
  // PCF and footprint level as in 2D (visibility / visibility_filtered above): each
  // sample's answer is the fraction of a pcf_side x pcf_side kernel of its slice (an
  // invalid side answers NaN), and with the _filtered forms at the two levels of the slice
  // where one texel is about `footprint` world units wide, blended; the time blend and the
  // average over samples are then taken of those fractions. pcf_side 1 with no
  // footprint is the single-tap lookup, bit for bit.
  uint32_t slices() const noexcept;
  float time_visibility(const WorldPoint& world, double time, uint32_t pcf_side = 1) const noexcept;
  float time_visibility_filtered(const WorldPoint& world, double time, float footprint,
                                 uint32_t pcf_side = 1) const noexcept;
  float soft_visibility(const WorldPoint& world, uint32_t pcf_side = 1) const noexcept;
  float soft_visibility_filtered(const WorldPoint& world, float footprint, uint32_t pcf_side = 1) const noexcept;
  // The _filtered forms with the receiver's surface normal: in each sample's slice the
  // receiver plane of visibility_filtered with a normal (the point moved 1.5 finest texels
  // of that slice along the normal, `closed`: 0.5; each tap against the plane), then the
  // same time blend or average. A sample whose slice does not hold the point answers lit.
  float time_visibility_filtered(const WorldPoint& world, const WorldPoint& normal, double time, float footprint,
                                 uint32_t pcf_side = 1, bool closed = false) const noexcept;
  float soft_visibility_filtered(const WorldPoint& world, const WorldPoint& normal, float footprint,
                                 uint32_t pcf_side = 1, bool closed = false) const noexcept;
  // out[i] = soft_visibility(points[i], pcf_side) for i < min(points.size(), out.size()),
  // bit for bit. With pcf_side 1 the walks of several points are interleaved so that
  // their cache misses overlap: a frame's receivers in one call cost several times less
  // per point than one call each (tiles/core/MHOCT.md "Batched soft lookups").
  void soft_visibility(std::span<const WorldPoint> points, std::span<float> out, uint32_t pcf_side = 1) const noexcept;
  float slice_depth(uint32_t slice, uint32_t level, uint64_t x, uint64_t y) const noexcept;
  size_t request_slices(uint32_t w0, uint32_t w1, uint16_t priority) noexcept;
  bool slices_resident(uint32_t w0, uint32_t w1) const noexcept;

  MapStats stats() const noexcept;
  // The cache's slot size: slot i of the pool lies at i * slot_bytes().
  uint32_t slot_bytes() const noexcept;

 private:
  friend class Client;
  friend struct MapAccess;  // the library's own tools (loadgen, render) reach the internals
  explicit Map(std::shared_ptr<RemoteMap> m) : map_(std::move(m)) {}
  std::shared_ptr<RemoteMap> map_;
};

class Fetcher;

class SHADOWTILE_API Client {
 public:
  explicit Client(Endpoint endpoint, ClientOptions options = {});
  // Several replicas serving the same pack files (a map opens on a replica only if its
  // pack header is byte-equal to the one first opened). Successive Clients of a process start at successive
  // replicas, so their connections spread; when a connection fails or drops, the next
  // attempt goes to the next replica, and the tiles that were in flight are requested
  // again there. Throws st::Error if `endpoints` is empty.
  explicit Client(std::vector<Endpoint> endpoints, ClientOptions options = {});
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Opens a map by name (waits for the connection up to request_timeout).
  Map open(const std::string& name);
  std::vector<MapListing> list_maps();
  ServerStats server_stats();

  bool connected() const noexcept;
  ClientStats stats() const noexcept;

 private:
  std::shared_ptr<Fetcher> fetcher_;
};

}  // namespace st::client

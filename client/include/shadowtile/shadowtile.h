/* shadowtile C API (C99): the client library for engines that cannot take C++ (C#, Rust,
 * Godot, Python ctypes). It wraps the C++ API of <shadowtile/client.hpp>; read that
 * header for what a map answers (light space, levels, texels, PCF, transmittance).
 *
 *   shadowtile_client_options o;
 *   shadowtile_client_options_default(&o);
 *   shadowtile_endpoint server = {"127.0.0.1", 7447};
 *   shadowtile_client* client;
 *   if (shadowtile_client_create(&server, 1, &o, &client) != SHADOWTILE_OK)
 *     fprintf(stderr, "%s\n", shadowtile_last_error());
 *   shadowtile_map* map;
 *   shadowtile_client_open_map(client, "city", &map);        (waits for the server)
 *   shadowtile_map_request_view(map, 0, view_projection, 1920, 1080, NULL, NULL);  (each frame)
 *   shadowtile_map_visibility(map, points, count, 3, out);  (3x3 PCF; never blocks)
 *   shadowtile_map_close(map);
 *   shadowtile_client_destroy(client);
 *
 * Errors. Every function that can fail returns a shadowtile_status; SHADOWTILE_OK is 0.
 * On failure the out-parameters are left unchanged, a one-line message is kept for the
 * calling thread (shadowtile_last_error) and the error callback, if one is set, is called.
 * No C++ exception ever crosses this boundary. Lookups (visibility, transmittance) and
 * region calls fail only on bad arguments (a NULL handle or array, a pcf_side that is not
 * odd 1..9): they
 * never block on the network, never allocate, and where a tile is not resident they
 * answer from a coarser level and queue its fetch.
 *
 * Ownership. shadowtile_client_create and shadowtile_client_open_map hand out handles the
 * caller owns and releases with shadowtile_client_destroy and shadowtile_map_close. A map
 * stays valid, answering from its cache, after its client is destroyed (it fetches
 * nothing more). Strings and arrays passed in are copied before the call returns; strings
 * handed out live as long as the handle they came from (map info) or until freed
 * (shadowtile_free_map_listings).
 *
 * Threads. Every function may be called from any thread, and concurrently on the same
 * handle (lookups on many threads run together), except shadowtile_client_destroy and
 * shadowtile_map_close: no other call may be in progress on that handle or follow it.
 * A client runs one network thread of its own.
 *
 * ABI. Structs below change only with the library's SONAME (libshadowtile.so.MAJOR, or
 * .so.0.MINOR before 1.0); SHADOWTILE_C_API_VERSION counts additions of functions. */
#ifndef SHADOWTILE_H
#define SHADOWTILE_H

#include <stddef.h>
#include <stdint.h>

#include "shadowtile/export.h"

#ifdef __cplusplus
extern "C" {
#endif

/* 2: PCF takes the kernel side (odd, 1..9), not a radius; views, the light transform,
 * the scene extent and the cache's shares added. 3: shadowtile_client_options::cache_bytes
 * (a memory budget per map), view look-ahead (shadowtile_view_options::time, lookahead;
 * shadowtile_view_stats::ahead). */
#define SHADOWTILE_C_API_VERSION 3
#define SHADOWTILE_MAX_PCF_SIDE 9
/* What one cache slot costs beyond its tile bytes, and the fewest tile slots a map opens
   with under a byte budget (shadowtile_client_options::cache_bytes). */
#define SHADOWTILE_SLOT_OVERHEAD_BYTES 4096
#define SHADOWTILE_MIN_TILE_SLOTS 8

typedef enum shadowtile_status {
  SHADOWTILE_OK = 0,
  SHADOWTILE_ERROR_INVALID_ARGUMENT = 1, /* NULL handle or pointer, bad option, bad map name, bad pcf_side */
  SHADOWTILE_ERROR_NOT_FOUND = 2,        /* the server has no map of that name */
  SHADOWTILE_ERROR_TIMEOUT = 3,          /* no answer within request_timeout_ms (not connected, or a slow server) */
  SHADOWTILE_ERROR_REFUSED = 4,          /* the key was refused, either way: final for this client */
  SHADOWTILE_ERROR_SERVER = 5,           /* the server answered another error (overloaded, shutting down, ...) */
  SHADOWTILE_ERROR_PROTOCOL = 6,         /* a malformed or unexpected answer */
  SHADOWTILE_ERROR_OUT_OF_MEMORY = 7,
  SHADOWTILE_ERROR_INTERNAL = 8          /* anything else: the message says what */
} shadowtile_status;

/* The library's version ("0.2.0"), and SHADOWTILE_C_API_VERSION as it was built. */
SHADOWTILE_API const char* shadowtile_version(void);
SHADOWTILE_API uint32_t shadowtile_c_api_version(void);
/* "ok", "invalid_argument", ...: a static string, never NULL. */
SHADOWTILE_API const char* shadowtile_status_name(shadowtile_status status);

/* The message of the last call on this thread that failed ("" if none did); successful
 * calls leave it as it is. Valid until the next failing call on this thread. */
SHADOWTILE_API const char* shadowtile_last_error(void);

/* Called on every failure, on the failing thread, before the failing function returns
 * (message as shadowtile_last_error). One for the process; NULL removes it. The callback
 * may call shadowtile functions but must not unwind (longjmp, exceptions) through them. */
typedef void (*shadowtile_error_callback)(void* user_data, shadowtile_status status, const char* message);
SHADOWTILE_API void shadowtile_set_error_callback(shadowtile_error_callback callback, void* user_data);

/* ------------------------------------------------------------------ client */

typedef struct shadowtile_client shadowtile_client; /* opaque */
typedef struct shadowtile_map shadowtile_map;       /* opaque */

typedef struct shadowtile_endpoint {
  const char* host; /* name or address */
  uint16_t port;
} shadowtile_endpoint;

/* ClientOptions of client.hpp, field for field (durations in milliseconds). Start from
 * shadowtile_client_options_default and change what you need. */
typedef struct shadowtile_client_options {
  uint32_t cache_slots;       /* tile cache slots per map (256) */
  uint32_t max_slot_bytes;    /* refuse maps whose tile bound exceeds this (16 MiB) */
  uint32_t want_capacity;     /* queued tile requests per map (8192) */
  uint32_t max_frame_bytes;   /* proposed in the handshake (64 MiB) */
  uint32_t max_tile_retries;  /* CRC or decode failures before a tile is given up (3) */
  uint16_t max_in_flight;     /* tile requests on the wire (64) */
  uint16_t tiles_per_request; /* (8) */
  uint16_t miss_priority;     /* priority of fetches queued by lookups (1) */
  uint16_t reserved;          /* 0 */
  uint32_t connect_timeout_ms, io_timeout_ms, request_timeout_ms; /* 2000, 10000, 10000 */
  uint32_t backoff_initial_ms, backoff_max_ms;                    /* 20, 2000 */
  const char* client_name;    /* NULL: "shadowtile-client" */
  const uint8_t* key;         /* the catalog's key (raw bytes), key_size of them; NULL: none */
  size_t key_size;
  int32_t tls;                /* nonzero: TLS; the certificate must chain to tls_ca_file */
  const char* tls_ca_file;    /* PEM; NULL or "": the system's trust store */
  const char* tls_server_name; /* NULL or "": the endpoint's host */
  uint64_t cache_bytes;       /* 0: cache_slots slots per map; else each map's memory budget in
                                 bytes (metadata, the DAG-MH dictionary and slots of the map's
                                 tile bound + SHADOWTILE_SLOT_OVERHEAD_BYTES; cache_slots is then
                                 ignored); a budget that cannot hold the metadata and
                                 SHADOWTILE_MIN_TILE_SLOTS slots fails at open, naming the least */
} shadowtile_client_options;

SHADOWTILE_API void shadowtile_client_options_default(shadowtile_client_options* options);

/* A client for `endpoint_count` replicas serving the same packs (client.hpp "Client").
 * options NULL: the defaults. Fails (INVALID_ARGUMENT) on bad options only: it connects
 * in the background and keeps retrying, so a server that is not up yet is no error. */
SHADOWTILE_API shadowtile_status shadowtile_client_create(const shadowtile_endpoint* endpoints, size_t endpoint_count,
                                                          const shadowtile_client_options* options,
                                                          shadowtile_client** out_client);
/* Stops the network thread and frees the client; NULL is a no-op. Open maps stay valid. */
SHADOWTILE_API void shadowtile_client_destroy(shadowtile_client* client);

typedef struct shadowtile_client_stats {
  uint64_t connects, connect_failures, disconnects;
  uint64_t frames_received, bytes_received, bytes_sent;
  uint64_t protocol_errors;
  int32_t connected; /* 1 while a session is up */
  int32_t refused;   /* 1 once authentication failed (final) */
} shadowtile_client_stats;
SHADOWTILE_API shadowtile_status shadowtile_client_get_stats(const shadowtile_client* client,
                                                             shadowtile_client_stats* out_stats);

/* One map of the server's catalog. */
typedef struct shadowtile_map_listing {
  const char* name;
  const char* encoding; /* "mh", "mmh", "dagmh" */
  uint32_t resolution_log2;
  uint32_t skip_level;
  uint32_t tile_count;
  uint32_t reserved;
  uint64_t pack_bytes;
} shadowtile_map_listing;
/* Asks the server for its catalog (waits up to request_timeout_ms). *out_maps is one
 * allocation holding the array and its strings: free it with shadowtile_free_map_listings. */
SHADOWTILE_API shadowtile_status shadowtile_client_list_maps(shadowtile_client* client, shadowtile_map_listing** out_maps,
                                                             size_t* out_count);
SHADOWTILE_API void shadowtile_free_map_listings(shadowtile_map_listing* maps);

/* Opens a map by name: waits for the connection and the map's header, up to
 * request_timeout_ms. NOT_FOUND: no such map; TIMEOUT, REFUSED, SERVER, PROTOCOL. */
SHADOWTILE_API shadowtile_status shadowtile_client_open_map(shadowtile_client* client, const char* name,
                                                            shadowtile_map** out_map);

/* ------------------------------------------------------------------ map */

/* Frees the handle; NULL is a no-op. */
SHADOWTILE_API void shadowtile_map_close(shadowtile_map* map);

typedef struct shadowtile_map_info {
  const char* name;       /* owned by the map: valid until shadowtile_map_close */
  const char* encoding;   /* "mh", "mmh" or "dagmh" (likewise) */
  uint32_t finest_level;  /* L: the map is 2^L texels a side */
  uint32_t skip_level;    /* K: the page table's dense top grid is 2^K a side */
  uint32_t tile_bytes;    /* bound on one tile's decoded size (a cache slot) */
  uint32_t slices;        /* light samples of a stack map; 0 for a 2D map */
  uint64_t tile_count;
  uint64_t scene_hash;    /* of the scene the map was built from */
  int32_t sun;            /* 1: directional light; 0: spot */
  int32_t has_deep;       /* 1: partial occluders (shadowtile_map_transmittance answers them) */
} shadowtile_map_info;
SHADOWTILE_API shadowtile_status shadowtile_map_get_info(const shadowtile_map* map, shadowtile_map_info* out_info);

/* A world-space point (right-handed, +Y up), in the scene's units. */
typedef struct shadowtile_point {
  double x, y, z;
} shadowtile_point;

/* Per-channel transmittance (1: nothing partial between the light and the point). */
typedef struct shadowtile_rgb {
  float r, g, b;
} shadowtile_rgb;

/* out[i] = fraction lit (0..1) of points[i], PCF over a pcf_side x pcf_side kernel at the
 * finest level: pcf_side odd, 1 (one tap) to SHADOWTILE_MAX_PCF_SIDE; any other side is
 * INVALID_ARGUMENT (nothing written). Points outside the light's box are lit. Bit for bit
 * the C++ Map::visibility. count 0 allows NULL arrays. */
SHADOWTILE_API shadowtile_status shadowtile_map_visibility(const shadowtile_map* map, const shadowtile_point* points,
                                                           size_t count, uint32_t pcf_side, float* out);
/* Hierarchical filtering: footprints[i] is the side, in world units, of the area
 * points[i]'s pixel covers (Map::visibility_filtered). */
SHADOWTILE_API shadowtile_status shadowtile_map_visibility_filtered(const shadowtile_map* map,
                                                                    const shadowtile_point* points,
                                                                    const float* footprints, size_t count,
                                                                    uint32_t pcf_side, float* out);
/* The same with each receiver's surface normal (normals[i], unit length, facing the light):
 * receiver-plane depth bias, bit for bit Map::visibility_filtered with normals (open
 * surfaces when closed is 0, closed objects' surfaces when 1). */
SHADOWTILE_API shadowtile_status shadowtile_map_visibility_filtered_normal(
    const shadowtile_map* map, const shadowtile_point* points, const shadowtile_point* normals,
    const float* footprints, size_t count, uint32_t pcf_side, int closed, float* out);
/* Partial occluders (Map::transmittance): out[i] for points[i]; footprints NULL: unfiltered,
 * else filtered over footprints[i] world units (Map::transmittance_filtered). All 1 for a
 * map without a deep part. */
SHADOWTILE_API shadowtile_status shadowtile_map_transmittance(const shadowtile_map* map, const shadowtile_point* points,
                                                              const float* footprints, size_t count,
                                                              shadowtile_rgb* out);

/* Prefetch: queues every tile under texels [x0, x0+w) x [y0, y0+h) of `level` (clamped to
 * the map); larger priority = sooner. *out_queued (if not NULL): tiles newly queued. */
SHADOWTILE_API shadowtile_status shadowtile_map_request_region(shadowtile_map* map, uint32_t level, uint64_t x0,
                                                               uint64_t y0, uint64_t w, uint64_t h, uint16_t priority,
                                                               size_t* out_queued);
/* Cancels queued and in-flight fetches of tiles outside the region. */
SHADOWTILE_API shadowtile_status shadowtile_map_cancel_outside(shadowtile_map* map, uint32_t level, uint64_t x0,
                                                               uint64_t y0, uint64_t w, uint64_t h,
                                                               size_t* out_cancelled);
/* *out_resident = 1 when every tile under the region is resident (lookups there exact). */
SHADOWTILE_API shadowtile_status shadowtile_map_region_resident(const shadowtile_map* map, uint32_t level, uint64_t x0,
                                                                uint64_t y0, uint64_t w, uint64_t h,
                                                                int32_t* out_resident);

/* ---- Cameras (Map::request_view of client.hpp: read it for what a view needs and keeps). */

/* ViewOptions of client.hpp. Start from shadowtile_view_options_default. */
typedef struct shadowtile_view_options {
  uint32_t samples_x, samples_y; /* screen samples (64 x 36); product <= 16384 */
  double receiver_height;        /* NaN: the scene's ground (shadowtile_scene_extent.ground) */
  double max_distance;           /* 0: 1.5 x the scene's span */
  uint16_t priority;             /* the nearest tile's fetch priority (60000) */
  uint16_t reserved[3];          /* 0 */
  double time;                   /* this frame's time in seconds on the caller's clock (NaN:
                                    motion unknown); with the previous request's time and
                                    matrix the view looks ahead along the camera's motion */
  double lookahead;              /* seconds to look ahead (0.25; 0: none) */
} shadowtile_view_options;
SHADOWTILE_API void shadowtile_view_options_default(shadowtile_view_options* options);

/* ViewStats of client.hpp. */
typedef struct shadowtile_view_stats {
  uint32_t wanted;    /* distinct tiles the view needs */
  uint32_t kept;      /* those it holds (nearest first) */
  uint32_t resident;  /* of the kept, resident now (== kept: the view's lookups are exact) */
  uint32_t queued;    /* request_view: fetches newly queued or raised */
  uint32_t cancelled; /* request_view: fetches cancelled (their tiles left every view) */
  uint32_t ahead;     /* tiles held for the camera's motion (shadowtile_view_options::time) */
} shadowtile_view_stats;

/* Registers or updates view `view_id` (up to 16 at once per map) from its view-projection
 * matrix (16 doubles, column-major as OpenGL and glm store it) and viewport in pixels, and
 * queues the tiles it needs, nearest first. Call it every frame for each camera.
 * options NULL: the defaults; out_stats may be NULL. INVALID_ARGUMENT (nothing changes):
 * a NULL matrix, a zero viewport, a sample grid of 0 or over 16384, a non-finite or
 * singular matrix, 16 other views registered, a stack map. Never blocks. */
SHADOWTILE_API shadowtile_status shadowtile_map_request_view(shadowtile_map* map, uint32_t view_id,
                                                             const double view_projection[16], uint32_t width,
                                                             uint32_t height, const shadowtile_view_options* options,
                                                             shadowtile_view_stats* out_stats);
/* Forgets a view (its tiles may then be evicted). *out_removed (if not NULL): 1 if it was
 * registered, else 0. */
SHADOWTILE_API shadowtile_status shadowtile_map_remove_view(shadowtile_map* map, uint32_t view_id,
                                                            int32_t* out_removed);
/* A registered view's counts now; NOT_FOUND for a view not registered. */
SHADOWTILE_API shadowtile_status shadowtile_map_view_stats(const shadowtile_map* map, uint32_t view_id,
                                                           shadowtile_view_stats* out_stats);

/* ---- The light (LightTransform of client.hpp): world points to light space and texels,
 * bit for bit what the lookups test. A stack map's: its first light sample's. */

/* A point in light space: u, v in [0, 1) across the map's image plane (outside: not
 * covered), d the depth (0 at the near plane, 1 at the far plane). */
typedef struct shadowtile_light_coord {
  double u, v, d;
} shadowtile_light_coord;
typedef struct shadowtile_texel {
  uint64_t x, y;
} shadowtile_texel;

typedef struct shadowtile_light {
  uint32_t kind;          /* 0 sun, 1 spot, 2 sun-ground, 3 spot-window (tiles/PACK.md) */
  int32_t orthographic;   /* 1: parallel rays (sun); 0: perspective (spot) */
  const char* kind_name;  /* "sun", "spot", "sun-ground", "spot-window" (static) */
  /* The frame: sun: origin is the near plane's corner (u, v) = (0, 0), extent the box's
   * side; spot: origin is the eye, extent the image plane's width at distance 1. */
  shadowtile_point origin, axis_u, axis_v, forward;
  double extent, near_plane, far_plane;
  shadowtile_point volume_lo, volume_hi; /* a world box holding the light's volume */
  double params[18];      /* the pack header's 18 doubles: rebuilds the light exactly */
} shadowtile_light;
SHADOWTILE_API shadowtile_status shadowtile_map_get_light(const shadowtile_map* map, shadowtile_light* out_light);

/* out[i] = points[i] in light space. */
SHADOWTILE_API shadowtile_status shadowtile_map_to_light(const shadowtile_map* map, const shadowtile_point* points,
                                                         size_t count, shadowtile_light_coord* out);
/* out[i] = coords[i] back in world space (to_light's inverse, up to rounding). */
SHADOWTILE_API shadowtile_status shadowtile_map_to_world(const shadowtile_map* map,
                                                         const shadowtile_light_coord* coords, size_t count,
                                                         shadowtile_point* out);
/* out[i] = the texel of `level` (<= 30) holding points[i], clamped to the map's edges. */
SHADOWTILE_API shadowtile_status shadowtile_map_texels(const shadowtile_map* map, uint32_t level,
                                                       const shadowtile_point* points, size_t count,
                                                       shadowtile_texel* out);
/* out[i] = the side, in world units, of one texel of `level` at points[i] (a pixel
 * covering f world units there needs the level where this is about f). */
SHADOWTILE_API shadowtile_status shadowtile_map_texel_size(const shadowtile_map* map, uint32_t level,
                                                           const shadowtile_point* points, size_t count,
                                                           double* out);

/* SceneExtent of client.hpp: where the map's surfaces lie (from its skip grid). */
typedef struct shadowtile_scene_extent {
  shadowtile_point bounds_lo, bounds_hi; /* every surface point of the skip grid */
  double ground, top;                    /* 5th and 98th percentile heights */
  double x0, x1, z0, z1;                 /* footprint: 1st to 99th percentiles */
  uint64_t points;                       /* < 4: nothing hit; values from the light box */
} shadowtile_scene_extent;
SHADOWTILE_API shadowtile_status shadowtile_map_get_scene_extent(const shadowtile_map* map,
                                                                 shadowtile_scene_extent* out_extent);

/* The cache's shares and the views' working set (MapStats of client.hpp). */
typedef struct shadowtile_map_budget {
  uint64_t dictionary_bytes;  /* a DAG-MH pack's shared dictionary, resident for the map's life */
  uint64_t accounted_bytes;   /* metadata + slots (within cache_bytes when that is set) */
  uint32_t dictionary_slots;  /* tile slots the dictionary displaces (see MapStats) */
  uint32_t tile_slots;        /* slots for tiles */
  uint32_t views, view_slots; /* registered views; slots they may hold */
  uint64_t view_tiles_wanted, view_tiles_over, view_overflows, view_refetches;
} shadowtile_map_budget;
SHADOWTILE_API shadowtile_status shadowtile_map_get_budget(const shadowtile_map* map, shadowtile_map_budget* out_budget);

typedef struct shadowtile_map_stats {
  /* the tile cache */
  uint64_t cache_hits, cache_misses, cache_evictions, cache_inserts;
  uint32_t slots_resident, slots_pinned, slots_free, reserved;
  /* the fetches (MapStats of client.hpp) */
  uint64_t tiles_requested, tiles_received, bytes_received;
  uint64_t crc_errors, decode_errors, tiles_failed, tiles_cancelled;
  uint64_t cache_full, queue_full, coarse_answers, dictionary_bytes;
} shadowtile_map_stats;
SHADOWTILE_API shadowtile_status shadowtile_map_get_stats(const shadowtile_map* map, shadowtile_map_stats* out_stats);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* SHADOWTILE_H */

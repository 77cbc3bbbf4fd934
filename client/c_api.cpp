// The C API (shadowtile/shadowtile.h) over the C++ API (shadowtile/client.hpp). This is a
// library boundary in the Embree sense: every entry point that can meet an exception
// catches it here and turns it into a status, a thread-local message and the error
// callback; nothing unwinds into C.
#include "shadowtile/shadowtile.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <mutex>
#include <new>
#include <string>
#include <vector>

#include "client/call_error.hpp"
#include "common/version.hpp"
#include "shadowtile/client.hpp"

// The C structs are ABI: their layout on LP64 (Linux x86-64, arm64) is pinned here, so a
// change that moves a field fails to compile instead of breaking bindings (C#, Rust,
// ctypes: tests/capi/capi_test.py mirrors them) at run time.
#if UINTPTR_MAX == UINT64_MAX
static_assert(sizeof(shadowtile_endpoint) == 16);
static_assert(SHADOWTILE_SLOT_OVERHEAD_BYTES == st::client::kSlotOverheadBytes &&
              SHADOWTILE_MIN_TILE_SLOTS == st::client::kMinTileSlots);
static_assert(sizeof(shadowtile_client_options) == 104 && offsetof(shadowtile_client_options, cache_bytes) == 96 && offsetof(shadowtile_client_options, connect_timeout_ms) == 28 &&
              offsetof(shadowtile_client_options, client_name) == 48 && offsetof(shadowtile_client_options, tls) == 72 &&
              offsetof(shadowtile_client_options, tls_server_name) == 88);
static_assert(sizeof(shadowtile_client_stats) == 64 && offsetof(shadowtile_client_stats, refused) == 60);
static_assert(sizeof(shadowtile_map_listing) == 40 && offsetof(shadowtile_map_listing, pack_bytes) == 32);
static_assert(sizeof(shadowtile_map_info) == 56 && offsetof(shadowtile_map_info, tile_count) == 32 &&
              offsetof(shadowtile_map_info, has_deep) == 52);
static_assert(sizeof(shadowtile_point) == 24 && sizeof(shadowtile_rgb) == 12);
static_assert(sizeof(shadowtile_map_stats) == 136 && offsetof(shadowtile_map_stats, tiles_requested) == 48 &&
              offsetof(shadowtile_map_stats, dictionary_bytes) == 128);

struct shadowtile_client {
  st::client::Client client;
};

static_assert(sizeof(shadowtile_view_options) == 48 && offsetof(shadowtile_view_options, priority) == 24 &&
              offsetof(shadowtile_view_options, time) == 32 && offsetof(shadowtile_view_options, lookahead) == 40);
static_assert(sizeof(shadowtile_view_stats) == 24);
static_assert(sizeof(shadowtile_light) == 328 && offsetof(shadowtile_light, origin) == 16 &&
              offsetof(shadowtile_light, extent) == 112 && offsetof(shadowtile_light, volume_lo) == 136 &&
              offsetof(shadowtile_light, params) == 184);
static_assert(sizeof(shadowtile_scene_extent) == 104 && offsetof(shadowtile_scene_extent, points) == 96);
static_assert(sizeof(shadowtile_map_budget) == 64 && offsetof(shadowtile_map_budget, view_tiles_wanted) == 32);
#endif

struct shadowtile_map {
  st::client::Map map;
  std::string name, encoding;  // what shadowtile_map_info's pointers point at
  shadowtile_map_info info{};
  st::client::LightTransform light;  // MapInfo's, kept: the transform calls never allocate
  st::client::SceneExtent scene;
};

namespace {

using st::client::CallError;
using st::client::CallFailure;

// ---------------------------------------------------------------- errors

// The message buffer is fixed so that reporting an error never allocates (it may be
// reporting std::bad_alloc); longer messages are cut.
constexpr size_t kMessageBytes = 512;
thread_local char t_last_error[kMessageBytes] = "";

std::mutex g_callback_mu;
shadowtile_error_callback g_callback = nullptr;
void* g_callback_user = nullptr;

shadowtile_status fail(shadowtile_status status, const char* message) noexcept {
  std::snprintf(t_last_error, kMessageBytes, "%s", message);
  shadowtile_error_callback cb;
  void* user;
  {
    std::lock_guard lock(g_callback_mu);
    cb = g_callback;
    user = g_callback_user;
  }
  if (cb) cb(user, status, t_last_error);  // outside the lock: it may set another callback
  return status;
}

shadowtile_status fail(shadowtile_status status, const std::string& message) noexcept {
  return fail(status, message.c_str());
}

// What a caught exception means for the caller. Run inside a catch block.
shadowtile_status fail_current_exception(const char* where) noexcept {
  char buf[kMessageBytes];
  try {
    throw;
  } catch (const CallError& e) {
    shadowtile_status s = SHADOWTILE_ERROR_INTERNAL;
    switch (e.kind()) {
      case CallFailure::bad_argument: s = SHADOWTILE_ERROR_INVALID_ARGUMENT; break;
      case CallFailure::stopped: s = SHADOWTILE_ERROR_INTERNAL; break;
      case CallFailure::refused: s = SHADOWTILE_ERROR_REFUSED; break;
      case CallFailure::timeout: s = SHADOWTILE_ERROR_TIMEOUT; break;
      case CallFailure::unexpected_answer: s = SHADOWTILE_ERROR_PROTOCOL; break;
      case CallFailure::server_error:
        s = e.server_code() == st::proto::ErrorCode::unknown_map ? SHADOWTILE_ERROR_NOT_FOUND : SHADOWTILE_ERROR_SERVER;
        break;
    }
    std::snprintf(buf, sizeof buf, "%s: %s", where, e.what());
    return fail(s, buf);
  } catch (const std::bad_alloc&) {
    std::snprintf(buf, sizeof buf, "%s: out of memory", where);
    return fail(SHADOWTILE_ERROR_OUT_OF_MEMORY, buf);
  } catch (const std::exception& e) {
    std::snprintf(buf, sizeof buf, "%s: %s", where, e.what());
    return fail(SHADOWTILE_ERROR_INTERNAL, buf);
  } catch (...) {
    std::snprintf(buf, sizeof buf, "%s: unknown exception", where);
    return fail(SHADOWTILE_ERROR_INTERNAL, buf);
  }
}

shadowtile_status null_argument(const char* where, const char* what) noexcept {
  char buf[kMessageBytes];
  std::snprintf(buf, sizeof buf, "%s: %s is NULL", where, what);
  return fail(SHADOWTILE_ERROR_INVALID_ARGUMENT, buf);
}

// Map::visibility answers NaN for a kernel side that is not odd 1..9 (client.hpp "PCF");
// here such a side is the caller's mistake and says so, before anything is written.
shadowtile_status check_lookup(const char* where, const shadowtile_map* map, const void* points, size_t count,
                               const void* out, uint32_t pcf_side) noexcept {
  if (!map) return null_argument(where, "map");
  if (count > 0 && !points) return null_argument(where, "points");
  if (count > 0 && !out) return null_argument(where, "out");
  if (!st::client::pcf_side_valid(pcf_side)) {
    char buf[kMessageBytes];
    std::snprintf(buf, sizeof buf, "%s: pcf_side %u is not a PCF kernel side (odd, 1..%u)", where, unsigned(pcf_side),
                  unsigned(st::client::kMaxPcfSide));
    return fail(SHADOWTILE_ERROR_INVALID_ARGUMENT, buf);
  }
  return SHADOWTILE_OK;
}

// shadowtile_point and WorldPoint are both three doubles, but distinct types: points are
// copied through a stack buffer (no aliasing games), a chunk per batched C++ call, which
// keeps the batch's one lock and tile-coherence per chunk.
constexpr size_t kChunk = 256;

template <typename Fn>
void for_each_chunk(const shadowtile_point* points, size_t count, Fn&& fn) noexcept {
  std::array<st::client::WorldPoint, kChunk> buf;
  for (size_t i0 = 0; i0 < count; i0 += kChunk) {
    const size_t n = std::min(kChunk, count - i0);
    for (size_t i = 0; i < n; ++i) buf[i] = {points[i0 + i].x, points[i0 + i].y, points[i0 + i].z};
    fn(i0, std::span<const st::client::WorldPoint>(buf.data(), n));
  }
}

std::chrono::milliseconds ms(uint32_t v) { return std::chrono::milliseconds(v); }

}  // namespace

extern "C" {

// ---------------------------------------------------------------- library

const char* shadowtile_version(void) { return st::kVersion; }
uint32_t shadowtile_c_api_version(void) { return SHADOWTILE_C_API_VERSION; }

const char* shadowtile_status_name(shadowtile_status status) {
  switch (status) {
    case SHADOWTILE_OK: return "ok";
    case SHADOWTILE_ERROR_INVALID_ARGUMENT: return "invalid_argument";
    case SHADOWTILE_ERROR_NOT_FOUND: return "not_found";
    case SHADOWTILE_ERROR_TIMEOUT: return "timeout";
    case SHADOWTILE_ERROR_REFUSED: return "refused";
    case SHADOWTILE_ERROR_SERVER: return "server";
    case SHADOWTILE_ERROR_PROTOCOL: return "protocol";
    case SHADOWTILE_ERROR_OUT_OF_MEMORY: return "out_of_memory";
    case SHADOWTILE_ERROR_INTERNAL: return "internal";
  }
  return "unknown";
}

const char* shadowtile_last_error(void) { return t_last_error; }

void shadowtile_set_error_callback(shadowtile_error_callback callback, void* user_data) {
  std::lock_guard lock(g_callback_mu);
  g_callback = callback;
  g_callback_user = user_data;
}

// ---------------------------------------------------------------- client

void shadowtile_client_options_default(shadowtile_client_options* o) {
  if (!o) return;
  const st::client::ClientOptions d;
  *o = shadowtile_client_options{};
  o->cache_slots = d.cache_slots;
  o->max_slot_bytes = d.max_slot_bytes;
  o->want_capacity = d.want_capacity;
  o->max_frame_bytes = d.max_frame_bytes;
  o->max_tile_retries = d.max_tile_retries;
  o->max_in_flight = d.max_in_flight;
  o->tiles_per_request = d.tiles_per_request;
  o->miss_priority = d.miss_priority;
  o->connect_timeout_ms = uint32_t(d.connect_timeout.count());
  o->io_timeout_ms = uint32_t(d.io_timeout.count());
  o->request_timeout_ms = uint32_t(d.request_timeout.count());
  o->backoff_initial_ms = uint32_t(d.backoff_initial.count());
  o->backoff_max_ms = uint32_t(d.backoff_max.count());
  o->cache_bytes = d.cache_bytes;
}

shadowtile_status shadowtile_client_create(const shadowtile_endpoint* endpoints, size_t endpoint_count,
                                           const shadowtile_client_options* options, shadowtile_client** out_client) {
  constexpr const char* where = "shadowtile_client_create";
  if (!out_client) return null_argument(where, "out_client");
  if (endpoint_count == 0) return fail(SHADOWTILE_ERROR_INVALID_ARGUMENT, "shadowtile_client_create: no endpoint");
  if (!endpoints) return null_argument(where, "endpoints");
  try {
    std::vector<st::client::Endpoint> eps;
    for (size_t i = 0; i < endpoint_count; ++i) {
      if (!endpoints[i].host || !*endpoints[i].host)
        return fail(SHADOWTILE_ERROR_INVALID_ARGUMENT,
                    std::string(where) + ": endpoint " + std::to_string(i) + " has no host");
      if (endpoints[i].port == 0)
        return fail(SHADOWTILE_ERROR_INVALID_ARGUMENT,
                    std::string(where) + ": endpoint " + std::to_string(i) + " has port 0");
      eps.push_back({endpoints[i].host, endpoints[i].port});
    }
    shadowtile_client_options o;
    shadowtile_client_options_default(&o);
    if (options) o = *options;
    if (o.key_size > 0 && !o.key) return null_argument(where, "options->key (key_size > 0)");
    st::client::ClientOptions co;
    co.cache_slots = o.cache_slots;
    co.cache_bytes = o.cache_bytes;
    co.max_slot_bytes = o.max_slot_bytes;
    co.want_capacity = o.want_capacity;
    co.max_in_flight = o.max_in_flight;
    co.tiles_per_request = o.tiles_per_request;
    co.max_frame_bytes = o.max_frame_bytes;
    co.max_tile_retries = o.max_tile_retries;
    co.miss_priority = o.miss_priority;
    co.connect_timeout = ms(o.connect_timeout_ms);
    co.io_timeout = ms(o.io_timeout_ms);
    co.request_timeout = ms(o.request_timeout_ms);
    co.backoff_initial = ms(o.backoff_initial_ms);
    co.backoff_max = ms(o.backoff_max_ms);
    if (o.client_name) co.client_name = o.client_name;
    if (o.key_size > 0) co.key.assign(o.key, o.key + o.key_size);
    co.tls = o.tls != 0;
    if (o.tls_ca_file) co.tls_ca_file = o.tls_ca_file;
    if (o.tls_server_name) co.tls_server_name = o.tls_server_name;
    // The constructor throws st::Error for bad options only (client.hpp).
    try {
      *out_client = new shadowtile_client{st::client::Client(std::move(eps), std::move(co))};
    } catch (const st::Error& e) {
      return fail(SHADOWTILE_ERROR_INVALID_ARGUMENT, std::string(where) + ": " + e.what());
    }
    return SHADOWTILE_OK;
  } catch (...) {
    return fail_current_exception(where);
  }
}

void shadowtile_client_destroy(shadowtile_client* client) { delete client; }

shadowtile_status shadowtile_client_get_stats(const shadowtile_client* client, shadowtile_client_stats* out) {
  constexpr const char* where = "shadowtile_client_get_stats";
  if (!client) return null_argument(where, "client");
  if (!out) return null_argument(where, "out_stats");
  const st::client::ClientStats s = client->client.stats();
  *out = shadowtile_client_stats{s.connects,      s.connect_failures, s.disconnects,     s.frames_received,
                                 s.bytes_received, s.bytes_sent,       s.protocol_errors, int32_t(s.connected),
                                 int32_t(s.refused)};
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_client_list_maps(shadowtile_client* client, shadowtile_map_listing** out_maps,
                                              size_t* out_count) {
  constexpr const char* where = "shadowtile_client_list_maps";
  if (!client) return null_argument(where, "client");
  if (!out_maps) return null_argument(where, "out_maps");
  if (!out_count) return null_argument(where, "out_count");
  try {
    const std::vector<st::client::MapListing> maps = client->client.list_maps();
    // One block: the array, then every string with its terminator (one free() frees all).
    size_t bytes = sizeof(shadowtile_map_listing) * std::max<size_t>(maps.size(), 1);
    for (const auto& m : maps) bytes += m.name.size() + 1 + m.encoding.size() + 1;
    void* block = std::malloc(bytes);
    if (!block) throw std::bad_alloc();
    auto* out = static_cast<shadowtile_map_listing*>(block);
    char* text = static_cast<char*>(block) + sizeof(shadowtile_map_listing) * std::max<size_t>(maps.size(), 1);
    auto put = [&text](const std::string& s) {
      char* p = text;
      std::memcpy(p, s.c_str(), s.size() + 1);
      text += s.size() + 1;
      return p;
    };
    for (size_t i = 0; i < maps.size(); ++i) {
      shadowtile_map_listing& l = out[i];
      l = shadowtile_map_listing{};
      l.name = put(maps[i].name);
      l.encoding = put(maps[i].encoding);
      l.resolution_log2 = maps[i].resolution_log2;
      l.skip_level = maps[i].skip_level;
      l.tile_count = maps[i].tile_count;
      l.pack_bytes = maps[i].pack_bytes;
    }
    *out_maps = out;
    *out_count = maps.size();
    return SHADOWTILE_OK;
  } catch (...) {
    return fail_current_exception(where);
  }
}

void shadowtile_free_map_listings(shadowtile_map_listing* maps) { std::free(maps); }

shadowtile_status shadowtile_client_open_map(shadowtile_client* client, const char* name, shadowtile_map** out_map) {
  constexpr const char* where = "shadowtile_client_open_map";
  if (!client) return null_argument(where, "client");
  if (!name) return null_argument(where, "name");
  if (!out_map) return null_argument(where, "out_map");
  try {
    auto* m = new shadowtile_map{client->client.open(name), {}, {}, {}, {}, {}};
    const st::client::MapInfo i = m->map.info();
    m->light = i.light;
    m->scene = i.scene;
    m->name = i.name;
    m->encoding = i.encoding;
    m->info.name = m->name.c_str();
    m->info.encoding = m->encoding.c_str();
    m->info.finest_level = i.finest_level;
    m->info.skip_level = i.skip_level;
    m->info.tile_bytes = i.tile_bytes;
    m->info.slices = m->map.slices();
    m->info.tile_count = i.tile_count;
    m->info.scene_hash = i.scene_hash;
    m->info.sun = i.sun ? 1 : 0;
    m->info.has_deep = m->map.has_deep() ? 1 : 0;
    *out_map = m;
    return SHADOWTILE_OK;
  } catch (...) {
    return fail_current_exception(where);
  }
}

// ---------------------------------------------------------------- map

void shadowtile_map_close(shadowtile_map* map) { delete map; }

shadowtile_status shadowtile_map_get_info(const shadowtile_map* map, shadowtile_map_info* out) {
  if (!map) return null_argument("shadowtile_map_get_info", "map");
  if (!out) return null_argument("shadowtile_map_get_info", "out_info");
  *out = map->info;
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_visibility(const shadowtile_map* map, const shadowtile_point* points, size_t count,
                                            uint32_t pcf_side, float* out) {
  if (shadowtile_status s = check_lookup("shadowtile_map_visibility", map, points, count, out, pcf_side))
    return s;
  for_each_chunk(points, count, [&](size_t i0, std::span<const st::client::WorldPoint> p) {
    map->map.visibility(p, std::span<float>(out + i0, p.size()), pcf_side);
  });
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_visibility_filtered(const shadowtile_map* map, const shadowtile_point* points,
                                                     const float* footprints, size_t count, uint32_t pcf_side,
                                                     float* out) {
  constexpr const char* where = "shadowtile_map_visibility_filtered";
  if (shadowtile_status s = check_lookup(where, map, points, count, out, pcf_side)) return s;
  if (count > 0 && !footprints) return null_argument(where, "footprints");
  for_each_chunk(points, count, [&](size_t i0, std::span<const st::client::WorldPoint> p) {
    map->map.visibility_filtered(p, std::span<const float>(footprints + i0, p.size()),
                                 std::span<float>(out + i0, p.size()), pcf_side);
  });
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_visibility_filtered_normal(const shadowtile_map* map, const shadowtile_point* points,
                                                            const shadowtile_point* normals, const float* footprints,
                                                            size_t count, uint32_t pcf_side, int closed, float* out) {
  constexpr const char* where = "shadowtile_map_visibility_filtered_normal";
  if (shadowtile_status s = check_lookup(where, map, points, count, out, pcf_side)) return s;
  if (count > 0 && !normals) return null_argument(where, "normals");
  if (count > 0 && !footprints) return null_argument(where, "footprints");
  for_each_chunk(points, count, [&](size_t i0, std::span<const st::client::WorldPoint> p) {
    for_each_chunk(normals + i0, p.size(), [&](size_t, std::span<const st::client::WorldPoint> nrm) {
      map->map.visibility_filtered(p, nrm, std::span<const float>(footprints + i0, p.size()),
                                   std::span<float>(out + i0, p.size()), pcf_side, closed != 0);
    });
  });
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_transmittance(const shadowtile_map* map, const shadowtile_point* points,
                                               const float* footprints, size_t count, shadowtile_rgb* out) {
  if (shadowtile_status s = check_lookup("shadowtile_map_transmittance", map, points, count, out, 1)) return s;
  for (size_t i = 0; i < count; ++i) {
    const st::client::WorldPoint p{points[i].x, points[i].y, points[i].z};
    const st::client::Transmittance t =
        footprints ? map->map.transmittance_filtered(p, footprints[i]) : map->map.transmittance(p);
    out[i] = shadowtile_rgb{t.r, t.g, t.b};
  }
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_request_region(shadowtile_map* map, uint32_t level, uint64_t x0, uint64_t y0,
                                                uint64_t w, uint64_t h, uint16_t priority, size_t* out_queued) {
  if (!map) return null_argument("shadowtile_map_request_region", "map");
  const size_t n = map->map.request_region(level, x0, y0, w, h, priority);
  if (out_queued) *out_queued = n;
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_cancel_outside(shadowtile_map* map, uint32_t level, uint64_t x0, uint64_t y0,
                                                uint64_t w, uint64_t h, size_t* out_cancelled) {
  if (!map) return null_argument("shadowtile_map_cancel_outside", "map");
  const size_t n = map->map.cancel_outside(level, x0, y0, w, h);
  if (out_cancelled) *out_cancelled = n;
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_region_resident(const shadowtile_map* map, uint32_t level, uint64_t x0, uint64_t y0,
                                                 uint64_t w, uint64_t h, int32_t* out_resident) {
  if (!map) return null_argument("shadowtile_map_region_resident", "map");
  if (!out_resident) return null_argument("shadowtile_map_region_resident", "out_resident");
  *out_resident = map->map.region_resident(level, x0, y0, w, h) ? 1 : 0;
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_get_stats(const shadowtile_map* map, shadowtile_map_stats* out) {
  if (!map) return null_argument("shadowtile_map_get_stats", "map");
  if (!out) return null_argument("shadowtile_map_get_stats", "out_stats");
  const st::client::MapStats s = map->map.stats();
  shadowtile_map_stats o{};
  o.cache_hits = s.cache.hits;
  o.cache_misses = s.cache.misses;
  o.cache_evictions = s.cache.evictions;
  o.cache_inserts = s.cache.inserts;
  o.slots_resident = s.cache.resident;
  o.slots_pinned = s.cache.pinned;
  o.slots_free = s.cache.free;
  o.tiles_requested = s.tiles_requested;
  o.tiles_received = s.tiles_received;
  o.bytes_received = s.bytes_received;
  o.crc_errors = s.crc_errors;
  o.decode_errors = s.decode_errors;
  o.tiles_failed = s.tiles_failed;
  o.tiles_cancelled = s.tiles_cancelled;
  o.cache_full = s.cache_full;
  o.queue_full = s.queue_full;
  o.coarse_answers = s.coarse_answers;
  o.dictionary_bytes = s.dictionary_bytes;
  *out = o;
  return SHADOWTILE_OK;
}

// ---------------------------------------------------------------- views

void shadowtile_view_options_default(shadowtile_view_options* o) {
  if (!o) return;
  const st::client::ViewOptions d;
  *o = shadowtile_view_options{d.samples_x, d.samples_y, d.receiver_height, d.max_distance, d.priority, {0, 0, 0},
                               d.time, d.lookahead};
}

namespace {
shadowtile_view_stats c_view_stats(const st::client::ViewStats& v) noexcept {
  return shadowtile_view_stats{v.wanted, v.kept, v.resident, v.queued, v.cancelled, v.ahead};
}
shadowtile_status invalid(const char* where, const char* what) noexcept {
  char buf[kMessageBytes];
  std::snprintf(buf, sizeof buf, "%s: %s", where, what);
  return fail(SHADOWTILE_ERROR_INVALID_ARGUMENT, buf);
}
}  // namespace

shadowtile_status shadowtile_map_request_view(shadowtile_map* map, uint32_t view_id, const double view_projection[16],
                                              uint32_t width, uint32_t height, const shadowtile_view_options* options,
                                              shadowtile_view_stats* out_stats) {
  constexpr const char* where = "shadowtile_map_request_view";
  if (!map) return null_argument(where, "map");
  if (!view_projection) return null_argument(where, "view_projection");
  st::client::ViewOptions o;
  if (options) {
    o.samples_x = options->samples_x;
    o.samples_y = options->samples_y;
    o.receiver_height = options->receiver_height;
    o.max_distance = options->max_distance;
    o.priority = options->priority;
    o.time = options->time;
    o.lookahead = options->lookahead;
  }
  // The reasons a caller can see here are named; the rest (a singular matrix, too many
  // views, a stack map) share the C++ API's one refusal.
  if (width == 0 || height == 0) return invalid(where, "the viewport is empty (width or height 0)");
  if (o.samples_x == 0 || o.samples_y == 0 || uint64_t(o.samples_x) * o.samples_y > st::client::kMaxViewSamples)
    return invalid(where, "samples_x * samples_y must be in 1..16384");
  for (int i = 0; i < 16; ++i)
    if (!std::isfinite(view_projection[i])) return invalid(where, "view_projection has a non-finite entry");
  const st::client::ViewStats v = map->map.request_view(view_id, view_projection, width, height, o);
  if (!v.ok)
    return invalid(where, map->map.slices() ? "views are not supported on stack maps"
                                            : "refused: the matrix is singular, or 16 other views are registered");
  if (out_stats) *out_stats = c_view_stats(v);
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_remove_view(shadowtile_map* map, uint32_t view_id, int32_t* out_removed) {
  if (!map) return null_argument("shadowtile_map_remove_view", "map");
  const bool removed = map->map.remove_view(view_id);
  if (out_removed) *out_removed = removed ? 1 : 0;
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_view_stats(const shadowtile_map* map, uint32_t view_id,
                                            shadowtile_view_stats* out_stats) {
  constexpr const char* where = "shadowtile_map_view_stats";
  if (!map) return null_argument(where, "map");
  if (!out_stats) return null_argument(where, "out_stats");
  const st::client::ViewStats v = map->map.view_stats(view_id);
  if (!v.ok) {
    char buf[kMessageBytes];
    std::snprintf(buf, sizeof buf, "%s: no view %u is registered", where, unsigned(view_id));
    return fail(SHADOWTILE_ERROR_NOT_FOUND, buf);
  }
  *out_stats = c_view_stats(v);
  return SHADOWTILE_OK;
}

// ---------------------------------------------------------------- the light

namespace {
shadowtile_point c_point(const st::client::WorldPoint& p) noexcept { return shadowtile_point{p.x, p.y, p.z}; }
st::client::WorldPoint cpp_point(const shadowtile_point& p) noexcept { return st::client::WorldPoint{p.x, p.y, p.z}; }
shadowtile_status check_array(const char* where, const shadowtile_map* map, const void* in, size_t count,
                              const void* out) noexcept {
  if (!map) return null_argument(where, "map");
  if (count > 0 && !in) return null_argument(where, "the input array");
  if (count > 0 && !out) return null_argument(where, "out");
  return SHADOWTILE_OK;
}
}  // namespace

shadowtile_status shadowtile_map_get_light(const shadowtile_map* map, shadowtile_light* out) {
  constexpr const char* where = "shadowtile_map_get_light";
  if (!map) return null_argument(where, "map");
  if (!out) return null_argument(where, "out_light");
  const st::client::LightTransform& l = map->light;
  shadowtile_light o{};
  o.kind = l.kind_id();
  o.orthographic = l.orthographic() ? 1 : 0;
  o.kind_name = l.kind_name();
  o.origin = c_point(l.origin());
  o.axis_u = c_point(l.axis_u());
  o.axis_v = c_point(l.axis_v());
  o.forward = c_point(l.forward());
  o.extent = l.extent();
  o.near_plane = l.near_plane();
  o.far_plane = l.far_plane();
  const st::client::WorldBox b = l.volume_bounds();
  o.volume_lo = c_point(b.lo);
  o.volume_hi = c_point(b.hi);
  const std::array<double, 18> a = l.to_array();
  std::copy(a.begin(), a.end(), o.params);
  *out = o;
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_to_light(const shadowtile_map* map, const shadowtile_point* points, size_t count,
                                          shadowtile_light_coord* out) {
  if (shadowtile_status s = check_array("shadowtile_map_to_light", map, points, count, out)) return s;
  for (size_t i = 0; i < count; ++i) {
    const st::client::LightCoord c = map->light.to_light(cpp_point(points[i]));
    out[i] = shadowtile_light_coord{c.u, c.v, c.d};
  }
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_to_world(const shadowtile_map* map, const shadowtile_light_coord* coords,
                                          size_t count, shadowtile_point* out) {
  if (shadowtile_status s = check_array("shadowtile_map_to_world", map, coords, count, out)) return s;
  for (size_t i = 0; i < count; ++i)
    out[i] = c_point(map->light.to_world(st::client::LightCoord{coords[i].u, coords[i].v, coords[i].d}));
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_texels(const shadowtile_map* map, uint32_t level, const shadowtile_point* points,
                                        size_t count, shadowtile_texel* out) {
  constexpr const char* where = "shadowtile_map_texels";
  if (shadowtile_status s = check_array(where, map, points, count, out)) return s;
  if (level > 30) return invalid(where, "level is above 30");
  for (size_t i = 0; i < count; ++i) {
    const st::client::Texel t = map->light.texel(level, cpp_point(points[i]));
    out[i] = shadowtile_texel{t.x, t.y};
  }
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_texel_size(const shadowtile_map* map, uint32_t level, const shadowtile_point* points,
                                            size_t count, double* out) {
  constexpr const char* where = "shadowtile_map_texel_size";
  if (shadowtile_status s = check_array(where, map, points, count, out)) return s;
  if (level > 30) return invalid(where, "level is above 30");
  for (size_t i = 0; i < count; ++i) out[i] = map->light.texel_size(cpp_point(points[i]), level);
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_get_scene_extent(const shadowtile_map* map, shadowtile_scene_extent* out) {
  if (!map) return null_argument("shadowtile_map_get_scene_extent", "map");
  if (!out) return null_argument("shadowtile_map_get_scene_extent", "out_extent");
  const st::client::SceneExtent& e = map->scene;
  *out = shadowtile_scene_extent{c_point(e.bounds.lo), c_point(e.bounds.hi), e.ground, e.top, e.x0, e.x1, e.z0, e.z1,
                                 e.points};
  return SHADOWTILE_OK;
}

shadowtile_status shadowtile_map_get_budget(const shadowtile_map* map, shadowtile_map_budget* out) {
  if (!map) return null_argument("shadowtile_map_get_budget", "map");
  if (!out) return null_argument("shadowtile_map_get_budget", "out_budget");
  const st::client::MapStats s = map->map.stats();
  *out = shadowtile_map_budget{s.dictionary_bytes,  s.accounted_bytes, s.dictionary_slots,  s.tile_slots,
                               s.views,             s.view_slots,      s.view_tiles_wanted, s.view_tiles_over,
                               s.view_overflows,    s.view_refetches};
  return SHADOWTILE_OK;
}

}  // extern "C"

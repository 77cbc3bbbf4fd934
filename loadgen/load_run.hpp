// The load tester's runner: N synthetic cameras over C client connections
// (camera i uses connection i % C; cameras on one connection share its map and cache,
// like several views of one game), each on its own frame clock. The cameras' frames run
// on a few worker threads and the connections' fetchers on a shared client::IoPool, so
// 1,000 cameras on 1,000 connections are a handful of threads (the soak, LOAD.md).
//
// No coordinated omission: frame f of every camera is scheduled at start + f / rate and
// its requests go out then whether or not earlier answers came back (request_region
// never blocks); a frame that starts late still counts from its scheduled time.
//
// Per frame a camera (1) casts its screen samples (client::Map::view_samples) and, on a 2D
// map, registers its view (Map::request_view) with the frame's time, so that the library
// asks for its pixels' tiles nearest first and for those of its poses up to kLookahead
// seconds ahead from its motion (a cut starts without a time: a real client cannot see a
// teleport coming); a stack map's camera asks for its slices and (2) prefetches those
// kPrefetchAhead seconds on, every kPrefetchEvery frames (camera c at frames f with
// (f + c) % kPrefetchEvery == 0, so a fleet does not prefetch in lockstep); (3) checks
// which needed cells are not
// resident (a frame with holes: its lookups answered from coarser levels) and (4)
// evaluates map.visibility_filtered at every receiver sample (its pixel footprint picks
// the levels, MH §3.3).
//
// Latency of a cell: from the scheduled time of the first frame that needed it while it
// was not resident, to the moment a watcher thread (polling every millisecond) sees it
// resident. Time to full residency after a cut: from the cut frame's scheduled time until
// every cell that frame needed is resident.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "shadowtile/client.hpp"
#include "loadgen/camera_path.hpp"
#include "loadgen/view_tiles.hpp"

namespace st::loadgen {

struct LoadOptions {
  client::Endpoint endpoint;
  // Further replicas of the same server: the clients spread over {endpoint, replicas...}
  // and fail over between them (client.hpp, Client(std::vector<Endpoint>, ...)).
  std::vector<client::Endpoint> replicas;
  std::string map;
  std::vector<uint8_t> key;  // the catalog key, when the server requires one
  bool tls = false;          // client::ClientOptions::tls and its CA file / expected name
  std::string tls_ca_file, tls_server_name;
  uint32_t cameras = 4;
  uint32_t connections = 0;  // 0: one per camera; clamped to [1, cameras]
  PathKind path = PathKind::flyover;
  double duration = 10;      // seconds
  double rate = 60;          // frames per second per camera
  double cache_mb = 64;      // tile cache per connection
  uint64_t seed = 1;
  bool prefetch = true;
  uint32_t workers = 0;      // camera threads (0: max(2, cores)); cameras are spread over them
  uint32_t io_threads = 2;   // client I/O threads shared by every connection (client::IoPool)
  ViewOptions view;
  // Stack maps (a pack with a light set, MH 2016 §4; ignored on 2D maps): each camera's
  // time runs from time0 at the start to time1 at `duration` (time0 == time1: a fixed
  // --time); per frame it asks request_slices for the two slices around its time (and,
  // when prefetching, those around its time kPrefetchAhead seconds on), a frame whose
  // slices are not all resident has holes, and the lookups are
  // time_visibility_filtered(point, time, footprint). soft: every slice is needed and the
  // lookups are soft_visibility_filtered (an area light's soft shadow).
  double time0 = 0, time1 = 0;
  bool soft = false;
};

// The slices [first, last] a stack lookup at `time` reads (StackMap::visibility:
// s = time * (N - 1); the two around s, one at a sample).
void time_slices(double time, uint32_t slices, uint32_t& first, uint32_t& last);
// A stack map's world frame (camera paths over it): the level-a map of slice 0 (a <= the
// skip level's x, y resolution, so no tile is read) in place of the 2D skip grid.
// A map's world frame from its public MapInfo (light and scene extent): a stack map's
// from its first slice (client.hpp MapInfo::light).
WorldFrame map_world_frame(const client::Map& m);
inline WorldFrame stack_world_frame(const client::Map& m) { return map_world_frame(m); }

inline constexpr double kPrefetchAhead[] = {0.25, 0.5, 1.0};  // seconds
inline constexpr uint64_t kPrefetchEvery = 6;                   // frames between prefetch rounds
// How far ahead each camera's view looks from its motion (client::ViewOptions::lookahead).
inline constexpr double kLookahead = 0.25;  // seconds

struct SeriesPoint {
  double t = 0;                 // seconds since start
  uint64_t tiles_received = 0;  // cumulative, all connections
  uint64_t frames = 0, frames_with_holes = 0;
  uint64_t bytes = 0;
};

// A frame's work on its camera thread, from the moment it starts (after any sleep until
// its schedule) to its end: the view's samples, the requests, the residency checks and the
// shadow lookups, what a game's frame spends on shadows. Kept as a histogram (8 buckets an
// octave from 1 us, about 9% wide) so that a soak of hours stays bounded; the maximum and
// the mean are exact, the percentiles the upper edge of their bucket.
struct FrameTimes {
  static constexpr int kBucketsPerOctave = 8, kOctaves = 25;  // 1 us .. 2^25 us (33 s)
  std::array<uint64_t, kBucketsPerOctave * kOctaves> counts{};
  uint64_t frames = 0;
  double sum_ms = 0, max_ms = 0;
  void add(double ms);
  void merge(const FrameTimes& o);
  double mean_ms() const { return frames ? sum_ms / double(frames) : 0; }
  double percentile_ms(double p) const;  // p in [0, 1]; 1 is the exact maximum
};

struct LoadResult {
  LoadOptions options;
  uint32_t connections = 0, map_level = 0, skip_level = 0, cache_slots = 0, slot_bytes = 0;
  uint32_t slices = 0;  // a stack map's N (0: a 2D map); its cells in the table count slices
  double wall_seconds = 0;
  uint64_t frames = 0, frames_with_holes = 0, frames_late = 0;  // late: started > 1 frame after schedule
  // Frames with holes while the camera's last cut was already fully resident (moving
  // along the path, not filling a new view): what prefetch is meant to drive to zero.
  uint64_t frames_with_holes_steady = 0;
  double max_lag_ms = 0;
  uint64_t cells_needed = 0, cells_missing = 0;  // summed over frames
  uint64_t samples = 0, lookups = 0;
  double lookup_seconds = 0;
  double mean_visibility = 0;
  client::MapStats map;        // summed over connections (after the final cancel)
  client::ClientStats client;  // summed
  uint32_t peak_slots_used = 0;  // most resident + pinned slots seen on any connection (100 ms samples)
  uint32_t workers = 0;          // camera threads used
  double watcher_poll_ms_max = 0;  // coarsest residency poll (latency resolution)
  bool drained = false;          // every sent request answered or cancelled at the end
  std::vector<double> latency_ms;         // one per cell that became resident
  uint64_t latency_abandoned = 0;         // needed cells no longer needed before arriving
  std::vector<double> cut_residency_ms;   // one per completed cut
  uint64_t cuts = 0, cuts_incomplete = 0; // cut superseded by the next or by the run's end
  std::vector<SeriesPoint> series;        // every 100 ms
  WorldFrame world;
  FrameTimes frame_times;  // every frame's work (FrameTimes)
  // A stack map swept in time: the frames that read a slice their camera's previous frame
  // did not (the sun crossed into the next slice), their work and how many had holes. A
  // hitch at a crossing shows as their maximum above the other frames'.
  FrameTimes crossing_times;
  uint64_t crossing_holes = 0;

  uint64_t frames_skipped = 0;  // not run: their time had passed the duration by over a second (a stalled run ends on time)
  // Tiles were asked for and none ever came (a server that answers nothing, or only
  // under wrong ids): the run measured nothing, whatever the counters below say.
  bool no_tile_received() const { return map.tiles_requested > 0 && map.tiles_received == 0; }
  uint64_t errors() const {
    return map.crc_errors + map.decode_errors + map.tiles_failed + map.tiles_unanswered + client.protocol_errors +
           client.connect_failures + (no_tile_received() ? 1 : 0);
  }
  double hole_fraction() const { return frames ? double(frames_with_holes) / double(frames) : 0; }
  double cache_hit_rate() const {
    const uint64_t n = map.cache.hits + map.cache.misses;
    return n ? double(map.cache.hits) / double(n) : 0;
  }
};

// Runs the load; throws st::Error if the map cannot be opened (server down or unknown
// map) within the client's request timeout.
LoadResult run_load(const LoadOptions& options);

// Percentile p in [0, 1] of `v` (sorted copy; 0 for empty).
double percentile_of(std::vector<double> v, double p);

}  // namespace st::loadgen

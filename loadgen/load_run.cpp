#include "loadgen/load_run.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>

#include "common/error.hpp"

namespace st::loadgen {

using Clock = std::chrono::steady_clock;

// The synthetic cameras' clip planes (request_view uses only their rays).
constexpr double kNearPlane = 0.1, kFarPlane = 1e6;
uint32_t display_w(const ViewOptions& v) { return uint32_t(std::max(1.0, v.display_width)); }
uint32_t display_h(const ViewOptions& v) { return uint32_t(std::max(1.0, v.display_width / Camera{}.aspect)); }
client::ViewOptions view_options(const WorldFrame& world, const ViewOptions& v, uint16_t priority) {
  client::ViewOptions o;
  o.samples_x = v.samples_x, o.samples_y = v.samples_y;
  o.receiver_height = world.ground;
  o.max_distance = v.max_distance > 0 ? v.max_distance : 1.5 * world.span();
  o.priority = priority;
  return o;
}

void time_slices(double time, uint32_t slices, uint32_t& first, uint32_t& last) {
  if (slices == 0) {
    first = last = 0;
    return;
  }
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(slices - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) {
    first = last = uint32_t(near);
    return;
  }
  first = uint32_t(std::floor(s));
  last = std::min(first + 1, slices - 1);
}

double percentile_of(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double pos = p * double(v.size() - 1);
  const size_t i = size_t(pos);
  if (i + 1 >= v.size()) return v.back();
  return v[i] + (v[i + 1] - v[i]) * (pos - double(i));
}

void FrameTimes::add(double ms) {
  ++frames;
  sum_ms += ms;
  max_ms = std::max(max_ms, ms);
  const double us = std::max(1.0, ms * 1000);
  const int b = std::min(int(counts.size()) - 1, int(std::floor(std::log2(us) * kBucketsPerOctave)));
  ++counts[size_t(b)];
}

void FrameTimes::merge(const FrameTimes& o) {
  for (size_t i = 0; i < counts.size(); ++i) counts[i] += o.counts[i];
  frames += o.frames, sum_ms += o.sum_ms, max_ms = std::max(max_ms, o.max_ms);
}

double FrameTimes::percentile_ms(double p) const {
  if (!frames) return 0;
  if (p >= 1) return max_ms;
  const uint64_t rank = uint64_t(std::ceil(std::clamp(p, 0.0, 1.0) * double(frames)));
  uint64_t seen = 0;
  for (size_t i = 0; i < counts.size(); ++i) {
    seen += counts[i];
    if (seen >= std::max<uint64_t>(rank, 1))  // the last bucket holds everything above it: its edge is the maximum
      return i + 1 == counts.size() ? max_ms : std::min(max_ms, std::exp2(double(i + 1) / kBucketsPerOctave) / 1000);
  }
  return max_ms;
}

namespace {

std::vector<client::Endpoint> all_endpoints(const LoadOptions& o) {
  std::vector<client::Endpoint> v{o.endpoint};
  v.insert(v.end(), o.replicas.begin(), o.replicas.end());
  return v;
}

double time_at(const LoadOptions& o, double t) {
  return o.time0 + (o.time1 - o.time0) * std::clamp(t / o.duration, 0.0, 1.0);
}

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

struct Pending {
  CellNeed cell;
  Clock::time_point first_needed, last_needed;
};

struct CutTrack {
  bool active = false;
  Clock::time_point scheduled;
  std::vector<CellNeed> cells;
};

// Everything the camera threads and the watcher share, under one mutex (touched a few
// times per frame: the lookups themselves never take it).
struct Shared {
  std::mutex mu;
  std::vector<std::unordered_map<uint64_t, Pending>> pending;  // per connection
  std::vector<CutTrack> cuts;                                  // per camera
  std::vector<uint32_t> camera_conn;
  std::vector<double> latency_ms, cut_ms;
  uint64_t abandoned = 0, cut_count = 0, cuts_incomplete = 0, holes_steady = 0;
  // Per-camera frame counters (summed at the end and for the series).
  std::atomic<uint64_t> frames{0}, holes{0}, late{0}, needed{0}, missing{0}, samples{0}, lookups{0};
  std::atomic<uint64_t> lookup_ns{0};
  std::atomic<uint64_t> skipped{0};  // frames not run: the run was past its duration + 1 s
  std::mutex lag_mu;
  double max_lag_ms = 0, visibility_sum = 0;
  FrameTimes frame_times, crossing_times;  // under lag_mu
  uint64_t crossing_holes = 0;
};

// A stack map's need is one slice: cell_level kSliceNeed, cx the slice.
constexpr uint32_t kSliceNeed = 63;

// A camera's view (Map::request_view): cell_level kViewNeed, cx the view id.
constexpr uint32_t kViewNeed = 62;

bool resident(const client::Map& m, const CellNeed& c) {
  if (c.cell_level == kSliceNeed) return m.slices_resident(uint32_t(c.cx), uint32_t(c.cx));
  if (c.cell_level == kViewNeed) {
    const client::ViewStats s = m.view_stats(uint32_t(c.cx));
    return !s.ok || s.resident == s.kept;  // a view removed needs nothing
  }
  return m.region_resident(c.level, c.x0(), c.y0(), c.side(), c.side());
}

CellNeed view_need(uint32_t id) {
  CellNeed c;
  c.level = c.cell_level = kViewNeed;
  c.cx = id;
  return c;
}

CellNeed slice_need(uint32_t w) {
  CellNeed c;
  c.level = c.cell_level = kSliceNeed;
  c.cx = w;
  return c;
}

}  // namespace

WorldFrame map_world_frame(const client::Map& m) {
  const client::MapInfo info = m.info();
  const LightSpace light = LightSpace::from_array(LightKind(info.light.kind_id()), info.light.to_array());
  SurfaceExtent e;
  e.ground = info.scene.ground, e.top = info.scene.top;
  e.x0 = info.scene.x0, e.x1 = info.scene.x1, e.z0 = info.scene.z0, e.z1 = info.scene.z1;
  return world_frame(light, e);
}

namespace {

// One camera's frame clock and path state. Workers (a few threads, not one per camera)
// run the frames of their cameras in schedule order.
struct CameraRun {
  uint32_t id = 0;
  CameraPath path;
  client::Map map;
  uint32_t view_id = 0;                // its view on its connection's map (2D maps)
  Clock::time_point first;             // schedule of frame 0 (start + phase)
  uint64_t next_frame = 0, frames = 0;
  uint64_t prev_segment = ~uint64_t(0);
  uint32_t prev_w0 = 0, prev_w1 = 0;  // the slices its previous frame read (stack maps)

  Clock::time_point schedule(double rate, uint64_t f) const {
    return first + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(double(f) / rate));
  }
};

// Runs frame `cam.next_frame` (its scheduled time has come) and advances it.
void camera_frame(CameraRun& cam, const LoadOptions& o, const WorldFrame& world, Shared& sh) {
  client::Map& map = cam.map;
  const uint32_t conn = sh.camera_conn[cam.id];
  const uint64_t f = cam.next_frame++;
  const double t = double(f) / o.rate;
  const auto sched = cam.schedule(o.rate, f);
  const auto began = Clock::now();
  const double lag = ms_between(sched, began);
  if (lag > 1000.0 / o.rate) sh.late.fetch_add(1, std::memory_order_relaxed);

  const CameraPath& path = cam.path;
  const uint64_t seg = path.segment(t);
  const bool cut = seg != cam.prev_segment;
  cam.prev_segment = seg;
  // The frame's receivers: the camera's screen samples on the ground (the client casts
  // them, the same rays request_view casts), each with its pixel's footprint.
  client::ViewOptions vo = view_options(world, o.view, 60000);
  // A camera that moves on (no cut) tells the library its frame time: the view asks for
  // the tiles of its poses ahead too (look-ahead from its motion); a cut is a new camera.
  vo.time = cut ? std::numeric_limits<double>::quiet_NaN() : t;
  vo.lookahead = o.prefetch ? kLookahead : 0;
  const auto vp = view_projection(path.at(t), kNearPlane, kFarPlane);
  std::vector<client::ViewSample> samples(size_t(o.view.samples_x) * o.view.samples_y);
  samples.resize(map.view_samples(vp.data(), display_w(o.view), display_h(o.view), vo, samples));
  std::vector<CellNeed> cells;
  const uint32_t slices = map.slices();
  const double time = time_at(o, t);
  bool crossing = false;  // reads a slice the previous frame did not
  if (slices) {
    // A stack map: the slices around the camera's time now, then (prefetch) those around
    // its time ahead; the view's 2D cells mean nothing here.
    uint32_t w0 = 0, w1 = slices - 1;
    if (!o.soft) time_slices(time, slices, w0, w1);
    crossing = f > 0 && (w0 < cam.prev_w0 || w1 > cam.prev_w1);
    cam.prev_w0 = w0, cam.prev_w1 = w1;
    for (uint32_t w = w0; w <= w1; ++w) cells.push_back(slice_need(w));
    map.request_slices(w0, w1, 60000);
    if (o.prefetch && !o.soft && (cut || (f + cam.id) % kPrefetchEvery == 0))
      for (size_t k = 0; k < std::size(kPrefetchAhead); ++k) {
        uint32_t a0, a1;
        time_slices(time_at(o, t + kPrefetchAhead[k]), slices, a0, a1);
        map.request_slices(a0, a1, uint16_t(40000 - 10000 * k));
      }
  } else {
    // A 2D map: the camera is a view (client.hpp Map::request_view): the library finds the
    // tiles its pixels need, nearest first, keeps them resident while in view, cancels what
    // leaves every view and, from the frame times, asks for the tiles of the poses ahead.
    map.request_view(cam.view_id, vp.data(), display_w(o.view), display_h(o.view), vo);
    cells.push_back(view_need(cam.view_id));
  }

  // Evaluation: which needed cells are resident, then the shadow lookups.
  std::vector<CellNeed> missing;
  for (const CellNeed& c : cells)
    if (!resident(map, c)) missing.push_back(c);
  // One batched call per frame, as a game would make it (client.hpp).
  std::vector<client::WorldPoint> points(samples.size());
  std::vector<float> footprints(samples.size()), answers(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) points[i] = samples[i].point, footprints[i] = samples[i].footprint;
  const auto t0 = Clock::now();
  // Filtered at each sample's footprint (MH §3.3: the level from the pixel, two levels
  // blended), as a renderer that does not alias in the distance would ask.
  if (!slices) {
    map.visibility_filtered(points, footprints, answers, 1);
  } else {
    for (size_t i = 0; i < points.size(); ++i)
      answers[i] = o.soft ? map.soft_visibility_filtered(points[i], footprints[i])
                          : map.time_visibility_filtered(points[i], time, footprints[i]);
  }
  const auto t1 = Clock::now();
  double vis = 0;
  for (float v : answers) vis += v;
  sh.lookup_ns.fetch_add(uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(t1 - t0).count()),
                         std::memory_order_relaxed);
  sh.lookups.fetch_add(points.size(), std::memory_order_relaxed);
  sh.samples.fetch_add(uint64_t(o.view.samples_x) * o.view.samples_y, std::memory_order_relaxed);
  sh.needed.fetch_add(cells.size(), std::memory_order_relaxed);
  sh.missing.fetch_add(missing.size(), std::memory_order_relaxed);
  if (!missing.empty()) sh.holes.fetch_add(1, std::memory_order_relaxed);
  {
    std::lock_guard lock(sh.mu);
    auto& pend = sh.pending[conn];
    for (const CellNeed& c : missing) {
      auto [it, fresh] = pend.try_emplace(c.key() ^ (uint64_t(c.level) << 52), Pending{c, sched, sched});
      if (!fresh) it->second.last_needed = sched;
    }
    if (!missing.empty() && !cut && !sh.cuts[cam.id].active) ++sh.holes_steady;
    if (cut) {
      CutTrack& ct = sh.cuts[cam.id];
      if (ct.active) ++sh.cuts_incomplete;
      ++sh.cut_count;
      ct.active = true;
      ct.scheduled = sched;
      ct.cells = missing;
      if (ct.cells.empty()) {
        sh.cut_ms.push_back(ms_between(sched, Clock::now()));
        ct.active = false;
      }
    }
  }
  const double work_ms = ms_between(began, Clock::now());
  {
    std::lock_guard lock(sh.lag_mu);
    sh.max_lag_ms = std::max(sh.max_lag_ms, lag);
    sh.visibility_sum += vis;
    sh.frame_times.add(work_ms);
    if (crossing) {
      sh.crossing_times.add(work_ms);
      sh.crossing_holes += !missing.empty();
    }
  }
  sh.frames.fetch_add(1, std::memory_order_relaxed);
}

// A worker runs its cameras' frames, always the one scheduled earliest next (a frame
// that starts late still counts from its schedule: no coordinated omission).
void worker_loop(std::vector<CameraRun*> cams, const LoadOptions& o, const WorldFrame& world, Shared& sh,
                 Clock::time_point end) {
  auto later = [&](const CameraRun* a, const CameraRun* b) {
    return a->schedule(o.rate, a->next_frame) > b->schedule(o.rate, b->next_frame);
  };
  std::erase_if(cams, [](const CameraRun* c) { return c->frames == 0; });
  std::make_heap(cams.begin(), cams.end(), later);
  while (!cams.empty()) {
    std::pop_heap(cams.begin(), cams.end(), later);
    CameraRun& cam = *cams.back();
    if (Clock::now() > end) {  // stalled (frames slower than the rate): the duration holds
      sh.skipped.fetch_add(cam.frames - cam.next_frame, std::memory_order_relaxed);
      cams.pop_back();
      continue;
    }
    std::this_thread::sleep_until(cam.schedule(o.rate, cam.next_frame));
    camera_frame(cam, o, world, sh);
    if (cam.next_frame < cam.frames) std::push_heap(cams.begin(), cams.end(), later);
    else cams.pop_back();
  }
}

void add(client::MapStats& a, const client::MapStats& b) {
  a.cache.hits += b.cache.hits, a.cache.misses += b.cache.misses;
  a.cache.evictions += b.cache.evictions, a.cache.inserts += b.cache.inserts;
  a.cache.resident += b.cache.resident, a.cache.pinned += b.cache.pinned, a.cache.free += b.cache.free;
  a.tiles_requested += b.tiles_requested, a.tiles_received += b.tiles_received;
  a.bytes_received += b.bytes_received, a.crc_errors += b.crc_errors, a.decode_errors += b.decode_errors;
  a.tiles_failed += b.tiles_failed, a.tiles_cancelled += b.tiles_cancelled, a.cache_full += b.cache_full;
  a.queue_full += b.queue_full, a.coarse_answers += b.coarse_answers;
  a.tiles_unanswered += b.tiles_unanswered, a.accounted_bytes += b.accounted_bytes;
  a.views += b.views, a.view_slots = b.view_slots;  // per connection: the same on each
  a.view_tiles_wanted += b.view_tiles_wanted, a.view_tiles_over += b.view_tiles_over;
  a.view_overflows += b.view_overflows, a.view_refetches += b.view_refetches;
}

void add(client::ClientStats& a, const client::ClientStats& b) {
  a.connects += b.connects, a.connect_failures += b.connect_failures, a.disconnects += b.disconnects;
  a.frames_received += b.frames_received, a.bytes_received += b.bytes_received, a.bytes_sent += b.bytes_sent;
  a.protocol_errors += b.protocol_errors;
}

}  // namespace

LoadResult run_load(const LoadOptions& o_in) {
  LoadOptions o = o_in;
  if (o.cameras == 0) throw Error("load: --cameras must be at least 1");
  if (!(o.rate > 0 && o.rate <= 1000)) throw Error("load: --rate must be in (0, 1000]");
  if (!(o.duration > 0)) throw Error("load: --duration must be positive");
  if (!(o.cache_mb > 0)) throw Error("load: --cache-mb must be positive");
  if (!(o.time0 >= 0 && o.time0 <= 1 && o.time1 >= 0 && o.time1 <= 1))
    throw Error("load: --time / --time-sweep must lie in [0, 1]");
  LoadResult r;
  r.connections = o.connections == 0 ? o.cameras : std::clamp(o.connections, 1u, o.cameras);

  client::ClientOptions co;
  co.client_name = "shadowtile-load";
  co.key = o.key;
  co.tls = o.tls;
  co.tls_ca_file = o.tls_ca_file;
  co.tls_server_name = o.tls_server_name;
  // The library's one rule (client.hpp cache_bytes): metadata and everything per slot
  // within --cache-mb, whatever the pack's tile bound; a budget too small for one slot
  // is refused by open() in one line.
  co.cache_bytes = uint64_t(o.cache_mb * 1048576.0);
  // Every connection's fetcher on a few shared I/O threads (not one thread per
  // connection: 1,000 connections stay 1,000 sockets, not 1,000 threads).
  co.io_pool = client::make_io_pool(std::clamp(o.io_threads, 1u, 64u));
  std::vector<std::unique_ptr<client::Client>> clients;
  std::vector<client::Map> maps;
  for (uint32_t i = 0; i < r.connections; ++i) {
    clients.push_back(std::make_unique<client::Client>(all_endpoints(o), co));
    maps.push_back(clients.back()->open(o.map));
  }
  const client::Map& m0 = maps[0];
  r.map_level = m0.finest_level();
  r.skip_level = m0.info().skip_level;
  {
    const client::MapStats s0 = m0.stats();
    r.cache_slots = s0.cache.resident + s0.cache.pinned + s0.cache.free;
  }
  r.slot_bytes = m0.slot_bytes();
  r.slices = m0.slices();
  r.world = map_world_frame(m0);

  Shared sh;
  sh.pending.resize(r.connections);
  sh.cuts.resize(o.cameras);
  for (uint32_t c = 0; c < o.cameras; ++c) sh.camera_conn.push_back(c % r.connections);

  const auto start = Clock::now() + std::chrono::milliseconds(20);
  std::atomic<bool> stop{false};
  std::thread watcher([&] {
    auto next_sample = start;
    auto poll = std::chrono::microseconds(1000);
    while (!stop.load()) {
      std::this_thread::sleep_for(poll);
      const auto now = Clock::now();
      {
        std::lock_guard lock(sh.mu);
        for (uint32_t c = 0; c < r.connections; ++c) {
          auto& pend = sh.pending[c];
          for (auto it = pend.begin(); it != pend.end();) {
            if (resident(maps[c], it->second.cell)) {
              sh.latency_ms.push_back(ms_between(it->second.first_needed, now));
              it = pend.erase(it);
            } else if (now - it->second.last_needed > std::chrono::seconds(1)) {
              ++sh.abandoned;  // the cameras moved on before it arrived
              it = pend.erase(it);
            } else {
              ++it;
            }
          }
        }
        for (uint32_t cam = 0; cam < o.cameras; ++cam) {
          CutTrack& ct = sh.cuts[cam];
          if (!ct.active) continue;
          const client::Map& m = maps[sh.camera_conn[cam]];
          std::erase_if(ct.cells, [&](const CellNeed& c) { return resident(m, c); });
          if (ct.cells.empty()) {
            sh.cut_ms.push_back(ms_between(ct.scheduled, now));
            ct.active = false;
          }
        }
      }
      // With hundreds of connections one pass costs more than a millisecond: poll at
      // most ~10% of the time (latency resolution then coarser than 1 ms; kept in the
      // result as watcher_poll_ms_max).
      const auto pass = std::chrono::duration_cast<std::chrono::microseconds>(Clock::now() - now);
      poll = std::clamp(pass * 10, std::chrono::microseconds(1000), std::chrono::microseconds(50000));
      r.watcher_poll_ms_max = std::max(r.watcher_poll_ms_max, double(poll.count()) / 1000.0);
      if (now >= next_sample) {
        SeriesPoint p;
        p.t = std::chrono::duration<double>(now - start).count();
        for (const client::Map& m : maps) {
          const client::MapStats s = m.stats();
          p.tiles_received += s.tiles_received;
          p.bytes += s.bytes_received;
          r.peak_slots_used = std::max(r.peak_slots_used, s.cache.resident + s.cache.pinned);
        }
        p.frames = sh.frames.load();
        p.frames_with_holes = sh.holes.load();
        r.series.push_back(p);
        next_sample += std::chrono::milliseconds(100);
      }
    }
  });

  // Cameras: a few worker threads, camera c on worker c % workers; frame 0 of camera c
  // is scheduled c / cameras of a frame after the start (a staggered fleet, not a
  // synchronized burst every frame).
  const uint64_t frames_per_camera = uint64_t(std::floor(o.duration * o.rate));
  std::vector<CameraRun> cameras;
  cameras.reserve(o.cameras);
  for (uint32_t c = 0; c < o.cameras; ++c) {
    const uint32_t conn = sh.camera_conn[c];
    const double phase = double(c) / double(o.cameras) / o.rate;
    // One view per camera (client::kMaxViews per connection; the look-ahead is the
    // view's own, from its frame times).
    cameras.push_back(CameraRun{c, CameraPath(o.path, r.world, o.seed, c), maps[conn], c / r.connections,
                                start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(phase)),
                                0, frames_per_camera});
  }
  const uint32_t workers = std::clamp(o.workers == 0 ? std::max(2u, std::thread::hardware_concurrency()) : o.workers,
                                      1u, o.cameras);
  r.workers = workers;
  std::vector<std::vector<CameraRun*>> assigned(workers);
  for (uint32_t c = 0; c < o.cameras; ++c) assigned[c % workers].push_back(&cameras[c]);
  std::vector<std::thread> pool;
  for (uint32_t w = 0; w < workers; ++w)
    pool.emplace_back(worker_loop, std::move(assigned[w]), std::cref(o), std::cref(r.world), std::ref(sh),
                      start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.duration + 1)));
  for (auto& t : pool) t.join();
  const auto end = Clock::now();
  // Let the watcher record the last arrivals of the final frames' needs briefly, then
  // stop and cancel whatever is still queued or in flight.
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  stop = true;
  watcher.join();
  r.wall_seconds = std::chrono::duration<double>(end - start).count();
  for (client::Map& m : maps) m.cancel_outside(r.map_level, 0, 0, 0, 0);
  const auto drain_deadline = Clock::now() + std::chrono::seconds(5);
  for (;;) {
    bool all = true;
    for (const client::Map& m : maps) {
      const client::MapStats s = m.stats();
      all = all && s.tiles_requested == s.tiles_received + s.tiles_cancelled + s.tiles_failed;
    }
    if (all || Clock::now() > drain_deadline) {
      r.drained = all;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  for (const client::Map& m : maps) {
    const client::MapStats s = m.stats();
    r.peak_slots_used = std::max(r.peak_slots_used, s.cache.resident + s.cache.pinned);
    add(r.map, s);
  }
  for (const auto& c : clients) add(r.client, c->stats());

  r.options = o;
  r.frames = sh.frames, r.frames_with_holes = sh.holes, r.frames_late = sh.late;
  r.frames_skipped = sh.skipped;
  r.cells_needed = sh.needed, r.cells_missing = sh.missing;
  r.samples = sh.samples, r.lookups = sh.lookups;
  r.lookup_seconds = double(sh.lookup_ns.load()) * 1e-9;
  r.mean_visibility = r.lookups ? sh.visibility_sum / double(r.lookups) : 0;
  r.max_lag_ms = sh.max_lag_ms;
  r.frame_times = sh.frame_times, r.crossing_times = sh.crossing_times, r.crossing_holes = sh.crossing_holes;
  r.latency_ms = std::move(sh.latency_ms);
  r.latency_abandoned = sh.abandoned;
  r.cut_residency_ms = std::move(sh.cut_ms);
  r.cuts = sh.cut_count;
  r.frames_with_holes_steady = sh.holes_steady;
  r.cuts_incomplete = sh.cuts_incomplete;
  for (const CutTrack& ct : sh.cuts)
    if (ct.active) ++r.cuts_incomplete;
  return r;
}

}  // namespace st::loadgen

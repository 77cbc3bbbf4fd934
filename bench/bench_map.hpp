// Shared by bench/encodings.cpp and bench/lookups.cpp (header only: bench/CMakeLists.txt
// makes one executable per *.cpp): a scene's map built tile by tile the way the paper
// builds big maps (MH §3.1 "Tiled construction": trace 4096^2 tiles with Embree, build
// each tile's hierarchy bottom-up, stitch the tiles' roots), timing helpers, and the
// finest-level values of a hierarchy painted into a flat float array.
#pragma once
#include "tiles/core/resolution.hpp"
#include <sys/mman.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "common/error.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"
#include "tiles/encode/mh_build.hpp"
#include "bench/timing.hpp"

namespace st::bench {

inline uint32_t parse_level(const std::string& s) { return parse_resolution(s); }

inline std::string side_name(uint32_t level) {
  uint64_t n = uint64_t(1) << level;
  return n >= 1024 ? std::to_string(n / 1024) + "K" : std::to_string(n);
}

inline double load_average() {
  double l[1] = {0};
  return getloadavg(l, 1) == 1 ? l[0] : -1;
}

inline std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  size_t p = 0;
  while (p <= s.size()) {
    size_t q = s.find(',', p);
    if (q == std::string::npos) q = s.size();
    if (q > p) out.push_back(s.substr(p, q - p));
    p = q + 1;
  }
  return out;
}

inline constexpr uint32_t kTileSide = 4096;  // traced and built per call (map_build's kMaxTraceSide)

// One traced tile of a tiled map: tile (ti, tj) of the grid covers texels
// [ti * side, (ti + 1) * side) x [tj * side, (tj + 1) * side) of the level-`map_level` map.
struct TileJob {
  uint32_t ti = 0, tj = 0, index = 0;  // index = tj * grid + ti
  IntervalTile intervals;
};

struct TiledRun {
  uint32_t map_level = 0, tile_side = 0, grid_level = 0;
  double trace_s = 0, per_tile_s = 0, bottom_up_s = 0;  // summed call times (seconds)
  double wall_s = 0;
};

// Where a bench map's depth bounds come from: the Embree tracer (`--builder embree`, either
// interval rule) or the light-space rasterizer (`--builder raster`: sun lights, either
// interval rule, as map_build's resolve_builder; same canonical bounds up to
// the few texels ARCHITECTURE.md "Canonical coverage" counts). `static_rule`: the
// static-geometry interval (an open first hit reaches to just below the next surface;
// voxel shadows 2014 §6.1), from either builder.
class BoundsSource {
 public:
  BoundsSource(const Scene& scene, const LightSpace& light, const std::string& builder, bool static_rule)
      : mode_(static_rule ? TraceMode::static_bounds : TraceMode::bounds) {
    if (builder == "raster") {
      raster_ = std::make_unique<RasterBounds>(scene, light, RasterSkip::exact, mode_);
    } else if (builder == "embree") {
      tracer_ = std::make_unique<DepthBoundsTracer>(scene, light);
    } else {
      throw Error("--builder: expected embree or raster, got '" + builder + "'");
    }
  }
  IntervalTile trace(const TraceRegion& r) const { return raster_ ? raster_->trace(r) : tracer_->trace(r, mode_); }
  bool traces_exit_depths() const { return raster_ ? raster_->traces_exit_depths() : tracer_->traces_exit_depths(); }
  uint64_t triangle_count() const { return raster_ ? raster_->triangle_count() : tracer_->triangle_count(); }
  double setup_seconds() const { return raster_ ? raster_->setup_seconds() : tracer_->build_seconds(); }

 private:
  std::unique_ptr<DepthBoundsTracer> tracer_;
  std::unique_ptr<RasterBounds> raster_;
  TraceMode mode_;
};

// True when some triangle of the scene is in an open mesh (the static-geometry rule
// changes its intervals; on an all-closed scene it changes nothing).
inline bool has_open_mesh(const Scene& s) { return s.closed_triangle_count() < s.triangles.size(); }

// Traces the map tile by tile (row-major tiles of min(2^L, 4096)^2 texels) with `workers`
// threads, each of which also runs `per_tile` (after the trace, with the tile's intervals)
// and the bottom-up construction; `built` receives each tile's hierarchy (from the worker
// thread, tiles in any order). The tracer parallelises each call itself (TBB), so on a
// 2-core machine one worker is best.
inline TiledRun trace_and_build_tiles(const BoundsSource& tracer, uint32_t map_level, unsigned workers,
                                      const std::function<void(const TileJob&)>& per_tile,
                                      const std::function<void(uint32_t index, Hierarchy&&)>& built) {
  TiledRun run;
  run.map_level = map_level;
  run.tile_side = uint32_t(std::min<uint64_t>(uint64_t(1) << map_level, kTileSide));
  run.grid_level = map_level - log2_exact(run.tile_side);
  const uint32_t grid = 1u << run.grid_level, tiles = grid * grid;
  std::atomic<uint32_t> next{0};
  std::mutex mu;
  std::string error;
  auto t0 = Clock::now();
  auto work = [&]() {
    try {
      for (uint32_t i; (i = next++) < tiles;) {
        TileJob job;
        job.index = i, job.ti = i % grid, job.tj = i / grid;
        auto a = Clock::now();
        job.intervals = tracer.trace(
            {map_level, uint64_t(job.ti) * run.tile_side, uint64_t(job.tj) * run.tile_side, run.tile_side, run.tile_side});
        double trace = seconds_since(a);
        a = Clock::now();
        if (per_tile) per_tile(job);
        double extra = seconds_since(a);
        a = Clock::now();
        Hierarchy h = build_hierarchy(job.intervals, MhConstruction::bottom_up);
        double bu = seconds_since(a);
        job.intervals.data = {};
        built(i, std::move(h));
        std::lock_guard<std::mutex> lock(mu);
        run.trace_s += trace, run.per_tile_s += extra, run.bottom_up_s += bu;
      }
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(mu);
      if (error.empty()) error = e.what();
      next = tiles;
    }
  };
  std::vector<std::thread> ts;
  for (unsigned k = 0; k < std::max(1u, workers); ++k) ts.emplace_back(work);
  for (auto& t : ts) t.join();
  if (!error.empty()) throw Error(error);
  run.wall_s = seconds_since(t0);
  return run;
}

// A float array of 2^level x 2^level (row-major), backed by anonymous memory with
// transparent huge pages requested (ARCHITECTURE.md "Measured on the development machines": random reads over GiBs are ~2x faster).
struct FloatMap {
  uint32_t level = 0;
  uint64_t side = 0;
  float* data = nullptr;
  size_t bytes = 0;

  explicit FloatMap(uint32_t l) : level(l), side(uint64_t(1) << l) {
    bytes = size_t(side * side * sizeof(float));
    void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw Error("FloatMap: mmap of " + std::to_string(bytes) + " bytes failed");
    madvise(p, bytes, MADV_HUGEPAGE);
    data = static_cast<float*>(p);
  }
  ~FloatMap() {
    if (data) munmap(data, bytes);
  }
  FloatMap(const FloatMap&) = delete;
  FloatMap& operator=(const FloatMap&) = delete;
  float at(uint64_t x, uint64_t y) const { return data[y * side + x]; }
};

// Uncompressed r x r PCF with the Evaluator::pcf semantics (taps clamped to the map).
inline float array_pcf(const FloatMap& m, uint64_t x, uint64_t y, uint32_t r, float receiver) {
  uint32_t lit = 0;
  const uint64_t h = (r - 1) / 2;
  if (x >= h && y >= h && x + (r - 1 - h) < m.side && y + (r - 1 - h) < m.side) {  // no clamping
    const float* p = m.data + (y - h) * m.side + (x - h);
    for (uint32_t j = 0; j < r; ++j, p += m.side)
      for (uint32_t i = 0; i < r; ++i) lit += receiver <= p[i];
    return float(lit) / float(r * r);
  }
  for (uint32_t j = 0; j < r; ++j) {
    const float* row = m.data + st::pcf_tap(y, j, r, m.side) * m.side;
    for (uint32_t i = 0; i < r; ++i) lit += receiver <= row[st::pcf_tap(x, i, r, m.side)];
  }
  return float(lit) / float(r * r);
}

// Bytes of this process's anonymous memory backed by transparent huge pages (to show
// whether MADV_HUGEPAGE took effect), or -1 when /proc cannot tell.
inline double anon_huge_mib() {
  std::FILE* f = std::fopen("/proc/self/smaps_rollup", "r");
  if (!f) return -1;
  char line[256];
  double kb = -1;
  while (std::fgets(line, sizeof line, f))
    if (std::sscanf(line, "AnonHugePages: %lf kB", &kb) == 1) break;
  std::fclose(f);
  return kb < 0 ? -1 : kb / 1024.0;
}

// Writes every finest-level texel's value (Hierarchy::depth_at(depth, x, y)) once: a walk
// down the node lists, filling the block of every node whose subtree stores nothing
// below it (or of every absent child) with the inherited value.
inline void paint_finest(const Hierarchy& h, FloatMap& out) {
  if (out.level != h.depth) throw Error("paint_finest: level mismatch");
  const auto first = h.first_child_index();
  const uint32_t L = h.depth;
  auto fill = [&](uint32_t level, uint64_t morton, float v) {
    const uint32_t s = L - level;
    const uint64_t x0 = uint64_t(morton_compact(morton)) << s, y0 = uint64_t(morton_compact(morton >> 1)) << s;
    const uint64_t n = uint64_t(1) << s;
    for (uint64_t y = y0; y < y0 + n; ++y) std::fill_n(out.data + y * out.side + x0, n, v);
  };
  std::function<void(uint32_t, uint32_t, float)> walk = [&](uint32_t level, uint32_t j, float inherited) {
    const HNode& node = h.levels[level][j];
    const float v = node.has_value ? node.value : inherited;
    if (level == L || node.child_mask == 0) return fill(level, node.morton, v);
    uint32_t k = first[level][j];
    for (uint32_t c = 0; c < 4; ++c) {
      if (node.child_mask & (1u << c)) walk(level + 1, k++, v);
      else fill(level + 1, node.morton * 4 + c, v);
    }
  };
  walk(0, 0, h.levels[0][0].value);
}

}  // namespace st::bench

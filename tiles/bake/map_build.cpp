#include "tiles/bake/map_build.hpp"

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "tiles/bake/depth_bounds.hpp"
#include "common/error.hpp"
#include "tiles/build/hierarchy.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/build/pack_writer.hpp"
#include "tiles/build/tile_cut.hpp"

namespace st {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Adds seconds to an atomic accumulator (no atomic<double>::fetch_add before C++20 libs).
void add_seconds(std::atomic<uint64_t>& ns, double s) { ns += uint64_t(s * 1e9); }
double seconds_of(const std::atomic<uint64_t>& ns) { return double(ns.load()) * 1e-9; }

bool cell_touches(const TexelRegion& r, uint64_t x0, uint64_t y0, uint64_t side) {
  return x0 < r.x + r.w && r.x < x0 + side && y0 < r.y + r.h && r.y < y0 + side;
}

// Traces one level-K cell and builds its hierarchy; cells wider than kMaxTraceSide are
// traced in sub-tiles whose hierarchies are stitched (MH §3.1 "Tiled construction").
Hierarchy cell_hierarchy(const DepthBoundsTracer& tracer, uint32_t level, uint64_t x0,
                         uint64_t y0, uint64_t side, MhConstruction method,
                         std::atomic<uint64_t>& texels, std::atomic<uint64_t>& trace_ns,
                         std::atomic<uint64_t>& build_ns) {
  auto trace_and_build = [&](uint64_t x, uint64_t y, uint64_t s) {
    auto t = Clock::now();
    IntervalTile tile = tracer.trace({level, x, y, uint32_t(s), uint32_t(s)}, TraceMode::bounds,
                                     nullptr, &texels);
    add_seconds(trace_ns, since(t));
    t = Clock::now();
    Hierarchy h = build_hierarchy(tile, method);
    add_seconds(build_ns, since(t));
    return h;
  };
  if (side <= kMaxTraceSide) return trace_and_build(x0, y0, side);
  const uint64_t n = side / kMaxTraceSide;
  std::vector<Hierarchy> parts;
  parts.reserve(n * n);
  for (uint64_t j = 0; j < n; ++j)
    for (uint64_t i = 0; i < n; ++i)
      parts.push_back(trace_and_build(x0 + i * kMaxTraceSide, y0 + j * kMaxTraceSide, kMaxTraceSide));
  auto t = Clock::now();
  Hierarchy h = stitch_tiles(std::move(parts), log2_exact(n), method);
  add_seconds(build_ns, since(t));
  return h;
}

}  // namespace

uint64_t peak_rss_bytes() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return uint64_t(ru.ru_maxrss) * 1024;
}

MapBuildReport build_map(const Scene& scene, const LightSpace& light, const MapBuildOptions& o,
                         const std::string& out_path) {
  const auto t_start = Clock::now();
  if (o.map_level > kMaxLevel) throw Error("build: resolution level exceeds 20");
  CutParams cut;
  cut.map_level = o.map_level;
  cut.skip_level = o.skip_level.value_or(default_skip_level(o.map_level));
  cut.tile_bytes = o.tile_bytes;
  cut.codec = TileCodec::of(o.encoding);
  cut.validate();
  const uint32_t L = cut.map_level, K = cut.skip_level;
  const uint64_t cells_side = uint64_t(1) << K, cell_side = uint64_t(1) << (L - K);
  if (o.region) {
    const uint64_t R = uint64_t(1) << L;
    const auto& r = *o.region;
    if (r.w == 0 || r.h == 0 || r.x >= R || r.y >= R || r.w > R - r.x || r.h > R - r.y)
      throw Error("build: --region lies outside the " + std::to_string(R) + "^2 map");
  }

  MapBuildReport rep;
  rep.map_level = L;
  rep.skip_level = K;
  rep.encoding = to_string(o.encoding);
  rep.cells_total = cells_side * cells_side;

  auto t = Clock::now();
  DepthBoundsTracer tracer(scene, light);
  rep.bvh_seconds = since(t);
  rep.exit_depths = tracer.traces_exit_depths();

  PackParams pp = PackParams::from(light, cut);
  pp.scene_hash = scene.content_hash();
  pp.features = rep.exit_depths ? uint32_t(kFeatureExitDepths) : 0u;
  pp.compression_level = o.compression_level;
  pp.build_params = {{"construction", o.construction == MhConstruction::bottom_up ? "bottom-up" : "top-down"},
                     {"light", o.light_spec.empty() ? light.spec().to_string() : o.light_spec},
                     {"scene", o.scene_spec.empty() ? scene.name : o.scene_spec},
                     {"tool", "shadowtile 0.1.0"}};
  if (o.region)
    pp.build_params.push_back({"region", std::to_string(o.region->x) + "," + std::to_string(o.region->y) +
                                             "," + std::to_string(o.region->w) + "," +
                                             std::to_string(o.region->h)});
  std::sort(pp.build_params.begin(), pp.build_params.end());
  auto writer = o.resume ? PackWriter::create_or_resume(out_path, pp) : PackWriter::create(out_path, pp);
  rep.cells_resumed = writer->resumed_cells();
  TileCutter cutter(cut);

  // Cells in Morton order (neighbouring cells share BVH nodes and cache lines).
  std::vector<std::pair<uint32_t, uint32_t>> todo;
  uint64_t outside = 0;
  for (uint64_t m = 0; m < rep.cells_total; ++m) {
    uint32_t cx = morton_compact(m), cy = morton_compact(m >> 1);
    if (writer->is_done(cx, cy)) continue;
    if (o.region && !cell_touches(*o.region, cx * cell_side, cy * cell_side, cell_side)) {
      CutCell c;
      c.cx = cx, c.cy = cy;
      c.entry = GridEntry{kLitDepth, EntryKind::constant, 0};
      c.lo = c.hi = kLitDepth;
      writer->append_cell(c);
      ++outside;
      continue;
    }
    todo.emplace_back(cx, cy);
  }
  rep.cells_outside_region = outside;

  std::atomic<uint64_t> next{0}, appended{0}, texels{0}, trace_ns{0}, build_ns{0}, cut_ns{0}, write_ns{0};
  std::atomic<bool> stop{false};
  std::exception_ptr failure;
  std::mutex failure_mu;
  auto worker = [&]() {
    try {
      for (;;) {
        if (stop || (o.cancel && o.cancel->load())) return;
        uint64_t i = next++;
        if (i >= todo.size()) return;
        auto [cx, cy] = todo[i];
        Hierarchy h = cell_hierarchy(tracer, L, cx * cell_side, cy * cell_side, cell_side,
                                     o.construction, texels, trace_ns, build_ns);
        auto tc = Clock::now();
        CutCell cell = cutter.cut_cell(cx, cy, std::move(h));
        add_seconds(cut_ns, since(tc));
        tc = Clock::now();
        writer->append_cell(cell);
        add_seconds(write_ns, since(tc));
        uint64_t n = ++appended;
        if (o.stop_after_cells && n >= *o.stop_after_cells) {
          stop = true;
          throw Error("build interrupted after " + std::to_string(n) + " cells (test hook)");
        }
      }
    } catch (...) {
      std::lock_guard lock(failure_mu);
      if (!failure) failure = std::current_exception();
      stop = true;
    }
  };

  std::mutex progress_mu;
  std::condition_variable progress_cv;
  bool finished = false;
  std::thread progress_thread;
  if (o.progress) {
    progress_thread = std::thread([&]() {
      std::unique_lock lock(progress_mu);
      while (!progress_cv.wait_for(lock, std::chrono::milliseconds(200), [&] { return finished; }))
        o.progress(rep.cells_total - todo.size() + appended.load(), rep.cells_total, texels.load());
    });
  }
  const unsigned nthreads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> workers;
  for (unsigned i = 0; i < nthreads; ++i) workers.emplace_back(worker);
  for (auto& w : workers) w.join();
  {
    std::lock_guard lock(progress_mu);
    finished = true;
  }
  progress_cv.notify_all();
  if (progress_thread.joinable()) progress_thread.join();
  if (failure) std::rethrow_exception(failure);
  if (o.cancel && o.cancel->load())
    throw Error("build interrupted; run again with --resume to continue from " + writer->tmp_path());

  auto tf = Clock::now();
  const MhConstruction method = o.construction;
  CutGrid grid = cutter.coarse_grid(writer->cells(),
                                    [method](const IntervalTile& t) { return build_hierarchy(t, method); });
  writer->finish(grid);
  rep.finish_seconds = since(tf);
  if (o.progress) o.progress(rep.cells_total, rep.cells_total, texels.load());

  rep.cells_built = appended.load();
  rep.texels_traced = texels.load();
  rep.trace_seconds = seconds_of(trace_ns);
  rep.hierarchy_seconds = seconds_of(build_ns);
  rep.cut_encode_seconds = seconds_of(cut_ns);
  rep.write_seconds = seconds_of(write_ns);

  // Figures from the finished file, as a reader sees it.
  auto reader = PackReader::open(out_path);
  rep.pack_bytes = reader->file_size();
  rep.grid_entries = reader->grid().entries.size();
  for (auto& e : reader->grid().entries) rep.constant_entries += e.kind == EntryKind::constant;
  rep.stored_bytes_per_level.assign(L + 1, 0);
  std::vector<uint64_t> bounds;
  for (uint64_t b = 256; b <= (uint64_t(1) << 30); b *= 2) bounds.push_back(b);
  std::vector<uint64_t> counts(bounds.size(), 0);
  for (auto& e : reader->tiles()) {
    ++rep.tile_count;
    rep.index_tile_count += e.kind == TileKind::index;
    rep.stored_bytes_per_level[tile_address(e.id).level] += e.stored_size;
    size_t k = 0;
    while (k + 1 < bounds.size() && e.stored_size > bounds[k]) ++k;
    ++counts[k];
  }
  for (size_t k = 0; k < bounds.size(); ++k)
    if (counts[k]) rep.tile_size_histogram.emplace_back(bounds[k], counts[k]);
  rep.wall_seconds = since(t_start);
  rep.peak_rss_bytes = peak_rss_bytes();
  return rep;
}

std::string MapBuildReport::to_json() const {
  nlohmann::json j;
  j["map_level"] = map_level;
  j["resolution"] = uint64_t(1) << map_level;
  j["skip_level"] = skip_level;
  j["encoding"] = encoding;
  j["cells"] = {{"total", cells_total}, {"built", cells_built}, {"resumed", cells_resumed},
                {"outside_region", cells_outside_region}};
  j["texels_traced"] = texels_traced;
  j["exit_depths"] = exit_depths;
  j["wall_seconds"] = wall_seconds;
  j["stage_thread_seconds"] = {{"bvh", bvh_seconds},           {"trace", trace_seconds},
                               {"hierarchy", hierarchy_seconds}, {"cut_encode", cut_encode_seconds},
                               {"compress_write", write_seconds}, {"finish", finish_seconds}};
  j["pack_bytes"] = pack_bytes;
  j["tiles"] = tile_count;
  j["index_tiles"] = index_tile_count;
  j["grid_entries"] = grid_entries;
  j["constant_entry_fraction"] = grid_entries ? double(constant_entries) / double(grid_entries) : 0.0;
  nlohmann::json per_level = nlohmann::json::object();
  for (size_t l = 0; l < stored_bytes_per_level.size(); ++l)
    if (stored_bytes_per_level[l]) per_level[std::to_string(l)] = stored_bytes_per_level[l];
  j["stored_bytes_per_tile_level"] = per_level;
  nlohmann::json hist = nlohmann::json::array();
  for (auto& [b, c] : tile_size_histogram) hist.push_back({{"max_bytes", b}, {"tiles", c}});
  j["tile_size_histogram"] = hist;
  j["peak_rss_bytes"] = peak_rss_bytes;
  j["texels_per_second"] = wall_seconds > 0 ? double(texels_traced) / wall_seconds : 0.0;
  return j.dump(2);
}

}  // namespace st

// The map build (map_build.hpp) as its stages: check the options, open or resume the
// pack, plan the cells, run the per-cell pipeline on every hardware thread, finish the
// pack and report its figures; build_map() strings them together.
#include "tiles/bake/map_build.hpp"

#include <sys/resource.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "common/error.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/encode/tile_cut.hpp"
#include "tiles/encode/vsdag_encode.hpp"

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

// The cut the options ask for, checked, with the region checked against the map.
CutParams checked_cut_params(const MapBuildOptions& o) {
  if (o.map_level > kMaxLevel) throw Error("build: resolution level exceeds 20");
  CutParams cut;
  cut.map_level = o.map_level;
  cut.skip_level = o.skip_level.value_or(default_skip_level(o.map_level));
  cut.tile_bytes = o.tile_bytes;
  cut.codec = o.encoding == Encoding::dagmh && o.dagmh_mixed_tiles ? TileCodec::dagmh_or_mmh(o.dagmh_mixed_exhaustive) : TileCodec::of(o.encoding);
  if (o.encoding == Encoding::vsdag) {
    const VsdagOptions vo{o.vsdag_z_bits};
    if (vo.z_bits < vsdag::kMinZBits || vo.z_bits > vsdag::kMaxZBits) throw Error("build: --depth-bits must be 3..20");
    cut.codec.encode = [vo](const Hierarchy& h) { return encode_vsdag(h, vo); };
  }
  if (o.planes && o.encoding != Encoding::vsdag) {
    PlaneFitOptions fit = o.plane_fit;
    fit.packed = o.pack_plane_tiles;  // weigh plane tiles as the pack will store them
    fit.predicted = o.predict_plane_labels;
    cut.codec = TileCodec::with_planes(cut.codec, cut.tile_bytes, fit);
  }
  cut.validate();
  if (o.region) {
    const uint64_t R = uint64_t(1) << cut.map_level;
    const auto& r = *o.region;
    if (r.w == 0 || r.h == 0 || r.x >= R || r.y >= R || r.w > R - r.x || r.h > R - r.y)
      throw Error("build: --region lies outside the " + std::to_string(R) + "^2 map");
  }
  return cut;
}

// The bounds producer of a build (MapBuildOptions::builder, resolved).
class CellBounds {
 public:
  CellBounds(const Scene& scene, const LightSpace& light, const MapBuildOptions& o)
      : builder_(resolve_builder(o.builder, light, o.intervals)), mode_(trace_mode_of(o.intervals)) {
    if (builder_ == BoundsBuilder::raster)
      raster_ = std::make_unique<RasterBounds>(scene, light, o.raster_skip, mode_);
    else tracer_ = std::make_unique<DepthBoundsTracer>(scene, light);
  }
  BoundsBuilder builder() const { return builder_; }
  bool exit_depths() const { return raster_ ? raster_->traces_exit_depths() : tracer_->traces_exit_depths(); }
  IntervalTile trace(const TraceRegion& r, std::atomic<uint64_t>* progress) const {
    return raster_ ? raster_->trace(r, nullptr, progress) : tracer_->trace(r, mode_, nullptr, progress);
  }
  // The rasterizer when it skips whole regions (RasterSkip::regions), else nullptr.
  const RasterBounds* regions() const {
    return raster_ && raster_->skip() == RasterSkip::regions ? raster_.get() : nullptr;
  }

 private:
  BoundsBuilder builder_;
  TraceMode mode_;
  std::unique_ptr<RasterBounds> raster_;
  std::unique_ptr<DepthBoundsTracer> tracer_;
};

// What the pack records of its build: the light and cut, the scene's hash, and the
// provenance (sorted), which a resumed build must match.
PackParams pack_params(const Scene& scene, const LightSpace& light, const MapBuildOptions& o,
                       const CutParams& cut, bool exit_depths, BoundsBuilder builder) {
  PackParams pp = PackParams::from(light, cut);
  pp.scene_hash = scene.content_hash();
  pp.features = exit_depths ? uint32_t(kFeatureExitDepths) : 0u;
  if (o.intervals == IntervalRule::static_geometry) pp.features |= kFeatureStaticIntervals;
  pp.compression_level = o.compression_level;
  pp.dagmh_dictionary = o.dagmh_dictionary && o.encoding == Encoding::dagmh;
  pp.pack_plane_tiles = o.pack_plane_tiles;
  pp.predict_plane_labels = o.predict_plane_labels;
  pp.build_params = {{"builder", to_string(builder)},
                     {"construction", o.construction == MhConstruction::bottom_up ? "bottom-up" : "top-down"},
                     {"light", o.light_spec.empty() ? light.spec().to_string() : o.light_spec},
                     {"scene", o.scene_spec.empty() ? scene.name : o.scene_spec},
                     {"tool", "shadowtile 0.1.0"}};
  if (o.intervals == IntervalRule::static_geometry) pp.build_params.push_back({"intervals", "static"});
  // Stored values lie in sub-intervals of the definition's (RasterSkip::narrow): still
  // lossless against the true intervals, but not bit-identical to a build without it.
  if (builder == BoundsBuilder::raster && (o.raster_skip == RasterSkip::narrow || o.raster_skip == RasterSkip::regions))
    pp.build_params.push_back({"intervals_narrowed", "yes"});
  if (o.shard) pp.build_params.push_back({kShardParam, o.shard->to_string()});
  // The depth resolution of vsdag tiles: what `verify` checks their contract against.
  if (o.encoding == Encoding::vsdag) pp.build_params.push_back({"depth_bits", std::to_string(o.vsdag_z_bits)});
  if (o.region)
    pp.build_params.push_back({"region", std::to_string(o.region->x) + "," + std::to_string(o.region->y) +
                                             "," + std::to_string(o.region->w) + "," +
                                             std::to_string(o.region->h)});
  std::sort(pp.build_params.begin(), pp.build_params.end());
  return pp;
}

using CellXY = std::pair<uint32_t, uint32_t>;

// The cells still to build, in Morton order (neighbouring cells share BVH nodes and cache
// lines). Cells already in the pack are skipped; cells outside the region are appended
// at once as constant kLitDepth and counted in `outside`.
std::vector<CellXY> plan_cells(PackWriter& writer, const MapBuildOptions& o, uint32_t skip_level,
                               uint64_t cell_side, uint64_t& outside) {
  const uint64_t cells_side = uint64_t(1) << skip_level;
  std::vector<CellXY> todo;
  outside = 0;
  for (uint64_t m = 0; m < cells_side * cells_side; ++m) {
    uint32_t cx = morton_compact(m), cy = morton_compact(m >> 1);
    if (o.shard && m % o.shard->count != o.shard->index) continue;  // BuildShard::holds
    if (writer.is_done(cx, cy)) continue;
    if (o.region && !cell_touches(*o.region, cx * cell_side, cy * cell_side, cell_side)) {
      CutCell c;
      c.cx = cx, c.cy = cy;
      c.entry = GridEntry{kLitDepth, EntryKind::constant, 0};
      c.lo = c.hi = kLitDepth;
      writer.append_cell(c);
      ++outside;
      continue;
    }
    todo.emplace_back(cx, cy);
  }
  return todo;
}

// Traces a square of `side` texels and builds its hierarchy, adding the texels traced and
// each stage's time to the counters.
Hierarchy traced_hierarchy(const CellBounds& bounds, uint32_t level, uint64_t x0, uint64_t y0, uint64_t side,
                           MhConstruction method, std::atomic<uint64_t>& texels, std::atomic<uint64_t>& trace_ns,
                           std::atomic<uint64_t>& build_ns) {
  auto t = Clock::now();
  IntervalTile tile = bounds.trace({level, x0, y0, uint32_t(side), uint32_t(side)}, &texels);
  add_seconds(trace_ns, since(t));
  t = Clock::now();
  Hierarchy h = build_hierarchy(tile, method);
  add_seconds(build_ns, since(t));
  return h;
}

// The hierarchy of a square of 2^depth texels a side that all admit `iv`: one valued
// leaf root, its value chosen as the construction chooses it for a texel of that interval.
Hierarchy uniform_hierarchy(const Interval& iv, uint32_t depth, MhConstruction method) {
  IntervalTile one;
  one.width = one.height = 1;
  one.data = {iv};
  Hierarchy h = build_hierarchy(one, method);
  h.depth = depth;
  h.levels.resize(size_t(depth) + 1);
  return h;
}

// Top-down over square regions (RasterSkip::regions): a region whose corners prove one
// interval for all its texels (RasterBounds::region_interval) is one leaf; any other
// splits in four down to kRegionLeafSide, whose texels are rasterized; the four
// children's hierarchies are stitched (MH §3.1 "Tiled construction": each child's root
// interval is the intersection of, or a window inside, its texels' intervals). Work
// grows with the regions the proof fails on, along edges between surfaces.
Hierarchy region_hierarchy(const RasterBounds& raster, const CellBounds& bounds, uint32_t level, uint64_t x0,
                           uint64_t y0, uint64_t side, MhConstruction method, std::atomic<uint64_t>& texels,
                           std::atomic<uint64_t>& skipped, std::atomic<uint64_t>& trace_ns,
                           std::atomic<uint64_t>& build_ns) {
  auto t = Clock::now();
  const std::optional<Interval> iv = raster.region_interval(level, x0, y0, side);
  add_seconds(trace_ns, since(t));
  if (iv) {
    skipped.fetch_add(side * side, std::memory_order_relaxed);
    return uniform_hierarchy(*iv, log2_exact(side), method);
  }
  if (side <= kRegionLeafSide) return traced_hierarchy(bounds, level, x0, y0, side, method, texels, trace_ns, build_ns);
  const uint64_t half = side / 2;
  std::vector<Hierarchy> parts;
  parts.reserve(4);
  for (uint64_t j = 0; j < 2; ++j)
    for (uint64_t i = 0; i < 2; ++i)
      parts.push_back(region_hierarchy(raster, bounds, level, x0 + i * half, y0 + j * half, half, method, texels,
                                       skipped, trace_ns, build_ns));
  t = Clock::now();
  Hierarchy h = stitch_tiles(std::move(parts), 1, method);
  add_seconds(build_ns, since(t));
  return h;
}

// Traces one level-K cell and builds its hierarchy; cells wider than kMaxTraceSide are
// traced in sub-tiles whose hierarchies are stitched (MH §3.1 "Tiled construction").
Hierarchy cell_hierarchy(const CellBounds& bounds, uint32_t level, uint64_t x0,
                         uint64_t y0, uint64_t side, MhConstruction method,
                         std::atomic<uint64_t>& texels, std::atomic<uint64_t>& skipped,
                         std::atomic<uint64_t>& trace_ns, std::atomic<uint64_t>& build_ns) {
  if (const RasterBounds* raster = bounds.regions())
    return region_hierarchy(*raster, bounds, level, x0, y0, side, method, texels, skipped, trace_ns, build_ns);
  auto trace_and_build = [&](uint64_t x, uint64_t y, uint64_t s) {
    return traced_hierarchy(bounds, level, x, y, s, method, texels, trace_ns, build_ns);
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

// The per-cell pipeline on every hardware thread: trace -> hierarchy -> cut + encode ->
// compress + append. Workers take the planned cells in order; the first failure, the
// cancel flag or the stop_after_cells hook stops them all at their next cell.
class CellWorkers {
 public:
  CellWorkers(const CellBounds& bounds, const TileCutter& cutter, PackWriter& writer,
              const MapBuildOptions& o, const std::vector<CellXY>& todo)
      : bounds_(bounds), cutter_(cutter), writer_(writer), o_(o), todo_(todo) {}

  // Runs the workers to the end and rethrows the first failure.
  void run() {
    const unsigned nthreads = std::max(1u, std::thread::hardware_concurrency());
    std::vector<std::thread> workers;
    for (unsigned i = 0; i < nthreads; ++i) workers.emplace_back([this] { work(); });
    if (o_.remote) workers.emplace_back([this] { serve_remote(); });
    for (auto& w : workers) w.join();
    if (failure_) std::rethrow_exception(failure_);
  }

  // Progress so far (another thread may poll them while run() is under way).
  uint64_t appended() const { return appended_.load(); }
  uint64_t texels() const { return texels_.load() + skipped_.load(); }

  // Cells built, texels traced and the thread-seconds of each stage.
  void report(MapBuildReport& rep) const {
    rep.cells_built = appended_.load();
    rep.texels_traced = texels_.load();
    rep.texels_in_regions = skipped_.load();
    rep.trace_seconds = seconds_of(trace_ns_);
    rep.hierarchy_seconds = seconds_of(build_ns_);
    rep.cut_encode_seconds = seconds_of(cut_ns_);
    rep.write_seconds = seconds_of(write_ns_);
  }

 private:
  void work() {
    try {
      for (;;) {
        if (stop_ || (o_.cancel && o_.cancel->load())) return;
        uint64_t i = next_++;
        if (i >= todo_.size()) return;
        build_cell(todo_[i].first, todo_[i].second);
      }
    } catch (...) {
      std::lock_guard lock(failure_mu_);
      if (!failure_) failure_ = std::current_exception();
      stop_ = true;
    }
  }

  void fail(std::exception_ptr e) {
    std::lock_guard lock(failure_mu_);
    if (!failure_) failure_ = e;
    stop_ = true;
  }

  // The other processes' share (RemoteCells): they take from the same cursor.
  void serve_remote() {
    try {
      o_.remote->run(
          [this]() -> std::optional<CellXY> {
            if (stop_ || (o_.cancel && o_.cancel->load())) return std::nullopt;
            uint64_t i = next_++;
            if (i >= todo_.size()) return std::nullopt;
            return todo_[i];
          },
          [this](std::span<const uint8_t> bytes) {
            auto t = Clock::now();
            writer_.append_cell_bytes(bytes);
            add_seconds(write_ns_, since(t));
            ++appended_;
          });
    } catch (...) {
      fail(std::current_exception());
    }
  }

  void build_cell(uint32_t cx, uint32_t cy) {
    const CutParams& cut = cutter_.params();
    const uint64_t cell_side = uint64_t(1) << (cut.map_level - cut.skip_level);
    Hierarchy h = cell_hierarchy(bounds_, cut.map_level, cx * cell_side, cy * cell_side,
                                 cell_side, o_.construction, texels_, skipped_, trace_ns_,
                                 build_ns_);
    auto t = Clock::now();
    CutCell cell = cutter_.cut_cell(cx, cy, std::move(h));
    add_seconds(cut_ns_, since(t));
    t = Clock::now();
    writer_.append_cell(cell);
    add_seconds(write_ns_, since(t));
    uint64_t n = ++appended_;
    if (o_.stop_after_cells && n >= *o_.stop_after_cells) {
      stop_ = true;
      throw Error("build interrupted after " + std::to_string(n) + " cells (test hook)");
    }
  }

  const CellBounds& bounds_;
  const TileCutter& cutter_;
  PackWriter& writer_;
  const MapBuildOptions& o_;
  const std::vector<CellXY>& todo_;
  std::atomic<uint64_t> next_{0}, appended_{0}, texels_{0}, skipped_{0};
  std::atomic<uint64_t> trace_ns_{0}, build_ns_{0}, cut_ns_{0}, write_ns_{0};
  std::atomic<bool> stop_{false};
  std::mutex failure_mu_;
  std::exception_ptr failure_;
};

// Calls `tick` from a background thread every 200 ms until destroyed (never, if empty).
class ProgressTicker {
 public:
  explicit ProgressTicker(std::function<void()> tick) : tick_(std::move(tick)) {
    if (!tick_) return;
    thread_ = std::thread([this] {
      std::unique_lock lock(mu_);
      while (!cv_.wait_for(lock, std::chrono::milliseconds(200), [this] { return finished_; }))
        tick_();
    });
  }
  ~ProgressTicker() {
    {
      std::lock_guard lock(mu_);
      finished_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  ProgressTicker(const ProgressTicker&) = delete;
  ProgressTicker& operator=(const ProgressTicker&) = delete;

 private:
  std::function<void()> tick_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool finished_ = false;
  std::thread thread_;
};

// The skip grid over every cell (levels 0..K-1 built from the cells' root intervals with
// the build's construction), then the index, header and rename.
void finish_pack(PackWriter& writer, const TileCutter& cutter, MhConstruction method) {
  CutGrid grid = cutter.coarse_grid(writer.cells(),
                                    [method](const IntervalTile& t) { return build_hierarchy(t, method); });
  writer.finish(grid);
}

// Figures from the finished file, as a reader sees it: sizes, entries, tiles per level
// and a histogram of stored tile sizes.
void report_pack_figures(const std::string& out_path, uint32_t map_level, MapBuildReport& rep) {
  auto reader = PackReader::open(out_path);
  rep.pack_bytes = reader->file_size();
  rep.grid_entries = reader->grid().entries.size();
  for (auto& e : reader->grid().entries) rep.constant_entries += e.kind == EntryKind::constant;
  rep.stored_bytes_per_level.assign(map_level + 1, 0);
  std::vector<uint64_t> bounds;
  for (uint64_t b = 256; b <= (uint64_t(1) << 30); b *= 2) bounds.push_back(b);
  std::vector<uint64_t> counts(bounds.size(), 0);
  for (auto& e : reader->tiles()) {
    if (is_deep_id(e.id)) continue;  // the deep part (deep_pack.hpp): not the opaque map's
    ++rep.tile_count;
    rep.index_tile_count += e.kind == TileKind::index;
    rep.stored_bytes_per_level[tile_address(e.id).level] += e.stored_size;
    size_t k = 0;
    while (k + 1 < bounds.size() && e.stored_size > bounds[k]) ++k;
    ++counts[k];
  }
  for (size_t k = 0; k < bounds.size(); ++k)
    if (counts[k]) rep.tile_size_histogram.emplace_back(bounds[k], counts[k]);
}

}  // namespace

const char* to_string(BoundsBuilder b) {
  switch (b) {
    case BoundsBuilder::automatic: return "auto";
    case BoundsBuilder::raster: return "raster";
    case BoundsBuilder::embree: return "embree";
  }
  return "?";
}

BoundsBuilder parse_bounds_builder(const std::string& text) {
  if (text == "auto") return BoundsBuilder::automatic;
  if (text == "raster") return BoundsBuilder::raster;
  if (text == "embree") return BoundsBuilder::embree;
  throw Error("--builder: expected raster, embree or auto, got '" + text + "'");
}

BoundsBuilder resolve_builder(BoundsBuilder b, const LightSpace& light, IntervalRule rule) {
  (void)rule;  // the rasterizer builds both interval rules
  const bool applies = light.kind() == LightKind::sun;
  if (b == BoundsBuilder::automatic) return applies ? BoundsBuilder::raster : BoundsBuilder::embree;
  if (b == BoundsBuilder::raster && !applies)
    throw Error("--builder raster: the rasterizer handles sun lights only; use --builder embree for a spot light");
  return b;
}

uint64_t peak_rss_bytes() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return uint64_t(ru.ru_maxrss) * 1024;
}

MapBuildReport build_map(const Scene& scene, const LightSpace& light, const MapBuildOptions& o,
                         const std::string& out_path) {
  const auto t_start = Clock::now();
  const CutParams cut = checked_cut_params(o);
  const uint32_t L = cut.map_level, K = cut.skip_level;
  MapBuildReport rep;
  rep.map_level = L;
  rep.skip_level = K;
  rep.encoding = to_string(o.encoding);
  rep.cells_total = o.shard ? o.shard->cell_count(K) : (uint64_t(1) << K) * (uint64_t(1) << K);

  auto t = Clock::now();
  const CellBounds bounds(scene, light, o);
  rep.bvh_seconds = since(t);
  rep.exit_depths = bounds.exit_depths();
  rep.builder = to_string(bounds.builder());

  const PackParams pp = pack_params(scene, light, o, cut, rep.exit_depths, bounds.builder());
  auto writer = o.resume ? PackWriter::create_or_resume(out_path, pp) : PackWriter::create(out_path, pp);
  rep.cells_resumed = writer->resumed_cells();
  TileCutter cutter(cut);
  const std::vector<CellXY> todo =
      plan_cells(*writer, o, K, uint64_t(1) << (L - K), rep.cells_outside_region);

  CellWorkers workers(bounds, cutter, *writer, o, todo);
  {
    const uint64_t planned_done = rep.cells_total - todo.size();
    ProgressTicker ticker(o.progress ? std::function<void()>([&] {
      o.progress(planned_done + workers.appended(), rep.cells_total, workers.texels());
    }) : std::function<void()>());
    workers.run();
  }
  if (o.cancel && o.cancel->load())
    throw Error("build interrupted; run again with --resume to continue from " + writer->tmp_path());

  t = Clock::now();
  if (o.shard) {
    if (writer->cells().size() != rep.cells_total)
      throw Error(writer->tmp_path() + ": shard " + o.shard->to_string() + " holds " +
                  std::to_string(writer->cells().size()) + " of its " + std::to_string(rep.cells_total) + " cells");
    writer->finish_part();
  } else {
    if (o.before_finish) o.before_finish(*writer);
    finish_pack(*writer, cutter, o.construction);
    const DictionaryOutcome& d = writer->dictionary_outcome();
    rep.dictionary_bytes = d.bytes, rep.dictionary_tiles_rewritten = d.tiles_rewritten;
    rep.dictionary_raw_before = d.raw_before, rep.dictionary_raw_after = d.raw_after;
    rep.dictionary_skipped = d.skipped;
  }
  rep.finish_seconds = since(t);
  if (o.progress) o.progress(rep.cells_total, rep.cells_total, workers.texels());

  workers.report(rep);
  if (o.shard) {
    struct stat st{};
    rep.pack_bytes = ::stat(out_path.c_str(), &st) == 0 ? uint64_t(st.st_size) : 0;
  } else {
    report_pack_figures(out_path, L, rep);
  }
  rep.wall_seconds = since(t_start);
  rep.peak_rss_bytes = peak_rss_bytes();
  return rep;
}

struct CellBuilder::Impl {
  Impl(const Scene& scene, const LightSpace& light, const MapBuildOptions& o)
      : options(o), cut(checked_cut_params(o)), bounds(scene, light, o), cutter(cut),
        params(pack_params(scene, light, o, cut, bounds.exit_depths(), bounds.builder())) {}
  MapBuildOptions options;
  CutParams cut;
  CellBounds bounds;
  TileCutter cutter;
  PackParams params;
  mutable std::atomic<uint64_t> texels{0}, skipped{0}, trace_ns{0}, build_ns{0};
};

CellBuilder::CellBuilder(const Scene& scene, const LightSpace& light, const MapBuildOptions& options)
    : impl_(std::make_unique<Impl>(scene, light, options)) {}
CellBuilder::~CellBuilder() = default;

std::vector<uint8_t> CellBuilder::build(uint32_t cx, uint32_t cy) const {
  const Impl& m = *impl_;
  const uint64_t cells_side = uint64_t(1) << m.cut.skip_level;
  if (cx >= cells_side || cy >= cells_side)
    throw Error("build: cell (" + std::to_string(cx) + ", " + std::to_string(cy) + ") outside the skip grid");
  const uint64_t side = uint64_t(1) << (m.cut.map_level - m.cut.skip_level);
  Hierarchy h = cell_hierarchy(m.bounds, m.cut.map_level, cx * side, cy * side, side, m.options.construction,
                               m.texels, m.skipped, m.trace_ns, m.build_ns);
  return encode_cell_bytes(m.cutter.cut_cell(cx, cy, std::move(h)), m.params);
}

uint64_t CellBuilder::texels_traced() const { return impl_->texels.load(); }

std::string MapBuildReport::to_json() const {
  nlohmann::json j;
  j["map_level"] = map_level;
  j["resolution"] = uint64_t(1) << map_level;
  j["skip_level"] = skip_level;
  j["encoding"] = encoding;
  j["builder"] = builder;
  j["cells"] = {{"total", cells_total}, {"built", cells_built}, {"resumed", cells_resumed},
                {"outside_region", cells_outside_region}};
  j["texels_traced"] = texels_traced;
  j["texels_in_regions"] = texels_in_regions;
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
  if (dictionary_bytes || !dictionary_skipped.empty())
    j["dagmh_dictionary"] = {{"bytes", dictionary_bytes},
                             {"tiles_rewritten", dictionary_tiles_rewritten},
                             {"tile_raw_bytes_before", dictionary_raw_before},
                             {"tile_raw_bytes_after", dictionary_raw_after},
                             {"skipped", dictionary_skipped}};
  j["texels_per_second"] = wall_seconds > 0 ? double(texels_traced) / wall_seconds : 0.0;
  return j.dump(2);
}

}  // namespace st

// Encoded sizes, shaped like DAG-MH 2021 Table 1: for each scene and map
// side, the bytes of the MH quadtree (MH §3.2), MMH and DAG-MH next to the raw float32
// shadow map (4 N^2 bytes: the first-hit depths `lo`, i.e. the ordinary shadow map) and
// that raw map compressed with zstd (level 19 by default, libzstd ZSTD_compress), with
// the ratios DAG-MH/MMH and MH/raw, and the construction time per stage.
//
//   bench_encodings [--scenes city,terrain,hairball,soup] [--light sun:azimuth=30,elevation=50]
//                   [--min-res 4k] [--max-res 16k] [--quick] [--workers 1]
//                   [--zstd-level 19] [--zstd-max-res 64k] [--whole-max 16k] [--json PATH]
//                   [--builder embree|raster] [--intervals default,static] [--depth-bits 16]
//
// Scenes: procedural names (city, terrain and hairball are all closed; soup is one open
// mesh with duplicate, sliver and overlapping faces) or any load_scene spec. A scene with
// an open mesh gets a row per interval rule in --intervals: "default" (the closed-object
// rule: an open first hit has hi = lo) and "static" (the static-geometry rule of voxel
// shadows 2014 §6.1, row "NAME/st": an open first hit reaches to just below the next
// surface, so answers are exact for receivers on surfaces only; ARCHITECTURE.md
// "Depth interval"). Every encoding of a row is built from the same intervals, and the
// vsdag table names the contract that applies (tiles/core/VSDAG.md "Exactness contract").
// An all-closed scene gets the default row only (the static rule changes nothing there).
// --builder: where the bounds come from (bench_map.hpp BoundsSource): embree (default,
// either rule) or raster (the light-space rasterizer: sun, default rule only).
// Maps are built tile by tile (MH §3.1 "Tiled construction"): 4096^2 tiles are traced
// with DepthBoundsTracer and built bottom-up, zstd compresses each tile's raw floats on
// its own (so "zstd" is the sum over 4096^2 chunks, each compressed independently), and
// stitch_tiles joins the tiles' hierarchies into the whole map's, which every encoder
// takes at once. Above --whole-max (default 16K) the whole-map hierarchy is not kept:
// each 4096^2 tile's hierarchy is encoded on its own and the coarse top (the hierarchy
// over the tiles' root intervals, as tile_cut's coarse_grid does) is encoded once more;
// the bytes reported are the sum (one header per tile included), and the output says so.
// Top-down construction (MH §3.1 Alg. 1) is timed on one 4096^2 tile per scene.
// --zstd-max-res R: no zstd above side R (its column shows "-"): level 19 runs at about
// 3 MB/s on this machine, so a 16K^2 map (1 GiB raw) takes minutes per scene.
// DAG+dict (tiles mode only; the whole-map encode has no tile edges to share across): the
// per-tile DAG-MH buffers and the top sharing their common subtrees through one pack
// dictionary (tiles/encode/dagmh_dictionary.hpp, tiles/core/DAGMH.md "Dictionary"), its
// bytes counted once. --whole-max 4k puts 16K^2 in tiles mode (16 tiles).
// --quick: sides 2K only (under a minute on an idle 2-core machine).
// The voxel shadow DAG (tiles/core/VSDAG.md, --depth-bits, default 16; the voxel paper uses
// as many as the side's) is always encoded per 4096^2
// tile, as a pack holds it (its build keeps a tile's transitions and min-max pyramid);
// sub-DAGs are not merged across tiles. Its size is also given against a 16-bit shadow
// map (2 N^2 bytes), the voxel paper's reference.
#include <zstd.h>

#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "bench/options.hpp"
#include "bench/bench_map.hpp"
#include "tiles/encode/dagmh_dictionary.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/vsdag_encode.hpp"

namespace {

using namespace st::bench;

uint32_t g_depth_bits = st::vsdag::kDefaultZBits;  // --depth-bits: the vsdag depth resolution

const st::Encoding kEncodings[] = {st::Encoding::mh, st::Encoding::mmh, st::Encoding::dagmh};

struct EncodingResult {
  uint64_t bytes = 0;
  double seconds = 0;
  std::string error;
};

struct Row {
  std::string scene;
  bool static_rule = false;  // the static-geometry interval rule (row "NAME/st")
  uint32_t level = 0;
  bool whole = true;  // whole-map encode (else per-tile subtrees + coarse top)
  bool zstd = true;   // zstd_bytes measured
  uint64_t raw_bytes = 0, zstd_bytes = 0, nodes = 0, valued = 0, tiles = 0;
  double trace_s = 0, zstd_s = 0, bottom_up_s = 0, stitch_s = 0, top_down_s = -1, wall_s = 0;
  std::map<st::Encoding, EncodingResult> enc;
  EncodingResult vsdag;  // sum over 4096^2 tiles
  // Tiles mode: DAG-MH with a pack dictionary over the tiles and the coarse top
  // (tiles/encode/dagmh_dictionary.hpp): the rewritten buffers plus the dictionary, once.
  uint64_t dag_dict_bytes = 0, dag_dict_only = 0;
  std::vector<std::vector<uint8_t>> dag_buffers;
};

// zstd of one tile's first-hit depths (row-major float32, as a raw shadow map stores them).
uint64_t zstd_tile(const st::IntervalTile& t, int level, std::vector<float>& raw, std::vector<char>& out) {
  raw.resize(t.data.size());
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = t.data[i].lo;
  const size_t in_bytes = raw.size() * sizeof(float);
  out.resize(ZSTD_compressBound(in_bytes));
  size_t n = ZSTD_compress(out.data(), out.size(), raw.data(), in_bytes, level);
  if (ZSTD_isError(n)) throw st::Error(std::string("zstd: ") + ZSTD_getErrorName(n));
  return n;
}

// Coarse top for the per-tile mode: the hierarchy over the tiles' root intervals.
st::IntervalTile root_grid(const std::vector<st::Interval>& roots, uint32_t grid_level) {
  st::IntervalTile g;
  g.level = grid_level;
  g.width = g.height = 1u << grid_level;
  g.data = roots;
  return g;
}

Row run_one(const std::string& scene_name, bool static_rule, const BoundsSource& tracer, uint32_t level, unsigned workers,
            int zstd_level, uint32_t zstd_max, uint32_t whole_max) {
  Row row;
  row.scene = scene_name;
  row.static_rule = static_rule;
  row.level = level;
  row.whole = level <= whole_max;
  row.zstd = level <= zstd_max;
  row.raw_bytes = (uint64_t(1) << (2 * level)) * sizeof(float);
  std::mutex mu;
  const uint32_t grid_level = level > 12 ? level - 12 : 0, grid = 1u << grid_level;
  std::vector<st::Hierarchy> tiles(row.whole ? size_t(grid) * grid : 0);
  std::vector<st::Interval> roots(size_t(grid) * grid);
  uint32_t tiles_done = 0;  // per-tile mode, under mu
  auto t0 = Clock::now();
  TiledRun run = trace_and_build_tiles(
      tracer, level, workers,
      [&](const TileJob& job) {
        if (!row.zstd) return;
        thread_local std::vector<float> raw;
        thread_local std::vector<char> out;
        uint64_t n = zstd_tile(job.intervals, zstd_level, raw, out);
        std::lock_guard<std::mutex> lock(mu);
        row.zstd_bytes += n;
      },
      [&](uint32_t i, st::Hierarchy&& h) {
        const st::HNode& r = h.levels[0][0];
        roots[i] = {r.lo, r.hi};
        {
          EncodingResult v;
          auto a = Clock::now();
          try {
            v.bytes = st::encode_vsdag(h, st::VsdagOptions{g_depth_bits}).size();
          } catch (const std::exception& ex) {
            v.error = ex.what();
          }
          v.seconds = seconds_since(a);
          std::lock_guard<std::mutex> lock(mu);
          row.vsdag.bytes += v.bytes, row.vsdag.seconds += v.seconds;
          if (!v.error.empty()) row.vsdag.error = v.error;
        }
        if (row.whole) {
          tiles[i] = std::move(h);
          return;
        }
        // Per-tile mode: encode now, keep only the sizes.
        std::map<st::Encoding, EncodingResult> local;
        for (st::Encoding e : kEncodings) {
          auto a = Clock::now();
          std::vector<uint8_t> buf;
          try {
            buf = st::encode(h, e);
            local[e].bytes = buf.size();
          } catch (const std::exception& ex) {
            local[e].error = ex.what();
          }
          local[e].seconds = seconds_since(a);
          if (e == st::Encoding::dagmh && !buf.empty()) {
            std::lock_guard<std::mutex> lock(mu);
            row.dag_buffers.push_back(std::move(buf));
          }
        }
        std::lock_guard<std::mutex> lock(mu);
        row.nodes += h.node_count(), row.valued += h.valued_count();
        for (auto& [e, r2] : local) {
          row.enc[e].bytes += r2.bytes, row.enc[e].seconds += r2.seconds;
          if (!r2.error.empty()) row.enc[e].error = r2.error;
        }
        // Progress of a long per-tile run (stderr): running sums over the tiles so far.
        if (++tiles_done % 16 == 0)
          std::fprintf(stderr, "  %s %s^2: %u of %u tiles, %.0f s, DAG-MH %llu B, vsdag %llu B so far (load %.1f)\n",
                       scene_name.c_str(), side_name(level).c_str(), tiles_done, grid * grid, seconds_since(t0),
                       (unsigned long long)row.enc[st::Encoding::dagmh].bytes, (unsigned long long)row.vsdag.bytes,
                       load_average());
      });
  row.tiles = uint64_t(grid) * grid;
  row.trace_s = run.trace_s, row.zstd_s = run.per_tile_s, row.bottom_up_s = run.bottom_up_s;
  if (row.whole) {
    auto a = Clock::now();
    st::Hierarchy h = grid_level ? st::stitch_tiles(std::move(tiles), grid_level) : std::move(tiles[0]);
    row.stitch_s = seconds_since(a);
    row.nodes = h.node_count(), row.valued = h.valued_count();
    for (st::Encoding e : kEncodings) {
      auto b = Clock::now();
      try {
        row.enc[e].bytes = st::encode(h, e).size();
      } catch (const std::exception& ex) {
        row.enc[e].error = ex.what();
      }
      row.enc[e].seconds = seconds_since(b);
    }
  } else {
    auto a = Clock::now();
    st::Hierarchy top = st::build_hierarchy(root_grid(roots, grid_level));
    row.stitch_s = seconds_since(a);
    row.nodes += top.node_count(), row.valued += top.valued_count();
    for (st::Encoding e : kEncodings) {
      auto b = Clock::now();
      try {
        std::vector<uint8_t> buf = st::encode(top, e);
        row.enc[e].bytes += buf.size();
        if (e == st::Encoding::dagmh) row.dag_buffers.push_back(std::move(buf));
      } catch (const std::exception& ex) {
        row.enc[e].error = ex.what();
      }
      row.enc[e].seconds += seconds_since(b);
    }
    if (row.enc[st::Encoding::dagmh].error.empty()) {
      const auto shared = st::dagmh::share_across_tiles(row.dag_buffers);
      row.dag_dict_only = shared.dictionary.size();
      row.dag_dict_bytes = shared.bytes_after + shared.dictionary.size();
    }
    row.dag_buffers.clear();
    row.dag_buffers.shrink_to_fit();
  }
  row.wall_s = seconds_since(t0);
  return row;
}

// Top-down (Alg. 1) next to bottom-up (Alg. 2) on one 4096^2 tile of the map: the centre one.
std::pair<double, double> time_constructions(const BoundsSource& tracer, uint32_t level) {
  const uint32_t side = uint32_t(std::min<uint64_t>(uint64_t(1) << level, kTileSide));
  const uint64_t c = ((uint64_t(1) << level) - side) / 2;
  st::IntervalTile t = tracer.trace({level, c, c, side, side});
  auto a = Clock::now();
  st::Hierarchy bu = st::build_hierarchy(t, st::MhConstruction::bottom_up);
  double bu_s = seconds_since(a);
  a = Clock::now();
  st::Hierarchy td = st::build_hierarchy(t, st::MhConstruction::top_down);
  return {bu_s, seconds_since(a)};
}

std::string fmt_bytes(uint64_t b) {
  char s[32];
  if (b >= (uint64_t(1) << 30)) std::snprintf(s, sizeof s, "%.2f GiB", double(b) / double(1 << 30));
  else if (b >= (1u << 20)) std::snprintf(s, sizeof s, "%.2f MiB", double(b) / double(1 << 20));
  else std::snprintf(s, sizeof s, "%.1f KiB", double(b) / 1024.0);
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scenes = "city,terrain,hairball,soup", light_spec = "sun:azimuth=30,elevation=50", json_path;
  std::string builder = "embree", rules = "default,static";
  uint32_t min_level = 12, max_level = 14, whole_max = 14, zstd_max = st::kMaxLevel;
  unsigned workers = 1;
  int zstd_level = 19;
  bool quick = false;
  try {
    st::bench::Options opt("bench_encodings", "Encoded sizes (DAG-MH 2021 Table 1): MH, MMH, DAG-MH beside the raw map and zstd");
    opt.value("--scenes", scenes, "Procedural names or scene specs, comma-separated")
        .value("--light", light_spec, "Light spec")
        .with("--min-res", [&](const std::string& v) { min_level = parse_level(v); }, "Smallest map side [4k]")
        .with("--max-res", [&](const std::string& v) { max_level = parse_level(v); }, "Largest map side [16k]")
        .with("--whole-max", [&](const std::string& v) { whole_max = parse_level(v); }, "Largest side whose whole-map hierarchy is kept [16k]")
        .value("--workers", workers, "Worker threads")
        .value("--zstd-level", zstd_level, "zstd level of the raw map's chunks")
        .with("--zstd-max-res", [&](const std::string& v) { zstd_max = parse_level(v); }, "Largest side compressed with zstd [all]")
        .flag("--quick", quick, "2K^2 only")
        .value("--depth-bits", g_depth_bits, "Depth bits of the encodings")
        .value("--json", json_path, "Write the rows as JSON to PATH")
        .value("--builder", builder, "Where the bounds come from: embree or raster")
        .value("--intervals", rules, "Interval rules for open scenes: default, static (comma-separated)");
    opt.parse(argc, argv);
    workers = std::max(1u, workers);
    for (const std::string& r : split_list(rules))
      if (r != "default" && r != "static") throw st::Error("--intervals: expected default or static, got '" + r + "'");
    if (builder != "embree" && builder != "raster")
      throw st::Error("--builder: expected embree or raster, got '" + builder + "'");
    if (quick) min_level = max_level = 11;
    if (min_level > max_level) throw st::Error("--min-res is above --max-res");

    std::printf("bench_encodings: light %s, bounds from %s, zstd level %d on 4096^2 chunks of the raw map, "
                "%u worker(s), %u cores, load %.1f\n",
                light_spec.c_str(), builder.c_str(), zstd_level, workers, std::thread::hardware_concurrency(),
                load_average());
    std::vector<Row> rows;
    nlohmann::json scene_info = nlohmann::json::array();
    for (const std::string& name : split_list(scenes)) {
      const std::string spec = name.find(':') == std::string::npos ? "procedural:" + name : name;
      st::Scene scene = st::load_scene(spec);
      st::LightSpace light = st::LightSpace::fit(st::LightSpec::parse(light_spec), scene.bounds());
      const bool open = has_open_mesh(scene);
      for (const std::string& rule : split_list(rules)) {
        const bool static_rule = rule == "static";
        if (static_rule && !open) continue;  // identical to the default rule on all-closed scenes
        const std::string label = name + (static_rule ? "/st" : "");
        BoundsSource tracer(scene, light, static_rule ? "embree" : builder, static_rule);
        auto [bu_s, td_s] = time_constructions(tracer, std::min<uint32_t>(max_level, 12));
        scene_info.push_back({{"scene", spec}, {"label", label}, {"intervals", rule},
                              {"builder", static_rule ? "embree" : builder}, {"triangles", tracer.triangle_count()},
                              {"closed_triangles", scene.closed_triangle_count()},
                              {"exit_depths", tracer.traces_exit_depths()}, {"setup_s", tracer.setup_seconds()},
                              {"tile_bottom_up_s", bu_s}, {"tile_top_down_s", td_s},
                              {"tile_side", std::min<uint64_t>(uint64_t(1) << std::min<uint32_t>(max_level, 12), kTileSide)}});
        std::printf("  %s (%s intervals, %s): %llu triangles (%zu in closed meshes), exit depths %s; one %s^2 tile: "
                    "bottom-up %.2f s, top-down %.2f s\n",
                    spec.c_str(), rule.c_str(), static_rule ? "embree" : builder.c_str(),
                    (unsigned long long)tracer.triangle_count(), scene.closed_triangle_count(),
                    tracer.traces_exit_depths() ? "yes" : "no", side_name(std::min<uint32_t>(max_level, 12)).c_str(),
                    bu_s, td_s);
        std::fflush(stdout);
        for (uint32_t level = min_level; level <= max_level; level += 2) {
          Row r = run_one(label, static_rule, tracer, level, workers, zstd_level, zstd_max, whole_max);
          if (level == std::min<uint32_t>(max_level, 12)) r.top_down_s = td_s;
          rows.push_back(r);
          std::printf("  %s %s^2 done in %.1f s (load %.1f)\n", label.c_str(), side_name(level).c_str(), r.wall_s,
                      load_average());
          std::fflush(stdout);
        }
      }
    }

    std::printf("\nBytes (DAG-MH 2021 Table 1 shape); raw = 4 N^2 (float32 first-hit depths); zstd = sum over 4096^2 "
                "chunks\n");
    std::printf("%-9s %5s %11s %11s %11s %11s %11s %9s %11s %9s %10s %10s %5s\n", "scene", "side", "raw", "zstd", "MH",
                "MMH", "DAG-MH", "DAG/MMH", "DAG+dict", "+dict/MMH", "MH/raw %", "DAG/raw %", "mode");
    for (const Row& r : rows) {
      auto b = [&](st::Encoding e) {
        const EncodingResult& x = r.enc.at(e);
        return x.error.empty() ? fmt_bytes(x.bytes) : std::string("error");
      };
      const double mh = double(r.enc.at(st::Encoding::mh).bytes), mmh = double(r.enc.at(st::Encoding::mmh).bytes),
                   dag = double(r.enc.at(st::Encoding::dagmh).bytes);
      char with_dict[32] = "-", dict_ratio[32] = "-";
      if (r.dag_dict_bytes) {
        std::snprintf(with_dict, sizeof with_dict, "%s", fmt_bytes(r.dag_dict_bytes).c_str());
        std::snprintf(dict_ratio, sizeof dict_ratio, "%.3f", double(r.dag_dict_bytes) / mmh);
      }
      std::printf("%-9s %5s %11s %11s %11s %11s %11s %9.3f %11s %9s %10.4f %10.4f %5s\n", r.scene.c_str(),
                  side_name(r.level).c_str(), fmt_bytes(r.raw_bytes).c_str(),
                  r.zstd ? fmt_bytes(r.zstd_bytes).c_str() : "-",
                  b(st::Encoding::mh).c_str(), b(st::Encoding::mmh).c_str(), b(st::Encoding::dagmh).c_str(), dag / mmh,
                  with_dict, dict_ratio, 100 * mh / double(r.raw_bytes), 100 * dag / double(r.raw_bytes),
                  r.whole ? "whole" : "tiles");
    }
    std::printf("\nVoxel shadow DAG (per 4096^2 tile, %u depth bits) next to DAG-MH\n", g_depth_bits);
    std::printf("%-9s %5s %11s %11s %9s %12s %10s %9s  %s\n", "scene", "side", "DAG-MH", "VSDAG", "VS/DAG", "VS/16-bit %",
                "VS/raw %", "enc VS s", "contract");
    for (const Row& r : rows)
      std::printf("%-9s %5s %11s %11s %9.3f %12.4f %10.4f %9.2f  %s\n", r.scene.c_str(), side_name(r.level).c_str(),
                  fmt_bytes(r.enc.at(st::Encoding::dagmh).bytes).c_str(),
                  r.vsdag.error.empty() ? fmt_bytes(r.vsdag.bytes).c_str() : "error",
                  double(r.vsdag.bytes) / double(r.enc.at(st::Encoding::dagmh).bytes),
                  100 * double(r.vsdag.bytes) / double(r.raw_bytes / 2), 100 * double(r.vsdag.bytes) / double(r.raw_bytes),
                  r.vsdag.seconds, r.static_rule ? "static" : "closed");
    std::printf("(voxel paper, all-closed scenes with the closed-object rule: 0.04-0.07%% of a 16-bit map at 256K^2)\n"
                "contract (VSDAG.md): closed = exact for every receiver outside the slabs of lo and hi, lo..hi the\n"
                "  closed-object interval (hi = lo on open surfaces); static = the same on the static-geometry\n"
                "  interval, so exact only for receivers on surfaces (an open surface's hi reaches the next one)\n");
    for (const Row& r : rows)
      if (!r.vsdag.error.empty())
        std::printf("error: %s %s vsdag: %s\n", r.scene.c_str(), side_name(r.level).c_str(), r.vsdag.error.c_str());
    std::printf("mode: whole = one encode of the stitched whole-map hierarchy; tiles = sum of per-4096^2-tile "
                "encodes + the coarse top over the tiles' roots (whole map kept out of memory)\n");
    std::printf("DAG+dict (tiles mode): the same DAG-MH buffers sharing their common subtrees through one pack "
                "dictionary (tiles/encode/dagmh_dictionary.hpp), dictionary bytes included once\n");

    std::printf("\nConstruction seconds per stage (summed call times; trace uses all cores itself)\n");
    std::printf("%-9s %5s %8s %8s %8s %8s %9s %8s %8s %8s %8s %12s\n", "scene", "side", "trace", "zstd", "bot-up",
                "top-down", "stitch", "enc MH", "enc MMH", "enc DAG", "wall", "nodes");
    for (const Row& r : rows) {
      char td[16] = "-";
      if (r.top_down_s >= 0) std::snprintf(td, sizeof td, "%.2f", r.top_down_s);
      std::printf("%-9s %5s %8.2f %8.2f %8.2f %8s %9.2f %8.2f %8.2f %8.2f %8.1f %12llu\n", r.scene.c_str(),
                  side_name(r.level).c_str(), r.trace_s, r.zstd_s, r.bottom_up_s, td, r.stitch_s,
                  r.enc.at(st::Encoding::mh).seconds, r.enc.at(st::Encoding::mmh).seconds,
                  r.enc.at(st::Encoding::dagmh).seconds, r.wall_s, (unsigned long long)r.nodes);
    }
    std::printf("(top-down: one %s^2 tile, next to bottom-up on that tile in the scene lines above; "
                "stitch in tiles mode = building the coarse top)\n",
                side_name(std::min<uint32_t>(max_level, 12)).c_str());
    for (const Row& r : rows)
      for (auto& [e, x] : r.enc)
        if (!x.error.empty())
          std::printf("error: %s %s %s: %s\n", r.scene.c_str(), side_name(r.level).c_str(), st::to_string(e).c_str(),
                      x.error.c_str());

    std::printf("\nTargets: DAG-MH <= 0.6x MMH bytes at 64K^2 on city and terrain; MH <= 0.1%% of raw at "
                "64K^2 city\n");
    for (const Row& r : rows) {
      const double mh = double(r.enc.at(st::Encoding::mh).bytes), mmh = double(r.enc.at(st::Encoding::mmh).bytes),
                   dag = double(r.enc.at(st::Encoding::dagmh).bytes);
      if (r.scene == "city" || r.scene == "terrain")
        std::printf("  %-8s %5s DAG-MH/MMH = %.3f (target <= 0.6%s) %s\n", r.scene.c_str(), side_name(r.level).c_str(),
                    dag / mmh, r.level == 16 ? "" : ", stated for 64K", dag / mmh <= 0.6 ? "met" : "NOT met");
      if ((r.scene == "city" || r.scene == "terrain") && r.dag_dict_bytes)
        std::printf("  %-8s %5s DAG-MH+dict/MMH = %.3f (target <= 0.6%s) %s\n", r.scene.c_str(), side_name(r.level).c_str(),
                    double(r.dag_dict_bytes) / mmh, r.level == 16 ? "" : ", stated for 64K",
                    double(r.dag_dict_bytes) / mmh <= 0.6 ? "met" : "NOT met");
      if (r.scene == "city")
        std::printf("  %-8s %5s MH/raw = %.4f%% (target <= 0.1%%%s) %s\n", r.scene.c_str(), side_name(r.level).c_str(),
                    100 * mh / double(r.raw_bytes), r.level == 16 ? "" : ", stated for 64K",
                    mh / double(r.raw_bytes) <= 0.001 ? "met" : "NOT met");
    }

    if (!json_path.empty()) {
      nlohmann::json j{{"bench", "encodings"}, {"light", light_spec}, {"zstd_level", zstd_level},
                       {"zstd_chunk_side", kTileSide}, {"workers", workers},
                       {"cores", std::thread::hardware_concurrency()}, {"load_average_end", load_average()},
                       {"scenes", scene_info}};
      for (const Row& r : rows) {
        nlohmann::json enc;
        for (auto& [e, x] : r.enc)
          enc[st::to_string(e)] = {{"bytes", x.bytes}, {"encode_s", x.seconds}, {"error", x.error}};
        const double mh = double(r.enc.at(st::Encoding::mh).bytes), mmh = double(r.enc.at(st::Encoding::mmh).bytes),
                     dag = double(r.enc.at(st::Encoding::dagmh).bytes);
        enc["vsdag_per_tile"] = {{"bytes", r.vsdag.bytes}, {"encode_s", r.vsdag.seconds}, {"error", r.vsdag.error}};
        j["results"].push_back({{"scene", r.scene}, {"intervals", r.static_rule ? "static" : "default"}, {"side", uint64_t(1) << r.level}, {"level", r.level},
                                {"mode", r.whole ? "whole" : "tiles"}, {"tiles", r.tiles},
                                {"raw_bytes", r.raw_bytes},
                                {"zstd_bytes", r.zstd ? nlohmann::json(r.zstd_bytes) : nlohmann::json(nullptr)}, {"encodings", enc},
                                {"dagmh_over_mmh", dag / mmh}, {"mh_over_raw", mh / double(r.raw_bytes)},
                                {"dagmh_dict_bytes", r.dag_dict_bytes ? nlohmann::json(r.dag_dict_bytes) : nlohmann::json(nullptr)},
                                {"dagmh_dictionary_bytes", r.dag_dict_only},
                                {"dagmh_dict_over_mmh", r.dag_dict_bytes ? nlohmann::json(double(r.dag_dict_bytes) / mmh) : nlohmann::json(nullptr)},
                                {"nodes", r.nodes}, {"valued", r.valued},
                                {"seconds", {{"trace", r.trace_s}, {"zstd", r.zstd_s}, {"bottom_up", r.bottom_up_s},
                                             {"top_down_one_tile", r.top_down_s}, {"stitch_or_top", r.stitch_s},
                                             {"wall", r.wall_s}}}});
      }
      std::ofstream out(json_path);
      if (!(out << j.dump(2) << "\n")) throw st::Error("bench_encodings: cannot write " + json_path);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_encodings: %s\n", e.what());
    return 1;
  }
  return 0;
}

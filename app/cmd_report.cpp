// `shadowtile report --scene SCENE --light SPEC [--resolution R] [--out DIR] ...`:
// (a) shadow error against ray-traced ground truth vs evaluation time per frame, across
//     encodings, PCF sizes and hierarchy levels, next to uncompressed float maps (full
//     resolution; the largest that fits in the compressed map's memory; one level lower);
// (c) hierarchical filtering (MH 2016 §3.3, the level from each pixel's footprint, two
//     levels blended) next to fixed-level PCF, both against the footprint reference
//     (supersampled ray-traced visibility over the kernel scaled to the pixel);
// (b) error against time since a camera cut while tiles stream from an in-process server
//     into a client (progressive refinement: coarser levels answer until tiles arrive).
// Writes report.txt, report.json and report.html (scripts/html_report.py draws the plots).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "loadgen/camera_path.hpp"
#include "loadgen/view_tiles.hpp"
#include "server/server.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "render/render_error.hpp"
#include "scene/scene.hpp"
#include "app/command.hpp"
#include "app/html_page.hpp"
#include "app/pcf_option.hpp"
#include "app/public_map.hpp"
#include "common/error.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/page_table.hpp"

namespace st::cli {
namespace {

using nlohmann::json;
using Clk = std::chrono::steady_clock;

struct ReportArgs {
  std::string scene, light, resolution = "2048", out = "report-out", encodings = "mh,mmh,dagmh,vsdag", size = "320x180";
  uint32_t frames = 4;
  std::vector<uint32_t> pcf = {3, 5};  // PCF kernel sides
  double cache_mb = 64, sample_ms = 5;
  std::optional<uint32_t> skip_level;  // the packs' K (default: the build's)
  uint32_t tile_bytes = 64 * 1024;
};

struct Row {
  std::string map, what;
  uint32_t level = 0, pcf = 0;
  uint64_t bytes = 0;
  double error = 0;          // single tap: fraction differing; PCF: mean |diff|
  double ms_per_frame = 0;
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> v;
  std::stringstream ss(s);
  for (std::string x; std::getline(ss, x, ',');)
    if (!x.empty()) v.push_back(x);
  return v;
}

// Stored bytes a client holds for the whole map: every tile's encoded (raw) size plus the
// skip grid and the map preview (grid_bytes holds both): what "the same memory" means for
// the uncompressed baselines.
uint64_t resident_bytes(const PackReader& r) {
  uint64_t b = r.grid_bytes().size();
  for (const TileIndexEntry& e : r.tiles()) b += e.raw_size;
  return b;
}

// What a client answers from the map info alone, with no tile at hand: the skip grid and,
// with `preview`, the map preview (MapPreview::coarse_answer, what RemoteMap answers on a
// miss). Deterministic, unlike the curve's first sample, during which the tiles its own
// misses asked for may already arrive.
class MapInfoEvaluator final : public Evaluator {
 public:
  MapInfoEvaluator(const PackReader& r, bool preview) : r_(r), preview_(preview) {}
  uint32_t finest_level() const override { return r_.map_level(); }
  float depth(uint32_t level, uint64_t x, uint64_t y) const override {
    if (!texel_in_map(r_.map_level(), level, x, y)) return kLitDepth;
    const PageHit hit = walk_page_table(r_.grid(), level, x, y,
                                        [](uint64_t, const GridEntry&) -> const CutGrid* { return nullptr; });
    return preview_ ? r_.preview().coarse_answer(r_.skip_level(), hit, level, x, y) : hit.value;
  }

 private:
  const PackReader& r_;
  bool preview_;
};

struct RefinementPoint {
  double ms;
  double error;
  size_t resident_cells;
};

// Cut to frame f's view with an empty cache; sample the error every sample_ms until all
// needed cells are resident (then one more sample), or 60 s.
std::vector<RefinementPoint> refinement(const std::string& pack_path, const std::string& name,
                                        const LightSpace& light, const FrameTruth& f, double cache_mb,
                                        double sample_ms, size_t& cells_total) {
  server::Catalog cat;
  cat.add(name, pack_path);
  server::ServerOptions so;
  so.port = 0;
  so.log = [](const std::string&) {};
  server::Server srv(std::move(cat), so);
  srv.start();
  client::ClientOptions co;
  co.client_name = "shadowtile-report";
  std::vector<RefinementPoint> pts;
  co.cache_bytes = uint64_t(cache_mb * 1048576.0);  // everything per slot counted (client.hpp)
  client::Client cl({"127.0.0.1", srv.port()}, co);
  client::Map map = cl.open(name);
  const MapEvaluator eval(map);  // the public API's lookups (app/public_map.hpp)
  const uint32_t L = map.finest_level();
  std::vector<std::pair<double, double>> uv;
  for (uint32_t i : f.lit_facing) {
    const LightPoint lp = lookup_point(f.receivers[i], light, L);
    uv.emplace_back(lp.u, lp.v);
  }
  std::vector<int64_t> cell_of;
  const std::vector<TexelCell> cells = cells_under(uv, L, map.info().skip_level, &cell_of);
  cells_total = cells.size();
  // The answer at the cut itself, before any request: what the map info alone gives
  // (the skip grid's level K and the map preview's levels K+1 .. K+p below it). Later samples are timed from their start; tiles keep
  // arriving while a sample evaluates the frame.
  pts.push_back({0.0, frame_error(eval, light, f, 0, L).fraction(), 0});
  const auto t0 = Clk::now();
  // Requests ordered by the error they can remove: a cell's tiles change the answers of
  // the receivers that look up in it, so cells serving more receivers go first (ties:
  // the nearest receiver first). Cells in order of first appearance would be screen order.
  std::vector<double> nearest(cells.size(), INFINITY);
  std::vector<uint64_t> served(cells.size(), 0);
  for (size_t i = 0; i < cell_of.size(); ++i)
    if (cell_of[i] >= 0) {
      nearest[size_t(cell_of[i])] = std::min(nearest[size_t(cell_of[i])], f.receivers[f.lit_facing[i]].distance);
      ++served[size_t(cell_of[i])];
    }
  std::vector<size_t> order(cells.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return served[a] != served[b] ? served[a] > served[b] : nearest[a] < nearest[b];
  });
  for (size_t r = 0; r < order.size(); ++r) {
    const auto& c = cells[order[r]];
    map.request_region(L, c.x0, c.y0, c.side, c.side, uint16_t(60000 - std::min<size_t>(r, 50000)));
  }
  for (bool last = false;;) {
    const double ms = std::chrono::duration<double, std::milli>(Clk::now() - t0).count();
    size_t resident = 0;
    for (const auto& c : cells) resident += map.region_resident(L, c.x0, c.y0, c.side, c.side);
    const FrameError e = frame_error(eval, light, f, 0, L);
    pts.push_back({ms, e.fraction(), resident});
    if (last || ms > 60000) break;
    last = resident == cells.size();
    if (!last) std::this_thread::sleep_for(std::chrono::microseconds(int64_t(sample_ms * 1000)));
  }
  srv.stop();
  return pts;
}

void run_report(const ReportArgs& a) {
  const uint32_t L = parse_resolution(a.resolution);
  uint32_t w = 0, h = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &w, &h) != 2 || w == 0 || h == 0 || w > 4096 || h > 4096)
    throw Error("--size: expected WxH (1..4096), got '" + a.size + "'");
  std::vector<uint32_t> radii;  // the measuring code's kernels: side 2R+1 (the single tap is always measured)
  for (uint32_t s : a.pcf) radii.push_back((checked_pcf_side("--pcf", s, 3) - 1) / 2);
  std::filesystem::create_directories(a.out);
  const Scene scene = load_scene(a.scene);
  const LightSpace light = LightSpace::fit(LightSpec::parse(a.light), scene.bounds());
  std::printf("%s\n", summary(scene).c_str());

  // Packs, one per encoding.
  struct Built {
    std::string enc, path;
    std::shared_ptr<PackReader> reader;
    uint64_t memory = 0;
    uint32_t slab_bits = 0;  // vsdag: its depth resolution (not lossless; VSDAG.md contract)
  };
  std::vector<Built> packs;
  for (const std::string& enc : split(a.encodings)) {
    MapBuildOptions o;
    o.map_level = L;
    o.encoding = parse_encoding(enc);
    o.skip_level = a.skip_level;
    o.tile_bytes = a.tile_bytes;
    o.scene_spec = a.scene;
    o.light_spec = a.light;
    Built b{enc, a.out + "/report_" + enc + ".pack", nullptr, 0,
            o.encoding == Encoding::vsdag ? o.vsdag_z_bits : 0};
    const auto r = build_map(scene, light, o, b.path);
    b.reader = PackReader::open(b.path);
    b.memory = resident_bytes(*b.reader);
    std::printf("built %s: %.2f MiB pack, %.2f MiB resident (%.1f s)\n", enc.c_str(), double(r.pack_bytes) / 1048576,
                double(b.memory) / 1048576, r.wall_seconds);
    packs.push_back(std::move(b));
  }
  if (packs.empty()) throw Error("--encodings: none given");

  // Uncompressed baselines: full resolution, the largest that fits in the smallest
  // compressed map's memory, and one level lower.
  uint64_t budget = packs[0].memory;
  for (const Built& b : packs) budget = std::min(budget, b.memory);
  uint32_t lm = 0;
  while (lm + 1 <= L && (uint64_t(4) << (2 * (lm + 1))) <= budget) ++lm;
  const DepthBoundsTracer bounds(scene, light);
  std::vector<std::pair<std::string, std::unique_ptr<FlatMapEvaluator>>> flats;
  for (uint32_t lv : {L, lm, lm > 0 ? lm - 1 : 0}) {
    const uint64_t side = uint64_t(1) << lv;
    if (side * side > DepthBoundsTracer::kMaxRegionTexels) continue;
    const IntervalTile t = bounds.trace({lv, 0, 0, uint32_t(side), uint32_t(side)});
    std::string label = "float " + std::to_string(side) + "^2" + (lv == L ? " (full)" : lv == lm ? " (same mem)" : " (lower)");
    if (std::none_of(flats.begin(), flats.end(), [&](const auto& f) { return f.first == label; }))
      flats.emplace_back(label, std::make_unique<FlatMapEvaluator>(t, lv == L));
  }

  // The camera path: a flyover over the map's footprint (loadgen/camera_path.hpp).
  const loadgen::WorldFrame world = loadgen::world_frame(packs[0].reader->header(), packs[0].reader->grid());
  const loadgen::CameraPath path(loadgen::PathKind::flyover, world, 7, 0);
  const SceneTracer tracer(scene, light);
  std::vector<FrameTruth> frames;
  for (uint32_t i = 0; i < a.frames; ++i) {
    Camera cam = path.at(3.0 * i);
    cam.aspect = double(w) / h;
    frames.push_back(make_frame_truth(tracer, cam, w, h, L, radii));
  }
  // Footprint references for hierarchical filtering: single tap and every PCF radius,
  // at the pixel angle of the frame's vertical field of view (as `render --filter`).
  std::vector<uint32_t> filter_radii = {0};
  for (uint32_t r : radii)
    if (std::find(filter_radii.begin(), filter_radii.end(), r) == filter_radii.end()) filter_radii.push_back(r);
  for (FrameTruth& f : frames)
    add_footprint_truth(tracer, f, L, filter_radii,
                        2 * std::tan(f.camera.fov_deg * 3.14159265358979323846 / 360) / double(h));

  // (a) error against evaluation time.
  std::vector<Row> rows;
  auto measure = [&](const std::string& map, const std::string& what, const Evaluator& eval, uint64_t bytes,
                     uint32_t pcf, uint32_t level) {
    Row r{map, what, level, pcf, bytes, 0, 0};
    uint64_t n = 0, diff = 0;
    double abs_sum = 0, secs = 0;
    for (const FrameTruth& f : frames) {
      const FrameError e = frame_error(eval, light, f, pcf, level);
      n += e.receivers, diff += e.differing, abs_sum += e.mean_abs * double(e.receivers), secs += e.seconds;
    }
    r.error = pcf == 0 ? (n ? double(diff) / double(n) : 0) : (n ? abs_sum / double(n) : 0);
    r.ms_per_frame = secs * 1e3 / double(frames.size());
    rows.push_back(r);
  };
  std::vector<std::unique_ptr<PackEvaluator>> evals;
  for (const Built& b : packs) {
    evals.push_back(std::make_unique<PackEvaluator>(b.reader, 1 << 16));
    const Evaluator& e = *evals.back();
    measure(b.enc, "warm-up", e, b.memory, 0, L);  // opens the tiles: not timed below
    rows.pop_back();
    for (uint32_t lv : {L, L - 1, L - 2}) measure(b.enc, "single tap", e, b.memory, 0, lv);
    for (uint32_t r : radii) measure(b.enc, "pcf " + std::to_string(2 * r + 1) + "x" + std::to_string(2 * r + 1), e, b.memory, r, L);
  }
  for (const auto& [label, f] : flats) {
    measure(label, "single tap", *f, f->bytes(), 0, f->finest_level());
    for (uint32_t r : radii)
      measure(label, "pcf " + std::to_string(2 * r + 1) + "x" + std::to_string(2 * r + 1), *f, f->bytes(), r, f->finest_level());
  }
  // (c) hierarchical filtering next to fixed-level PCF, against the footprint reference.
  struct FilterRow {
    std::string map;
    uint32_t radius = 0;
    uint64_t bytes = 0;
    double fixed = 0, filtered = 0, fixed_ms = 0, filtered_ms = 0;
  };
  std::vector<FilterRow> filter_rows;
  auto measure_filter = [&](const std::string& map, const Evaluator& eval, uint64_t bytes) {
    for (uint32_t radius : filter_radii) {
      FilterRow fr{map, radius, bytes};
      uint64_t n = 0;
      for (const FrameTruth& f : frames) {
        const FrameError x = footprint_error(eval, light, f, radius, false);
        const FrameError y = footprint_error(eval, light, f, radius, true);
        n += x.receivers;
        fr.fixed += x.mean_abs * double(x.receivers), fr.filtered += y.mean_abs * double(y.receivers);
        fr.fixed_ms += x.seconds * 1e3, fr.filtered_ms += y.seconds * 1e3;
      }
      fr.fixed = n ? fr.fixed / double(n) : 0, fr.filtered = n ? fr.filtered / double(n) : 0;
      fr.fixed_ms /= double(frames.size()), fr.filtered_ms /= double(frames.size());
      filter_rows.push_back(fr);
    }
  };
  for (size_t i = 0; i < packs.size(); ++i) measure_filter(packs[i].enc, *evals[i], packs[i].memory);
  for (const auto& [label, f] : flats) measure_filter(label, *f, f->bytes());

  // Lossless check: compressed (every tile resident) vs the uncompressed full map.
  // Only receivers whose lookup depth lies inside their texel's [lo, hi] (inside a closed
  // object along the texel-centre ray) may differ; the rest must be 0 (render_error.hpp).
  // The voxel shadow DAG is checked against its own contract instead: it may also differ
  // in the depth slab of a texel's lo or hi (tiles/core/VSDAG.md), counted apart.
  json lossless = json::object();
  for (size_t i = 0; i < packs.size(); ++i) {
    if (flats.empty() || !flats[0].second->interval(0, 0)) break;  // no full map at this size
    Disagreements n;
    for (const FrameTruth& f : frames) {
      const Disagreements d = count_disagreements(*evals[i], *flats[0].second, light, f, packs[i].slab_bits);
      n.total += d.total, n.within_interval += d.within_interval, n.within_slab += d.within_slab;
    }
    lossless[packs[i].enc] = {{"differing", n.outside()}, {"within_interval", n.within_interval}};
    if (packs[i].slab_bits)
      lossless[packs[i].enc]["within_slab"] = n.within_slab, lossless[packs[i].enc]["slab_bits"] = packs[i].slab_bits;
  }

  // (b) progressive refinement after a cut, per encoding, on frame 0, each sample next to
  // the uncompressed map of the same memory (fully resident: the bar to stay under).
  double same_memory_error = -1;
  for (const auto& [label, f] : flats)
    if (label.find("(same mem)") != std::string::npos)
      same_memory_error = frame_error(*f, light, frames[0], 0, f->finest_level()).fraction();
  json refine = json::object();
  for (size_t i = 0; i < packs.size(); ++i) {
    size_t cells = 0;
    const auto pts = refinement(packs[i].path, "report_" + packs[i].enc, light, frames[0], a.cache_mb, a.sample_ms, cells);
    json arr = json::array();
    for (const auto& p : pts) arr.push_back({p.ms, p.error, p.resident_cells});
    uint64_t below = 0;
    for (const auto& p : pts) below += p.error < same_memory_error;
    const uint32_t L = packs[i].reader->map_level();
    const double grid_only = frame_error(MapInfoEvaluator(*packs[i].reader, false), light, frames[0], 0, L).fraction();
    const double with_preview = frame_error(MapInfoEvaluator(*packs[i].reader, true), light, frames[0], 0, L).fraction();
    refine[packs[i].enc] = {{"cells", cells}, {"columns", {"ms", "error", "resident_cells"}}, {"points", arr},
                            {"final_error", pts.empty() ? 0.0 : pts.back().error},
                            {"ms_to_full", pts.empty() ? 0.0 : pts.back().ms},
                            {"same_memory_float_error", same_memory_error},
                            {"map_info_error", with_preview},
                            {"skip_grid_only_error", grid_only},
                            {"preview_levels", packs[i].reader->preview().levels()},
                            {"preview_bytes", packs[i].reader->preview().serialized_size()},
                            {"samples_below_same_memory_float", below}};
  }
  json flat_lines = json::object();
  for (size_t k = 0; k < flats.size(); ++k) {
    const FrameError e = frame_error(*flats[k].second, light, frames[0], 0, flats[k].second->finest_level());
    flat_lines[flats[k].first] = e.fraction();
  }

  // Outputs.
  std::string table;
  char buf[512];
  std::snprintf(buf, sizeof buf, "%-24s %-12s %5s %10s %12s %10s\n", "map", "lookup", "level", "MiB", "error", "ms/frame");
  table += buf;
  for (const Row& r : rows) {
    std::snprintf(buf, sizeof buf, "%-24s %-12s %5u %10.3f %12.6f %10.2f\n", r.map.c_str(), r.what.c_str(), r.level,
                  double(r.bytes) / 1048576, r.error, r.ms_per_frame);
    table += buf;
  }
  table += "error: single tap = fraction of lit-facing receivers whose lit answer differs from Embree shadow rays;\n"
           "       pcf = mean |PCF - supersampled ray-traced visibility over the kernel|\n";
  table += "\nhierarchical filtering (level from the pixel footprint, two levels blended) vs fixed-level PCF:\n";
  std::snprintf(buf, sizeof buf, "%-24s %-9s %12s %12s %10s %10s\n", "map", "kernel", "fixed err", "filtered err",
                "fixed ms", "filt. ms");
  table += buf;
  for (const FilterRow& r : filter_rows) {
    const std::string k = std::to_string(2 * r.radius + 1) + "x" + std::to_string(2 * r.radius + 1);
    std::snprintf(buf, sizeof buf, "%-24s %-9s %12.6f %12.6f %10.2f %10.2f\n", r.map.c_str(), k.c_str(), r.fixed,
                  r.filtered, r.fixed_ms, r.filtered_ms);
    table += buf;
  }
  table += "error: mean |answer - ray-traced visibility supersampled over the kernel scaled to the pixel footprint|\n"
           "       (render_error.hpp); the float baselines' coarser levels point-sample their finest level\n\n";
  for (auto& [enc, n] : lossless.items()) {
    if (n.contains("within_slab")) {
      std::snprintf(buf, sizeof buf,
                    "contract check %-6s: %llu receivers differ from the uncompressed full map outside its contract "
                    "(every tile resident); %llu more lie in the depth slab of their texel's lo or hi (%u depth bits: "
                    "VSDAG.md), %llu inside [lo, hi]\n",
                    enc.c_str(), (unsigned long long)n["differing"].get<uint64_t>(),
                    (unsigned long long)n["within_slab"].get<uint64_t>(), n["slab_bits"].get<unsigned>(),
                    (unsigned long long)n["within_interval"].get<uint64_t>());
      table += buf;
      continue;
    }
    std::snprintf(buf, sizeof buf,
                  "lossless check %-6s: %llu receivers differ from the uncompressed full map (every tile resident); "
                  "%llu more lie inside their texel's [lo, hi] (in a closed object), where any stored value is lossless\n",
                  enc.c_str(), (unsigned long long)n["differing"].get<uint64_t>(),
                  (unsigned long long)n["within_interval"].get<uint64_t>());
    table += buf;
  }
  for (auto& [enc, r] : refine.items()) {
    std::snprintf(buf, sizeof buf,
                  "refinement %-6s: %zu cells, error %.5f at the cut (map preview: %u levels, %.1f KiB) -> %.5f after "
                  "%.0f ms (full residency)\n",
                  enc.c_str(), size_t(r["cells"]), double(r["points"][0][1]), unsigned(r["preview_levels"]),
                  double(r["preview_bytes"]) / 1024, double(r["final_error"]), double(r["ms_to_full"]));
    table += buf;
    std::snprintf(buf, sizeof buf, "  map info alone (no tile): %.5f with the map preview, %.5f from the skip grid only\n",
                  double(r["map_info_error"]), double(r["skip_grid_only_error"]));
    table += buf;
    if (same_memory_error >= 0) {
      std::snprintf(buf, sizeof buf, "  %zu of %zu samples below the same-memory float map (%.5f); ms:error",
                    size_t(r["samples_below_same_memory_float"]), r["points"].size(), same_memory_error);
      table += buf;
      // The curve itself, thinned to at most 16 samples (the first and the last kept).
      const size_t np = r["points"].size(), step = std::max<size_t>(1, (np + 15) / 16);
      std::vector<size_t> shown;
      for (size_t k = 0; k < np; k += step) shown.push_back(k);
      if (np > 0 && shown.back() != np - 1) shown.push_back(np - 1);
      for (size_t k : shown) {
        std::snprintf(buf, sizeof buf, " %.0f:%.4f%s", double(r["points"][k][0]), double(r["points"][k][1]),
                      double(r["points"][k][1]) < same_memory_error ? "" : "!");
        table += buf;
      }
      table += "   (! = not below)\n";
    }
  }
  for (auto& [label, e] : flat_lines.items()) {
    std::snprintf(buf, sizeof buf, "frame 0 error of %-26s %.5f\n", label.c_str(), double(e));
    table += buf;
  }
  std::printf("%s", table.c_str());
  std::ofstream(a.out + "/report.txt") << table;

  json j;
  j["scene"] = a.scene, j["light"] = a.light, j["level"] = L, j["frames"] = a.frames, j["size"] = a.size;
  j["same_memory_budget_bytes"] = budget;
  json jr = json::array();
  for (const Row& r : rows)
    jr.push_back({{"map", r.map}, {"lookup", r.what}, {"level", r.level}, {"pcf_radius", r.pcf}, {"pcf_side", 2 * r.pcf + 1},
                  {"bytes", r.bytes},
                  {"error", r.error}, {"ms_per_frame", r.ms_per_frame}});
  j["error_vs_time"] = jr;
  j["lossless_disagreements"] = lossless;
  json jf = json::array();
  for (const FilterRow& r : filter_rows)
    jf.push_back({{"map", r.map}, {"pcf_radius", r.radius}, {"pcf_side", 2 * r.radius + 1}, {"bytes", r.bytes}, {"fixed_level_error", r.fixed},
                  {"filtered_error", r.filtered}, {"fixed_level_ms_per_frame", r.fixed_ms},
                  {"filtered_ms_per_frame", r.filtered_ms}});
  j["hierarchical_filtering"] = {{"reference", "ray-traced visibility supersampled over the kernel scaled to the pixel footprint"},
                                 {"rows", jf}};
  j["refinement"] = refine;
  j["uncompressed_frame0_error"] = flat_lines;
  std::ofstream(a.out + "/report.json") << j.dump(2) << "\n";

  std::printf("report: %s/report.{txt,json}\n", a.out.c_str());
  write_html_page("report", a.out + "/report.json", a.out + "/report.html");
}

Register reg_report{"report", "Shadow error vs time: encodings, PCF, levels, uncompressed maps, refinement", [](CLI::App& sub) {
  auto a = std::make_shared<ReportArgs>();
  sub.add_option("--scene", a->scene, "Scene spec or file")->required();
  sub.add_option("--light", a->light, "Light spec")->required();
  sub.add_option("--resolution", a->resolution, "Map resolution (power of two, e.g. 2048, 4k)")->capture_default_str();
  sub.add_option("--out", a->out, "Report folder")->capture_default_str();
  sub.add_option("--encodings", a->encodings, "Comma-separated encodings")->capture_default_str();
  sub.add_option("--frames", a->frames, "Camera frames along the path")->capture_default_str()->check(CLI::Range(1u, 1000u));
  sub.add_option("--size", a->size, "Frame size WxH")->capture_default_str();
  sub.add_option("--pcf", a->pcf, "PCF kernel sides to measure: odd, 3..9")->capture_default_str();
  sub.add_option("--cache-mb", a->cache_mb, "Client tile cache for the refinement run (MiB)")->capture_default_str();
  sub.add_option("--sample-ms", a->sample_ms, "Refinement sampling period (ms)")->capture_default_str();
  sub.add_option("--skip-level", a->skip_level, "Skip level K of the packs (as build --skip-level)");
  sub.add_option("--tile-bytes", a->tile_bytes, "Tile size bound of the packs (as build --tile-bytes)")
      ->capture_default_str();
  sub.callback([a] { run_report(*a); });
}};

}  // namespace
}  // namespace st::cli

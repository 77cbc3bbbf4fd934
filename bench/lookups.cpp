// Lookup speed: single taps, 3x3 and 5x5 PCF per second on each
// encoding (MH quadtree MH §3.2/§3.3, MMH, DAG-MH §3.5) of one traced map, each as a ratio
// to the same lookups on the uncompressed float array of the same map (the hierarchy's
// finest-level values, huge pages requested), in the same run.
//
//   bench_lookups [--scene city] [--light sun:azimuth=30,elevation=50] [--res 16k]
//                 [--lookups 1048576] [--reps 5] [--quick] [--workers 1] [--json PATH]
//                 [--builder embree|raster] [--intervals default|static]
//
// --intervals static: the static-geometry interval rule (voxel shadows 2014 §6.1; Embree
// only), for open scenes such as procedural:soup: an open first hit's hi reaches to just
// below the next surface. The receivers below (lo, just past hi) then lie on surfaces,
// which is what that rule answers exactly. --builder as bench_encodings (bench_map.hpp).
//
// Access patterns, precomputed once and shared by every encoding:
//   random:   uniformly random texels of the finest level;
//   coherent: runs of 256 consecutive texels along a row, each run at a random start
//             (a screen scanline mapped into light space, roughly).
// Receivers come from the traced intervals: half the lookups use lo (a receiver on the
// first surface: lit for every admissible value) and half the next float above hi
// (behind the occluder: shadowed for every admissible value), so every encoding must give
// exactly the uncompressed array's single-tap answers; the bench checks that on every
// position before timing (and the PCF paths against the average of single lookups on a
// sample). Single-threaded, timed in thread-CPU seconds; each figure is the median over --reps passes,
// and the encodings take turns inside each pass so that load changes hit all of them.
// --quick: an 8K^2 map, 128K lookups per pattern, 3 reps.
// The voxel shadow DAG (tiles/core/VSDAG.md) joins when the map is at most 4K^2 (it is
// encoded whole here; packs cut it into tiles): single taps, PCF up to 17x17 by leaf
// popcounts, and "vsdag-raster" = the same PCF visiting the leaves in raster order (the
// voxel paper's baseline for its traversal-order saving). Its receivers on lo or just past
// hi lie in a surface's slab, where the contract lets it differ from the array: those
// differences are counted apart and do not fail the run.
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "bench/options.hpp"
#include "bench/bench_map.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/vsdag_evaluator.hpp"

namespace {

using namespace st::bench;

struct Lookup {
  uint32_t x, y;
  float receiver;
};

// What one pass measures: `op` r = 1 is a single lit test, r > 1 an r x r PCF kernel.
struct Subject {
  std::string name;
  const st::Evaluator* ev = nullptr;  // null: the float array
  uint64_t bytes = 0;
  const st::VsdagEvaluator* vs = nullptr;  // set: PCF by pcf_wide (up to 17x17)
  bool best_order = true;
};


// Thread-CPU seconds for one pass of `op` over `list` (the machine may be shared with more
// runnable threads than cores: CPU time leaves out the time this thread waited for a
// core, wall time does not); `sink` keeps the results alive.
double time_pass(const Subject& s, const FloatMap& map, const std::vector<Lookup>& list, uint32_t r, double& sink) {
  const uint32_t L = map.level;
  double acc = 0;
  const double c0 = thread_cpu_now();
  if (!s.ev) {
    if (r == 1) {
      uint64_t lit = 0;
      for (const Lookup& q : list) lit += q.receiver <= map.at(q.x, q.y);
      acc = double(lit);
    } else {
      for (const Lookup& q : list) acc += array_pcf(map, q.x, q.y, r, q.receiver);
    }
  } else if (r == 1 && s.vs) {
    uint64_t lit = 0;  // one walk to the voxel (Evaluator::lit would bisect the column for depth())
    for (const Lookup& q : list) lit += s.vs->lit_voxel(L, q.x, q.y, q.receiver);
    acc = double(lit);
  } else if (r == 1) {
    uint64_t lit = 0;
    for (const Lookup& q : list) lit += s.ev->lit(q.x, q.y, q.receiver);
    acc = double(lit);
  } else if (s.vs) {
    for (const Lookup& q : list) acc += s.vs->pcf_wide(q.x, q.y, r, q.receiver, s.best_order);
  } else {
    for (const Lookup& q : list) acc += s.ev->pcf(L, q.x, q.y, r, q.receiver);
  }
  double t = thread_cpu_now() - c0;
  sink += acc;
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_spec = "procedural:city", light_spec = "sun:azimuth=30,elevation=50", json_path;
  std::string builder = "embree", rule = "default";
  uint32_t level = 14;
  size_t count = size_t(1) << 20;
  int reps = 5;
  unsigned workers = 1;
  bool quick = false, level_given = false;
  try {
    st::bench::Options opt("bench_lookups", "Lookup speed: single taps and PCF on each encoding beside a float array");
    opt.value("--scene", scene_spec, "Scene spec (a bare name is procedural:NAME)")
        .value("--light", light_spec, "Light spec")
        .with("--res", [&](const std::string& v) { level = parse_level(v), level_given = true; }, "Map side (at least 512) [16k]")
        .with("--lookups", [&](const std::string& v) { count = size_t(std::max(1ll, std::stoll(v))); }, "Lookups per pattern [1048576]")
        .with("--reps", [&](const std::string& v) { reps = std::max(1, std::stoi(v)); }, "Median of R passes [5]")
        .with("--workers", [&](const std::string& v) { workers = unsigned(std::max(1, std::stoi(v))); }, "Worker threads of the build [1]")
        .flag("--quick", quick, "8K^2, 128K lookups, 3 reps")
        .value("--json", json_path, "Write the rows as JSON to PATH")
        .value("--builder", builder, "Where the bounds come from: embree or raster")
        .value("--intervals", rule, "Interval rule: default or static");
    opt.parse(argc, argv);
    if (rule != "default" && rule != "static")
      throw st::Error("--intervals: expected default or static, got '" + rule + "'");
    if (scene_spec.find(':') == std::string::npos) scene_spec = "procedural:" + scene_spec;
    if (quick) {
      if (!level_given) level = 13;
      count = std::min<size_t>(count, size_t(1) << 17);
      reps = std::min(reps, 3);
    }
    if (level < 9) throw st::Error("--res must be at least 512");
    const uint64_t side = uint64_t(1) << level;
    std::printf("bench_lookups: %s, %s, %s^2, %s intervals, bounds from %s, %zu lookups per pattern, median of %d, "
                "load %.1f\n",
                scene_spec.c_str(), light_spec.c_str(), side_name(level).c_str(), rule.c_str(), builder.c_str(), count,
                reps, load_average());
    std::fflush(stdout);

    // Positions first (the receivers are filled in while the tiles are traced).
    std::mt19937_64 rng(20261122);
    std::vector<Lookup> random(count), coherent(count);
    std::vector<uint8_t> behind(2 * count);
    for (auto& q : random) q = {uint32_t(rng() & (side - 1)), uint32_t(rng() & (side - 1)), 0};
    for (size_t i = 0; i < count; i += 256) {
      const uint32_t x0 = uint32_t(rng() % (side - 256)), y = uint32_t(rng() & (side - 1));
      for (size_t k = 0; k < 256 && i + k < count; ++k) coherent[i + k] = {uint32_t(x0 + k), y, 0};
    }
    for (auto& b : behind) b = uint8_t(rng() & 1);
    const uint32_t tile_side = uint32_t(std::min<uint64_t>(side, kTileSide));
    const uint32_t grid = uint32_t(side / tile_side);
    std::vector<std::vector<uint32_t>> by_tile(size_t(grid) * grid);  // indices into random ++ coherent
    auto lookup_at = [&](uint32_t i) -> Lookup& { return i < count ? random[i] : coherent[i - count]; };
    for (uint32_t i = 0; i < 2 * count; ++i) {
      const Lookup& q = lookup_at(i);
      by_tile[(q.y / tile_side) * grid + q.x / tile_side].push_back(i);
    }

    st::Scene scene = st::load_scene(scene_spec);
    st::LightSpace light = st::LightSpace::fit(st::LightSpec::parse(light_spec), scene.bounds());
    const BoundsSource tracer(scene, light, builder, rule == "static");
    std::printf("  %llu triangles, %zu in closed meshes; vsdag contract: %s\n",
                (unsigned long long)tracer.triangle_count(), scene.closed_triangle_count(),
                rule == "static" ? "static-geometry intervals (exact for receivers on surfaces)"
                                 : "closed-object intervals (hi = lo on open surfaces)");
    std::vector<st::Hierarchy> tiles(size_t(grid) * grid);
    std::mutex mu;
    TiledRun run = trace_and_build_tiles(
        tracer, level, workers,
        [&](const TileJob& job) {
          const uint64_t x0 = uint64_t(job.ti) * tile_side, y0 = uint64_t(job.tj) * tile_side;
          for (uint32_t i : by_tile[job.index]) {
            Lookup& q = lookup_at(i);
            const st::Interval& iv = job.intervals.at(uint32_t(q.x - x0), uint32_t(q.y - y0));
            q.receiver = behind[i] ? std::nextafter(iv.hi, INFINITY) : iv.lo;
          }
        },
        [&](uint32_t i, st::Hierarchy&& h) {
          std::lock_guard<std::mutex> lock(mu);
          tiles[i] = std::move(h);
        });
    auto t0 = Clock::now();
    st::Hierarchy h = grid > 1 ? st::stitch_tiles(std::move(tiles), st::log2_exact(grid)) : std::move(tiles[0]);
    const double stitch_s = seconds_since(t0);
    std::printf("  map built: trace %.1f s, bottom-up %.1f s, stitch %.1f s, %zu nodes\n", run.trace_s,
                run.bottom_up_s, stitch_s, h.node_count());
    std::fflush(stdout);

    FloatMap map(level);
    paint_finest(h, map);
    for (int k = 0; k < 1000; ++k) {  // the painted array is the hierarchy's finest level
      const uint64_t x = rng() & (side - 1), y = rng() & (side - 1);
      if (map.at(x, y) != h.depth_at(level, x, y)) throw st::Error("paint_finest disagrees with depth_at");
    }
    const double huge_mib = anon_huge_mib();
    std::printf("  float array %zu MiB, of which in transparent huge pages (process total): %.0f MiB\n",
                map.bytes >> 20, huge_mib);
    const st::Encoding encs[] = {st::Encoding::mh, st::Encoding::mmh, st::Encoding::dagmh};
    std::vector<std::vector<uint8_t>> buffers;
    std::vector<std::unique_ptr<st::Evaluator>> evaluators;
    std::vector<Subject> subjects{{"float array", nullptr, map.bytes}};
    for (st::Encoding e : encs) {
      auto a = Clock::now();
      buffers.push_back(st::encode(h, e));
      const double enc_s = seconds_since(a);
      evaluators.push_back(st::open_encoded(e, buffers.back()));
      subjects.push_back({st::to_string(e), evaluators.back().get(), buffers.back().size()});
      std::printf("  %-6s %12zu bytes, encoded in %.1f s\n", st::to_string(e).c_str(), buffers.back().size(), enc_s);
      std::fflush(stdout);
    }
    // The voxel shadow DAG, encoded whole (at most 4K^2: its build holds the whole map's
    // transitions and min-max pyramid).
    std::vector<uint8_t> vs_buffer;
    std::unique_ptr<st::VsdagEvaluator> vs;
    if (level <= 12) {
      auto a = Clock::now();
      vs_buffer = st::encode(h, st::Encoding::vsdag);
      const double enc_s = seconds_since(a);
      vs = std::make_unique<st::VsdagEvaluator>(vs_buffer);
      subjects.push_back({"vsdag", vs.get(), vs_buffer.size(), vs.get(), true});
      subjects.push_back({"vsdag-raster", vs.get(), vs_buffer.size(), vs.get(), false});
      std::printf("  %-6s %12zu bytes, encoded in %.1f s (16 depth bits)\n", "vsdag", vs_buffer.size(), enc_s);
    } else {
      std::printf("  vsdag: not measured above 4K^2 (whole-map encode)\n");
    }
    h = {};

    // Every encoding gives the array's single-tap answer at every position (lossless).
    uint64_t mismatches = 0;
    for (const auto* list : {&random, &coherent})
      for (const Lookup& q : *list) {
        const bool want = q.receiver <= map.at(q.x, q.y);
        for (const auto& ev : evaluators) mismatches += ev->lit(q.x, q.y, q.receiver) != want;
      }
    std::printf("  lossless check on %zu positions x %zu encodings: %llu mismatches\n", 2 * count,
                evaluators.size(), (unsigned long long)mismatches);
    uint64_t vs_differ = 0, vs_pcf_mismatches = 0;
    if (vs) {
      for (const auto* list : {&random, &coherent})
        for (const Lookup& q : *list) vs_differ += vs->lit(q.x, q.y, q.receiver) != (q.receiver <= map.at(q.x, q.y));
      for (const auto* list : {&random, &coherent})
        for (size_t i = 0; i < std::min<size_t>(count, 4096); ++i)
          for (uint32_t r : {3u, 9u, 17u})
            for (bool best : {true, false}) {
              const Lookup& q = (*list)[i];
              uint32_t lit = 0;
              for (uint32_t j = 0; j < r; ++j)
                for (uint32_t k = 0; k < r; ++k)
                  lit += vs->lit_voxel(level, st::pcf_tap(q.x, k, r, side), st::pcf_tap(q.y, j, r, side), q.receiver);
              vs_pcf_mismatches += vs->pcf_wide(q.x, q.y, r, q.receiver, best) != float(lit) / float(r * r);
            }
      std::printf("  vsdag: %llu of %zu single taps differ from the array (receivers in a surface's slab), "
                  "PCF up to 17x17 vs single voxel lookups: %llu mismatches\n",
                  (unsigned long long)vs_differ, 2 * count, (unsigned long long)vs_pcf_mismatches);
    }
    // The encodings' shared-traversal PCF equals the average of single lookups (the
    // Evaluator base implementation) on a sample of the positions.
    uint64_t pcf_mismatches = 0;
    for (const auto* list : {&random, &coherent})
      for (size_t i = 0; i < std::min<size_t>(count, 4096); ++i)
        for (const auto& ev : evaluators)
          for (uint32_t r : {3u, 5u}) {
            const Lookup& q = (*list)[i];
            pcf_mismatches += ev->pcf(level, q.x, q.y, r, q.receiver) != ev->Evaluator::pcf(level, q.x, q.y, r, q.receiver);
          }
    std::printf("  PCF 3x3/5x5 vs the average of single lookups on %zu positions: %llu mismatches\n",
                2 * std::min<size_t>(count, 4096), (unsigned long long)pcf_mismatches);

    struct Result {
      std::string pattern, subject;
      uint32_t r = 1;
      double seconds = 0;  // median per pass
    };
    std::vector<Result> results;
    double sink = 0;
    const std::pair<const char*, const std::vector<Lookup>*> patterns[] = {{"random", &random}, {"coherent", &coherent}};
    const uint32_t kernels[] = {1, 3, 5, 9, 17};
    // 17x17 exceeds Evaluator::kMaxPcf: only the float array and vsdag run it; vsdag-raster
    // only the kernels whose leaf order matters.
    auto runs = [&](const Subject& s, uint32_t r) {
      if (s.name == "vsdag-raster") return r >= 9;
      return r <= st::Evaluator::kMaxPcf || !s.ev || s.vs;
    };
    for (auto& [pname, list] : patterns)
      for (uint32_t r : kernels) {
        std::vector<std::vector<double>> t(subjects.size());
        for (const Subject& s : subjects)
          if (runs(s, r)) time_pass(s, map, *list, r, sink);  // warm-up
        for (int rep = 0; rep < reps; ++rep)
          for (size_t s = 0; s < subjects.size(); ++s)
            if (runs(subjects[s], r)) t[s].push_back(time_pass(subjects[s], map, *list, r, sink));
        for (size_t s = 0; s < subjects.size(); ++s)
          if (runs(subjects[s], r)) results.push_back({pname, subjects[s].name, r, median(t[s])});
      }

    auto find = [&](const std::string& p, const std::string& s, uint32_t r) {
      for (const Result& x : results)
        if (x.pattern == p && x.subject == s && x.r == r) return x.seconds;
      return 0.0;
    };
    std::printf("\nLookups on %s %s^2 (single thread, thread-CPU time; M/s = kernels per second; x array = time / float-array time "
                "of the same lookups; /single = time / this encoding's single-tap time)\n",
                scene_spec.c_str(), side_name(level).c_str());
    std::printf("%-9s %-6s %-12s %12s %10s %10s %9s %9s\n", "pattern", "kernel", "encoding", "bytes", "M/s", "ns/kernel",
                "x array", "/single");
    nlohmann::json jres = nlohmann::json::array();
    for (const Result& x : results) {
      const double per = x.seconds / double(count);
      const double vs_array = x.seconds / find(x.pattern, "float array", x.r);
      const double vs_single = x.seconds / find(x.pattern, x.subject == "vsdag-raster" ? "vsdag" : x.subject, 1);
      uint64_t bytes = 0;
      for (const Subject& s : subjects)
        if (s.name == x.subject) bytes = s.bytes;
      const std::string kernel = x.r == 1 ? "single" : std::to_string(x.r) + "x" + std::to_string(x.r);
      std::printf("%-9s %-6s %-12s %12llu %10.2f %10.1f %9.2f %9.2f\n", x.pattern.c_str(), kernel.c_str(),
                  x.subject.c_str(), (unsigned long long)bytes, 1e-6 / per, 1e9 * per, vs_array, vs_single);
      jres.push_back({{"pattern", x.pattern}, {"kernel", x.r}, {"subject", x.subject}, {"bytes", bytes},
                      {"seconds_per_pass", x.seconds}, {"lookups_per_pass", count},
                      {"mlookups_per_s", 1e-6 / per}, {"ns_per_lookup", 1e9 * per},
                      {"ratio_to_float_array", vs_array}, {"ratio_to_single", vs_single}});
    }

    std::printf("\nTargets against the measured figures:\n");
    nlohmann::json targets = nlohmann::json::array();
    for (auto& [pname, list] : patterns) {
      (void)list;
      const double single = find(pname, "dagmh", 1) / find(pname, "float array", 1);
      std::printf("  %-9s DAG-MH single lookup = %.2fx uncompressed (target <= 3) %s\n", pname, single,
                  single <= 3 ? "met" : "NOT met");
      targets.push_back({{"target", "dagmh_single_over_array<=3"}, {"pattern", pname}, {"value", single}});
      for (const char* e : {"mh", "mmh", "dagmh"}) {
        const double pcf = find(pname, e, 5) / find(pname, e, 1);
        std::printf("  %-9s %-6s 5x5 PCF = %.2fx a single lookup (target <= 6) %s\n", pname, e, pcf,
                    pcf <= 6 ? "met" : "NOT met");
        targets.push_back({{"target", "pcf5_over_single<=6"}, {"pattern", pname}, {"encoding", e}, {"value", pcf}});
      }
    }
    if (vs)
      for (auto& [pname, list] : patterns) {
        (void)list;
        const double r17 = find(pname, "vsdag", 17) / find(pname, "vsdag", 1);
        std::printf("  %-9s vsdag 17x17 PCF = %.2fx a single tap (voxel paper: at most 4.5) %s\n", pname, r17,
                    r17 <= 4.5 ? "met" : "NOT met");
        targets.push_back({{"target", "vsdag_pcf17_over_single<=4.5"}, {"pattern", pname}, {"value", r17}});
        for (uint32_t r : {9u, 17u}) {
          const double saving = 1 - find(pname, "vsdag", r) / find(pname, "vsdag-raster", r);
          std::printf("  %-9s vsdag %ux%u leaf visit order saves %.1f%% over raster order (paper: 7.5-26.6%%)\n", pname,
                      r, r, 100 * saving);
          targets.push_back({{"target", "vsdag_order_saving"}, {"pattern", pname}, {"kernel", r}, {"value", saving}});
        }
      }
    std::printf("  (sink %.0f, load %.1f)\n", sink, load_average());

    if (!json_path.empty()) {
      nlohmann::json j{{"bench", "lookups"}, {"scene", scene_spec}, {"light", light_spec}, {"intervals", rule},
                       {"builder", builder}, {"side", side},
                       {"level", level}, {"lookups_per_pattern", count}, {"reps", reps},
                       {"lossless_mismatches", mismatches}, {"pcf_mismatches", pcf_mismatches},
                       {"vsdag_taps_differing", vs_differ}, {"vsdag_pcf_mismatches", vs_pcf_mismatches}, {"anon_huge_mib", huge_mib}, {"load_average_end", load_average()},
                       {"build", {{"trace_s", run.trace_s}, {"bottom_up_s", run.bottom_up_s}, {"stitch_s", stitch_s}}},
                       {"results", jres}, {"targets", targets}};
      std::ofstream out(json_path);
      if (!(out << j.dump(2) << "\n")) throw st::Error("bench_lookups: cannot write " + json_path);
    }
    return mismatches == 0 && pcf_mismatches == 0 && vs_pcf_mismatches == 0 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_lookups: %s\n", e.what());
    return 1;
  }
}

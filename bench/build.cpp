// Build benchmark: the depth bounds alone with each builder (the Embree tracer and the
// light-space rasterizer, raster_bounds.hpp) over the same texels, then whole builds with
// each builder and encoding, at one or more resolutions, in the same run: wall time, CPU
// time, peak memory, pack size, texels per second, the thread-seconds of each build stage,
// and how time grows with the texel count (the slope of log time against log texels
// between successive resolutions: 1.0 is linear in texels).
//
//   bench_build [--scene procedural:city] [--light sun:azimuth=30,elevation=50]
//               [--resolutions 4k,16k] [--encodings dagmh,dagmh+dict,mmh] [--builders raster,embree]
//               (builders: raster = the rasterizer with its per-tile skip, exact; raster-off
//               without it; raster-narrow with narrowed intervals in skipped tiles;
//               raster-regions top-down over regions proven by their corners; embree)
//               [--intervals default,static] [--json PATH] [--out DIR]
//
// --resolution R is --resolutions R. 64k is an option (the tracer takes minutes there).
// --intervals lists the interval rules to build each encoding with (default: the
// closed-object rule only; static: the static-geometry interval, map_build.hpp), so the
// pack bytes of the two stand side by side on open scenes; the rasterizer builds only
// the default rule with a sun (the tracer does the rest).
// Encoding `dagmh` builds without the pack dictionary, `dagmh+dict` with it (the build's
// own finish pass, timed with the build; tiles/PACK.md "DAG-MH dictionary"), so the two
// pack sizes stand side by side with MMH's. Each plain DAG-MH build is also followed by a
// line estimating the dictionary from its tiles (tiles/encode/dagmh_dictionary.hpp, not
// timed): pack bytes with the tiles' zlib streams replaced by the rewritten tiles' plus
// the dictionary's, and the tiles' raw bytes (what a client caches) with the dictionary's.
// Each measurement runs in a forked child so that its peak memory (wait4 rusage) is its
// own. The bounds-only passes trace the same level-K cells the build traces, on the same
// worker threads, and throw the intervals away.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/options.hpp"
#include "bench/dagmh_dict_figures.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "common/error.hpp"
#include "tiles/core/resolution.hpp"
#include "tiles/encode/tile_cut.hpp"

namespace {

using Clock = std::chrono::steady_clock;

uint32_t parse_level(const std::string& text) { return st::parse_resolution(text); }

struct Measured {
  nlohmann::json result;
  double wall = 0, cpu = 0, peak_mib = 0;
};

// Runs `job` in a child process; the child prints one JSON line to a pipe.
template <class Job>
Measured in_child(Job job) {
  int fds[2];
  if (pipe(fds) != 0) throw st::Error("pipe failed");
  auto t0 = Clock::now();
  pid_t pid = fork();
  if (pid == 0) {
    close(fds[0]);
    std::string out;
    try {
      out = job().dump();
    } catch (const std::exception& e) {
      out = nlohmann::json{{"error", e.what()}}.dump();
    }
    ssize_t w = write(fds[1], out.data(), out.size());
    (void)w;
    _exit(0);
  }
  close(fds[1]);
  std::string text;
  char buf[4096];
  ssize_t n;
  while ((n = read(fds[0], buf, sizeof buf)) > 0) text.append(buf, size_t(n));
  close(fds[0]);
  int status = 0;
  rusage ru{};
  wait4(pid, &status, 0, &ru);
  Measured m;
  m.wall = std::chrono::duration<double>(Clock::now() - t0).count();
  m.cpu = double(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) + 1e-6 * double(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  m.peak_mib = double(ru.ru_maxrss) / 1024.0;
  m.result = text.empty() ? nlohmann::json{{"error", "child died"}} : nlohmann::json::parse(text);
  return m;
}

// The same cells build_map traces, on as many threads, with `trace` (region -> discard).
template <class Trace>
double bounds_pass(uint32_t L, uint32_t K, Trace trace) {
  const uint64_t cells = uint64_t(1) << K, side = uint64_t(1) << (L - K);
  const uint64_t sub = std::min<uint64_t>(side, st::kMaxTraceSide), per = side / sub;
  std::atomic<uint64_t> next{0};
  const uint64_t total = cells * cells * per * per;
  auto t0 = Clock::now();
  auto work = [&]() {
    for (uint64_t i; (i = next++) < total;) {
      uint64_t c = i / (per * per), s = i % (per * per);
      uint64_t cx = st::morton_compact(c), cy = st::morton_compact(c >> 1);
      trace(st::TraceRegion{L, cx * side + (s % per) * sub, cy * side + (s / per) * sub, uint32_t(sub),
                            uint32_t(sub)});
    }
  };
  std::vector<std::thread> ts;
  for (unsigned k = 0; k < std::max(1u, std::thread::hardware_concurrency()); ++k) ts.emplace_back(work);
  for (auto& t : ts) t.join();
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_spec = "procedural:city", light_spec = "sun:azimuth=30,elevation=50",
              resolutions = "4k,16k", encodings = "dagmh", builders = "raster,embree",
              intervals = "default", json_path, out_dir = "/tmp";
  st::bench::Options opt("bench_build", "Depth bounds and whole builds with each builder and encoding, side by side");
  opt.value("--scene", scene_spec, "Scene spec")
      .value("--light", light_spec, "Light spec")
      .value("--resolutions,--resolution", resolutions, "Map sides, comma-separated (4k,16k,64k)")
      .value("--encodings", encodings, "dagmh, dagmh+dict, mmh, mh (comma-separated)")
      .value("--builders", builders, "raster, raster-off, raster-narrow, raster-regions, embree (comma-separated)")
      .value("--intervals", intervals, "Interval rules: default, static (comma-separated)")
      .value("--json", json_path, "Write the rows as JSON to PATH")
      .value("--out", out_dir, "Folder for the packs built");
  opt.parse(argc, argv);
  try {
    st::Scene scene = st::load_scene(scene_spec);
    st::LightSpace light = st::LightSpace::fit(st::LightSpec::parse(light_spec), scene.bounds());
    const bool sun = light.kind() == st::LightKind::sun;
    std::vector<std::string> rules = split(intervals), builder_list = split(builders);
    for (const std::string& r : rules)
      if (r != "default" && r != "static") throw st::Error("--intervals: expected default or static, got '" + r + "'");
    for (const std::string& b : builder_list)
      if (b != "raster" && b != "raster-off" && b != "raster-narrow" && b != "raster-regions" && b != "embree")
        throw st::Error("--builders: expected raster, raster-off, raster-narrow, raster-regions or embree, got '" +
                        b + "'");
    // raster: the rasterizer with its default per-tile skip (exact); raster-off: without
    // the skip; raster-narrow: with narrowed intervals in skipped tiles; raster-regions:
    // builds top-down over regions proven by their corners (a build-only mode: its bounds
    // pass would be raster-narrow's).
    auto skip_of = [](const std::string& b) {
      if (b == "raster-off") return st::RasterSkip::off;
      if (b == "raster-narrow") return st::RasterSkip::narrow;
      if (b == "raster-regions") return st::RasterSkip::regions;
      return st::RasterSkip::exact;
    };
    std::vector<std::string> bounds_list{"embree"};
    for (const std::string& b : builder_list)
      if (b != "embree") bounds_list.push_back(b);
    if (bounds_list.size() == 1) bounds_list.push_back("raster");
    std::error_code ec;  // the packs' folder: made if missing
    std::filesystem::create_directories(out_dir, ec);
    if (ec) throw st::Error("--out: cannot create '" + out_dir + "': " + ec.message());
    std::vector<uint32_t> levels;
    for (const std::string& r : split(resolutions)) levels.push_back(parse_level(r));
    if (levels.empty()) throw st::Error("--resolutions: none given");

    nlohmann::json rows = nlohmann::json::array();
    // Seconds of each run name at each level, for the slopes.
    std::vector<std::pair<std::string, std::vector<std::pair<uint32_t, double>>>> series;
    auto record = [&](const std::string& name, uint32_t L, double s) {
      for (auto& [n, v] : series)
        if (n == name) return v.push_back({L, s});
      series.push_back({name, {{L, s}}});
    };
    for (const uint32_t L : levels) {
      const uint32_t K = st::default_skip_level(L);
      const uint64_t texels = uint64_t(1) << (2 * L);
      std::printf("bench_build: %s, %s, %llu^2 (level %u, skip level %u), %u threads\n", scene_spec.c_str(),
                  light_spec.c_str(), (unsigned long long)(uint64_t(1) << L), L, K,
                  std::thread::hardware_concurrency());
      std::printf("%-20s %8s %8s %10s %9s %9s %8s %8s %7s %7s %7s %7s\n", "run", "wall s", "cpu s", "Mtexels/s",
                  "pack MiB", "% of raw", "peak MiB", "/tracer", "trace", "hier", "cut+enc", "write");
      // Bounds alone with each builder.
      double tracer_wall = 0;
      for (const std::string& b : bounds_list) {
        if ((b != "embree" && !sun) || b == "raster-regions") continue;
        Measured m = in_child([&]() {
          double setup = 0, s = 0;
          std::atomic<uint64_t> tests{0}, hits{0}, closed{0}, skipped{0};
          if (b == "embree") {
            st::DepthBoundsTracer tracer(scene, light);
            setup = tracer.build_seconds();
            s = bounds_pass(L, K, [&](const st::TraceRegion& r) { tracer.trace(r); });
          } else {
            st::RasterBounds raster(scene, light, skip_of(b));
            setup = raster.setup_seconds();
            s = bounds_pass(L, K, [&](const st::TraceRegion& r) {
              st::DepthBoundsStats st;
              raster.trace(r, &st);
              tests += st.traversals, hits += st.hits, closed += st.closed;
            });
            skipped = raster.skipped_texels();
          }
          return nlohmann::json{{"seconds", s}, {"setup_seconds", setup},
                                {"triangle_texel_tests_per_texel", double(tests) / double(texels)},
                                {"hit_fraction", double(hits) / double(texels)},
                                {"closed_fraction", double(closed) / double(texels)},
                                {"skipped_fraction", double(skipped) / double(texels)}};
        });
        if (m.result.contains("error")) {
          std::printf("%-20s failed: %s\n", ("bounds " + b).c_str(), m.result["error"].get<std::string>().c_str());
          continue;
        }
        if (b == "embree") tracer_wall = m.wall;
        const std::string name = "bounds " + b;
        std::printf("%-20s %8.2f %8.2f %10.2f %9s %9s %8.0f %8.2f %7.2f %7s %7s %7s\n", name.c_str(), m.wall, m.cpu,
                    double(texels) / m.wall / 1e6, "-", "-", m.peak_mib, tracer_wall > 0 ? m.wall / tracer_wall : 0.0,
                    m.result["seconds"].get<double>(), "-", "-", "-");
        if (b != "embree")
          std::printf("%-20s skipped %.1f%% of texels, %.2f triangle-texel tests per texel\n", "",
                      100 * m.result["skipped_fraction"].get<double>(),
                      m.result["triangle_texel_tests_per_texel"].get<double>());
        rows.push_back({{"run", "bounds"}, {"builder", b}, {"map_level", L}, {"texels", texels},
                        {"wall_s", m.wall}, {"cpu_s", m.cpu}, {"peak_mib", m.peak_mib},
                        {"mtexels_per_s", double(texels) / m.wall / 1e6},
                        {"over_tracer", tracer_wall > 0 ? m.wall / tracer_wall : 0.0}, {"detail", m.result}});
        record(name, L, m.wall);
      }
      for (const std::string& rule : rules)
        for (const std::string& enc : split(encodings))
          for (const std::string& b : builder_list) {
            if (b != "embree" && (!sun || rule == "static")) continue;
            const std::string path = out_dir + "/bench_build_" + enc + "_" + rule + "_" + b + ".pack";
            const std::string name = "build " + enc + (rule == "static" ? "/st " : " ") + b;
            Measured m = in_child([&]() {
              st::MapBuildOptions o;
              o.map_level = L;
              o.dagmh_dictionary = enc == "dagmh+dict";
              o.encoding = st::parse_encoding(o.dagmh_dictionary ? "dagmh" : enc);
              o.builder = b != "embree" ? st::BoundsBuilder::raster : st::BoundsBuilder::embree;
              o.raster_skip = skip_of(b);
              if (rule == "static") o.intervals = st::IntervalRule::static_geometry;
              st::MapBuildReport r = st::build_map(scene, light, o, path);
              return nlohmann::json::parse(r.to_json());
            });
            // DAG-MH: the same pack's tiles with a pack dictionary (dagmh_dictionary.hpp).
            nlohmann::json dict;
            if (enc == "dagmh" && !m.result.contains("error")) {
              const st::bench::DictFigures f = st::bench::dict_figures(st::bench::encoded_tiles_of(path));
              dict = {{"tiles_raw", f.raw_before}, {"tiles_raw_with", f.raw_with()}, {"dictionary_raw", f.dict_raw},
                      {"tiles_zlib", f.zlib_before}, {"tiles_zlib_with", f.zlib_with()}, {"dictionary_zlib", f.dict_zlib},
                      {"pack_bytes_with", m.result["pack_bytes"].get<double>() - double(f.zlib_before) + double(f.zlib_with())}};
            }
            std::remove(path.c_str());
            if (m.result.contains("error")) {
              std::printf("%-20s failed: %s\n", name.c_str(), m.result["error"].get<std::string>().c_str());
              continue;
            }
            const double pack = m.result["pack_bytes"].get<double>();
            const auto& stages = m.result["stage_thread_seconds"];
            std::printf("%-20s %8.2f %8.2f %10.2f %9.2f %9.5f %8.0f %8.2f %7.2f %7.2f %7.2f %7.2f\n", name.c_str(),
                        m.wall, m.cpu, double(texels) / m.wall / 1e6, pack / (1 << 20),
                        100.0 * pack / (double(texels) * 4), m.peak_mib, tracer_wall > 0 ? m.wall / tracer_wall : 0.0,
                        stages["trace"].get<double>(), stages["hierarchy"].get<double>(),
                        stages["cut_encode"].get<double>(), stages["compress_write"].get<double>());
            if (m.result.contains("dagmh_dictionary")) {
              const auto& d = m.result["dagmh_dictionary"];
              std::printf("%-20s pack dictionary %.1f KiB, %llu tiles rewritten, tiles raw %.2f -> %.2f MiB%s\n", "",
                          d["bytes"].get<double>() / 1024, (unsigned long long)d["tiles_rewritten"].get<uint64_t>(),
                          d["tile_raw_bytes_before"].get<double>() / (1 << 20),
                          d["tile_raw_bytes_after"].get<double>() / (1 << 20),
                          d["skipped"].get<std::string>().empty() ? "" : (" (none: " + d["skipped"].get<std::string>() + ")").c_str());
            }
            if (m.result.value("texels_in_regions", 0.0) > 0)
              std::printf("%-20s %.3f%% of texels traced, the rest in proven regions\n", "",
                          100.0 * m.result["texels_traced"].get<double>() / double(texels));
            rows.push_back({{"run", "build"}, {"builder", b}, {"encoding", enc}, {"intervals", rule},
                            {"map_level", L}, {"texels", texels}, {"wall_s", m.wall}, {"cpu_s", m.cpu},
                            {"peak_mib", m.peak_mib}, {"mtexels_per_s", double(texels) / m.wall / 1e6},
                            {"over_tracer", tracer_wall > 0 ? m.wall / tracer_wall : 0.0}, {"report", m.result},
                            {"dagmh_dictionary", dict}});
            record(name, L, m.wall);
            if (!dict.is_null())
              std::printf("%-20s with a pack dictionary: pack %.2f MiB (x%.3f), tiles raw %.2f -> %.2f MiB "
                          "(dictionary %.1f KiB raw, %.1f KiB zlib)\n",
                          "", dict["pack_bytes_with"].get<double>() / (1 << 20), dict["pack_bytes_with"].get<double>() / pack,
                          dict["tiles_raw"].get<double>() / (1 << 20), dict["tiles_raw_with"].get<double>() / (1 << 20),
                          dict["dictionary_raw"].get<double>() / 1024, dict["dictionary_zlib"].get<double>() / 1024);
          }
    }
    // How time grows: d log(time) / d log(texels) between successive resolutions.
    nlohmann::json slopes = nlohmann::json::array();
    if (levels.size() > 1) std::printf("slope of log time against log texels (1.0: linear in texels)\n");
    for (const auto& [name, v] : series)
      for (size_t k = 1; k < v.size(); ++k) {
        const double dl = std::log(double(uint64_t(1) << (2 * v[k].first))) -
                          std::log(double(uint64_t(1) << (2 * v[k - 1].first)));
        if (dl == 0 || v[k - 1].second <= 0) continue;
        const double slope = std::log(v[k].second / v[k - 1].second) / dl;
        std::printf("  %-20s level %u -> %u: %.2f\n", name.c_str(), v[k - 1].first, v[k].first, slope);
        slopes.push_back({{"run", name}, {"from_level", v[k - 1].first}, {"to_level", v[k].first}, {"slope", slope}});
      }
    nlohmann::json j{{"scene", scene_spec}, {"light", light_spec}, {"levels", levels},
                     {"threads", std::thread::hardware_concurrency()}, {"runs", rows}, {"slopes", slopes}};
    if (!json_path.empty()) std::ofstream(json_path) << j.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_build: error: %s\n", e.what());
    return 1;
  }
  return 0;
}

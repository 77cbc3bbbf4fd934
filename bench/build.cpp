// Build benchmark: whole builds of a scene with each encoding next to computing
// the depth bounds alone (first hit + exit depth) over the same texels, in the same run:
// wall time, CPU time, peak memory, pack size, texels per second, and build / bounds.
//
//   bench_build [--scene procedural:city] [--light sun:azimuth=30,elevation=50]
//               [--resolution 16k] [--encodings dagmh,mmh,mh] [--intervals default,static]
//               [--json PATH] [--out DIR]
//
// --intervals lists the interval rules to build each encoding with (default: the
// closed-object rule only; static: the static-geometry interval, map_build.hpp), so the
// pack bytes of the two stand side by side on open scenes.
// Each measurement runs in a forked child so that its peak memory (wait4 rusage) is its
// own. The bounds-only pass traces the same level-K cells the build traces, on the same
// worker threads, and throws the intervals away.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/scene.hpp"
#include "common/error.hpp"
#include "tiles/core/resolution.hpp"
#include "tiles/build/tile_cut.hpp"

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

}  // namespace

int main(int argc, char** argv) {
  std::string scene_spec = "procedural:city", light_spec = "sun:azimuth=30,elevation=50",
              resolution = "16k", encodings = "dagmh,mmh,mh", intervals = "default", json_path,
              out_dir = "/tmp";
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_build: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--scene") scene_spec = next();
    else if (a == "--light") light_spec = next();
    else if (a == "--resolution") resolution = next();
    else if (a == "--encodings") encodings = next();
    else if (a == "--intervals") intervals = next();
    else if (a == "--json") json_path = next();
    else if (a == "--out") out_dir = next();
    else {
      std::fprintf(stderr, "usage: bench_build [--scene S] [--light L] [--resolution 16k] "
                           "[--encodings dagmh,mmh,mh] [--intervals default,static] [--json PATH] [--out DIR]\n");
      return 2;
    }
  }
  try {
    const uint32_t L = parse_level(resolution);
    const uint32_t K = st::default_skip_level(L);
    st::Scene scene = st::load_scene(scene_spec);
    st::LightSpace light = st::LightSpace::fit(st::LightSpec::parse(light_spec), scene.bounds());
    const uint64_t texels = uint64_t(1) << (2 * L);

    // Bounds alone: the same cells, the same number of worker threads as build_map.
    Measured bounds = in_child([&]() {
      st::DepthBoundsTracer tracer(scene, light);
      const uint64_t cells = uint64_t(1) << K, side = uint64_t(1) << (L - K);
      const uint64_t sub = std::min<uint64_t>(side, st::kMaxTraceSide), per = side / sub;
      std::atomic<uint64_t> next{0};
      const uint64_t total = cells * cells * per * per;
      auto t0 = Clock::now();
      auto work = [&]() {
        for (uint64_t i; (i = next++) < total;) {
          uint64_t c = i / (per * per), s = i % (per * per);
          uint64_t cx = st::morton_compact(c), cy = st::morton_compact(c >> 1);
          tracer.trace({L, cx * side + (s % per) * sub, cy * side + (s / per) * sub, uint32_t(sub), uint32_t(sub)});
        }
      };
      std::vector<std::thread> ts;
      for (unsigned k = 0; k < std::max(1u, std::thread::hardware_concurrency()); ++k) ts.emplace_back(work);
      for (auto& t : ts) t.join();
      return nlohmann::json{{"seconds", std::chrono::duration<double>(Clock::now() - t0).count()}};
    });

    nlohmann::json rows = nlohmann::json::array();
    std::printf("bench_build: %s, %s, %llu^2 (level %u, skip level %u), %u threads\n", scene_spec.c_str(),
                light_spec.c_str(), (unsigned long long)(uint64_t(1) << L), L, K,
                std::thread::hardware_concurrency());
    std::printf("%-14s %9s %9s %10s %11s %10s %11s %9s %11s\n", "run", "wall s", "cpu s", "Mtexels/s",
                "pack MiB", "% of raw", "peak MiB", "/bounds", "cpu/bounds");
    std::printf("%-14s %9.1f %9.1f %10.2f %11s %10s %11.0f %9s %11s\n", "bounds only", bounds.wall, bounds.cpu,
                double(texels) / bounds.wall / 1e6, "-", "-", bounds.peak_mib, "1.00", "1.00");
    rows.push_back({{"run", "bounds"}, {"wall_s", bounds.wall}, {"cpu_s", bounds.cpu}, {"peak_mib", bounds.peak_mib}});
    std::vector<std::string> rules;
    {
      std::stringstream rs(intervals);
      for (std::string r; std::getline(rs, r, ',');) {
        if (r != "default" && r != "static") throw st::Error("--intervals: expected default or static, got '" + r + "'");
        rules.push_back(r);
      }
    }
    for (const std::string& rule : rules) {
      std::stringstream ss(encodings);
      std::string enc;
      while (std::getline(ss, enc, ',')) {
        const std::string path = out_dir + "/bench_build_" + enc + "_" + rule + ".pack";
        const std::string name = "build " + enc + (rule == "static" ? "/st" : "");
        Measured m = in_child([&]() {
          st::MapBuildOptions o;
          o.map_level = L;
          o.encoding = st::parse_encoding(enc);
          if (rule == "static") o.intervals = st::IntervalRule::static_geometry;
          st::MapBuildReport r = st::build_map(scene, light, o, path);
          return nlohmann::json::parse(r.to_json());
        });
        if (m.result.contains("error")) {
          std::printf("%-14s failed: %s\n", name.c_str(), m.result["error"].get<std::string>().c_str());
          continue;
        }
        double pack = m.result["pack_bytes"].get<double>();
        std::printf("%-14s %9.1f %9.1f %10.2f %11.2f %10.5f %11.0f %9.2f %11.2f\n", name.c_str(), m.wall,
                    m.cpu, double(texels) / m.wall / 1e6, pack / (1 << 20), 100.0 * pack / (double(texels) * 4),
                    m.peak_mib, m.wall / bounds.wall, m.cpu / bounds.cpu);
        rows.push_back({{"run", "build"}, {"encoding", enc}, {"intervals", rule}, {"wall_s", m.wall},
                        {"cpu_s", m.cpu}, {"peak_mib", m.peak_mib}, {"build_over_bounds", m.wall / bounds.wall},
                        {"cpu_over_bounds", m.cpu / bounds.cpu}, {"report", m.result}});
        std::remove(path.c_str());
      }
    }
    nlohmann::json j{{"scene", scene_spec}, {"light", light_spec}, {"map_level", L}, {"skip_level", K},
                     {"texels", texels}, {"threads", std::thread::hardware_concurrency()}, {"runs", rows}};
    if (!json_path.empty()) std::ofstream(json_path) << j.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_build: error: %s\n", e.what());
    return 1;
  }
  return 0;
}

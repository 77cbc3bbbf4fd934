// Depth-bounds benchmark (MH §3.1): Mtexels/s of dual depth bounds (lo + exit depth hi)
// next to plain first-hit rays (an ordinary shadow map: one traversal per texel) over
// the same texels in the same run, their ratio, traversals per texel and peak memory;
// and the cost of the canonical depth (tiles/bake/canonical_depth.hpp): the same bounds
// from the tracer's float t ("tracer t", the tracer before the canonical depth).
//
//   bench_bounds [--scene procedural:city] [--light sun:azimuth=30,elevation=50]
//                [--resolution 16k] [--region-side 4096] [--regions N] [--quick]
//                [--json PATH]
//
// The map is traced in region-side^2 regions (the tiled construction of MH §3.1); by
// default all of them, --regions N keeps the N regions nearest the map centre, --quick
// is --regions 2 --region-side 2048. Each region is traced both ways back to back, so
// the ratio is measured side by side on this shared, noisy machine. Wall time and
// process CPU time (getrusage, all threads) are both reported.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "tiles/bake/depth_bounds.hpp"
#include "scene/scene.hpp"
#include "bench/options.hpp"
#include "common/error.hpp"
#include "tiles/core/resolution.hpp"

namespace {

double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double peak_rss_mib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

uint32_t parse_level(const std::string& text) { return st::parse_resolution(text); }

struct Side {
  double wall = 0, cpu = 0;
  st::DepthBoundsStats stats;
};

Side run(const st::DepthBoundsTracer& tracer, const st::TraceRegion& r, st::TraceMode mode) {
  Side s;
  const double c0 = cpu_seconds();
  const auto t0 = std::chrono::steady_clock::now();
  st::IntervalTile tile = tracer.trace(r, mode, &s.stats);
  s.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  s.cpu = cpu_seconds() - c0;
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_spec = "procedural:city", light_spec = "sun:azimuth=30,elevation=50";
  std::string resolution = "16k", json_path;
  uint32_t region_side = 4096, max_regions = 0;
  bool quick = false;
  st::bench::Options opt("bench_bounds", "Depth bounds (MH 3.1): Mtexels/s of dual depth bounds beside first-hit rays");
  opt.value("--scene", scene_spec, "Scene spec")
      .value("--light", light_spec, "Light spec")
      .value("--resolution", resolution, "Map side (4k, 16k, ...)")
      .value("--region-side", region_side, "Side of a traced region in texels (1..8192)")
      .value("--regions", max_regions, "Keep the N regions nearest the map centre (0: all)")
      .flag("--quick", quick, "2 regions of 2048^2 (unless --regions / --region-side are given)")
      .value("--json", json_path, "Write the rows as JSON to PATH");
  opt.parse(argc, argv);
  if (quick) {
    if (!opt.given("--regions")) max_regions = 2;
    if (!opt.given("--region-side")) region_side = 2048;
  }
  try {
    const uint32_t level = parse_level(resolution);
    const uint64_t side = uint64_t(1) << level;
    region_side = uint32_t(std::min<uint64_t>(region_side, side));
    if (region_side == 0 || uint64_t(region_side) * region_side > st::DepthBoundsTracer::kMaxRegionTexels)
      throw st::Error("--region-side must be in 1..8192");

    const double c_load = cpu_seconds();
    const auto t_load = std::chrono::steady_clock::now();
    st::Scene scene = st::load_scene(scene_spec);
    const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_load).count();
    st::LightSpace light = st::LightSpace::fit(st::LightSpec::parse(light_spec), scene.bounds());
    st::DepthBoundsTracer tracer(scene, light);
    const double setup_cpu = cpu_seconds() - c_load;

    // Regions ordered by distance of their centre from the map centre (the city covers
    // the middle; the corners of an oblique sun's box are mostly empty).
    std::vector<st::TraceRegion> regions;
    for (uint64_t y = 0; y < side; y += region_side)
      for (uint64_t x = 0; x < side; x += region_side)
        regions.push_back({level, x, y, uint32_t(std::min<uint64_t>(region_side, side - x)),
                           uint32_t(std::min<uint64_t>(region_side, side - y))});
    const double c = double(side) / 2;
    std::stable_sort(regions.begin(), regions.end(), [&](auto& a, auto& b) {
      auto d = [&](const st::TraceRegion& r) {
        return std::hypot(double(r.x0) + r.width / 2.0 - c, double(r.y0) + r.height / 2.0 - c);
      };
      return d(a) < d(b);
    });
    if (max_regions > 0 && max_regions < regions.size()) regions.resize(max_regions);

    std::printf("scene %s: %llu triangles, %s; embree build %.3f s (load %.3f s)\n",
                scene_spec.c_str(), (unsigned long long)tracer.triangle_count(),
                tracer.traces_exit_depths() ? "closed meshes" : "open only",
                tracer.build_seconds(), load_s);
    std::printf("map %llu^2 (level %u), %zu regions of <= %u^2, %u hardware threads\n\n",
                (unsigned long long)side, level, regions.size(), region_side,
                std::thread::hardware_concurrency());
    std::printf("%-22s %7s %7s %11s %11s %7s %12s %8s %9s %9s\n", "region", "hit%", "closed%",
                "bounds Mt/s", "first Mt/s", "ratio", "tracer-t Mt/s", "canon x", "trav/tex", "fallback");

    nlohmann::json jr = nlohmann::json::array();
    Side tb, tf, tt;  // totals
    for (const auto& r : regions) {
      Side b = run(tracer, r, st::TraceMode::bounds);
      Side f = run(tracer, r, st::TraceMode::first_hit);
      Side t = run(tracer, r, st::TraceMode::bounds_tracer_t);
      const double tex = double(b.stats.texels);
      char name[64];
      std::snprintf(name, sizeof name, "%llu,%llu,%u,%u", (unsigned long long)r.x0,
                    (unsigned long long)r.y0, r.width, r.height);
      std::printf("%-22s %7.2f %7.2f %11.2f %11.2f %7.3f %12.2f %8.3f %9.3f %9llu\n", name,
                  100 * double(b.stats.hits) / tex, 100 * double(b.stats.closed) / tex,
                  tex / b.wall * 1e-6, tex / f.wall * 1e-6, b.wall / f.wall, tex / t.wall * 1e-6,
                  b.wall / t.wall, double(b.stats.traversals) / tex,
                  (unsigned long long)b.stats.fallbacks);
      jr.push_back({{"region", {r.x0, r.y0, r.width, r.height}},
                    {"texels", b.stats.texels},
                    {"hits", b.stats.hits},
                    {"closed", b.stats.closed},
                    {"fallbacks", b.stats.fallbacks},
                    {"bounds_traversals", b.stats.traversals},
                    {"bounds_wall_s", b.wall},
                    {"bounds_cpu_s", b.cpu},
                    {"first_hit_wall_s", f.wall},
                    {"first_hit_cpu_s", f.cpu},
                    {"tracer_t_wall_s", t.wall},
                    {"tracer_t_cpu_s", t.cpu}});
      tb.wall += b.wall, tb.cpu += b.cpu, tb.stats += b.stats;
      tf.wall += f.wall, tf.cpu += f.cpu, tf.stats += f.stats;
      tt.wall += t.wall, tt.cpu += t.cpu, tt.stats += t.stats;
    }
    const double tex = double(tb.stats.texels);
    const double peak = peak_rss_mib();
    std::printf("\n%-22s %7.2f %7.2f %11.2f %11.2f %7.3f %12.2f %8.3f %9.3f %9llu\n", "total (wall)",
                100 * double(tb.stats.hits) / tex, 100 * double(tb.stats.closed) / tex,
                tex / tb.wall * 1e-6, tex / tf.wall * 1e-6, tb.wall / tf.wall, tex / tt.wall * 1e-6,
                tb.wall / tt.wall, double(tb.stats.traversals) / tex,
                (unsigned long long)tb.stats.fallbacks);
    std::printf("%-22s %7s %7s %11.2f %11.2f %7.3f %12.2f %8.3f   (Mtexels per CPU second, all threads)\n",
                "total (cpu)", "", "", tex / tb.cpu * 1e-6, tex / tf.cpu * 1e-6, tb.cpu / tf.cpu,
                tex / tt.cpu * 1e-6, tb.cpu / tt.cpu);
    std::printf("bounds: %.2f Mrays/s wall, %.2f Mtraversals/s wall; peak RSS %.0f MiB\n",
                double(tb.stats.rays) / tb.wall * 1e-6, double(tb.stats.traversals) / tb.wall * 1e-6,
                peak);

    if (!json_path.empty()) {
      nlohmann::json j = {
          {"benchmark", "bounds"},
          {"scene", scene_spec},
          {"triangles", tracer.triangle_count()},
          {"light", light_spec},
          {"resolution", side},
          {"level", level},
          {"region_side", region_side},
          {"hardware_threads", std::thread::hardware_concurrency()},
          {"embree_build_s", tracer.build_seconds()},
          {"setup_cpu_s", setup_cpu},
          {"texels", tb.stats.texels},
          {"hit_fraction", double(tb.stats.hits) / tex},
          {"closed_fraction", double(tb.stats.closed) / tex},
          {"fallbacks", tb.stats.fallbacks},
          {"traversals_per_texel", double(tb.stats.traversals) / tex},
          {"bounds_mtexels_per_s_wall", tex / tb.wall * 1e-6},
          {"first_hit_mtexels_per_s_wall", tex / tf.wall * 1e-6},
          {"bounds_mtexels_per_cpu_s", tex / tb.cpu * 1e-6},
          {"first_hit_mtexels_per_cpu_s", tex / tf.cpu * 1e-6},
          {"bounds_over_first_hit_time_wall", tb.wall / tf.wall},
          {"bounds_over_first_hit_time_cpu", tb.cpu / tf.cpu},
          {"tracer_t_mtexels_per_s_wall", tex / tt.wall * 1e-6},
          {"canonical_over_tracer_t_time_wall", tb.wall / tt.wall},
          {"canonical_over_tracer_t_time_cpu", tb.cpu / tt.cpu},
          {"peak_rss_mib", peak},
          {"regions", jr}};
      std::ofstream(json_path) << j.dump(2) << "\n";
      std::printf("wrote %s\n", json_path.c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_bounds: %s\n", e.what());
    return 1;
  }
  return 0;
}

// MH quadtree vs MMH benchmark (MH §3.2, §3.3): bytes, encode and open (validation)
// times, random single lookups side by side with a dense float array, and 5x5 PCF with
// the shared-path traversal side by side with 25 independent lookups, on synthetic
// fields built bottom-up.
//
//   bench_mh_quadtree [--side 2048] [--reps 3] [--lookups 2000000] [--field NAME] [--json PATH]
//
// Prints a table (medians over --reps runs; thread-CPU seconds, the steadier figure on a
// shared machine) and optionally writes the same figures as JSON.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/options.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/mh_quadtree_layout.hpp"
#include "tiles/encode/mmh_merge.hpp"
// The field generators are the tests' (one definition of "realistic" for both; the
// shadowtile_interval_fields library, tests/fixtures.cmake).
#include "tests/tiles/interval_fields.hpp"
#include "bench/timing.hpp"

namespace {

using st::bench::median_cpu;

volatile float g_sink;

}  // namespace

int main(int argc, char** argv) {
  uint32_t side = 2048;
  int reps = 3;
  uint64_t lookups = 2000000;
  std::string only, json_path;
  st::bench::Options opt("bench_mh_quadtree", "MH quadtree vs MMH (MH 3.2, 3.3): bytes, encode and open time, lookups beside a float array");
  opt.value("--side", side, "Map side, a power of two")
      .value("--reps", reps, "Median of R runs")
      .value("--lookups", lookups, "Lookups per field")
      .value("--field", only, "One field (its name in the table)")
      .value("--json", json_path, "Write the rows as JSON to PATH");
  opt.parse(argc, argv);
  reps = std::max(1, reps);
  if (!st::is_power_of_two(side)) {
    std::fprintf(stderr, "--side must be a power of two\n");
    return 2;
  }
  nlohmann::json out = nlohmann::json::array();
  std::printf("%-9s %6s %9s %11s %11s %6s %8s %8s %8s %8s %8s %8s %8s %7s\n", "field", "side", "nodes", "MH bytes",
              "MMH bytes", "MMH/MH", "MH enc s", "MMH enc", "MH open", "MMH open", "MH ns", "MMH ns", "array ns",
              "pcf x");
  for (auto& f : st::fields::all_fields(side, 7)) {
    if (f.name == "constant" || (!only.empty() && f.name != only)) continue;
    const st::Hierarchy h = st::build_hierarchy(f.tile);
    std::vector<uint8_t> mh, mmh;
    const double t_mh = median_cpu(reps, [&] { mh = st::encode_mh(h); });
    const double t_mmh = median_cpu(reps, [&] { mmh = st::encode_mmh(h); });
    st::mhq::MergeStats ms;
    const auto flat = st::mhq::flatten(h, true);
    (void)st::mhq::plan_mmh(flat, {}, &ms);
    std::unique_ptr<st::Evaluator> ev_mh, ev_mmh;
    const double o_mh = median_cpu(reps, [&] { ev_mh = st::open_mh(mh); });
    const double o_mmh = median_cpu(reps, [&] { ev_mmh = st::open_mmh(mmh); });

    // Random texels of the finest level; the dense array is the uncompressed map.
    std::vector<float> dense(size_t(side) * side);
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) dense[size_t(y) * side + x] = ev_mh->depth(f.tile.level, x, y);
    std::vector<uint32_t> xs(lookups), ys(lookups);
    st::fields::Rng rng(99);
    for (uint64_t i = 0; i < lookups; ++i) xs[i] = rng.below(side), ys[i] = rng.below(side);
    const uint32_t L = f.tile.level;
    auto lookup_ns = [&](const std::function<float(uint32_t, uint32_t)>& fn) {
      return 1e9 / double(lookups) * median_cpu(reps, [&] {
               float acc = 0;
               for (uint64_t i = 0; i < lookups; ++i) acc += fn(xs[i], ys[i]);
               g_sink = acc;
             });
    };
    const double ns_mh = lookup_ns([&](uint32_t x, uint32_t y) { return ev_mh->depth(L, x, y); });
    const double ns_mmh = lookup_ns([&](uint32_t x, uint32_t y) { return ev_mmh->depth(L, x, y); });
    const double ns_array = lookup_ns([&](uint32_t x, uint32_t y) { return dense[size_t(y) * side + x]; });
    const uint64_t pcf_n = std::max<uint64_t>(1, lookups / 25);
    auto pcf_time = [&](bool shared) {
      return median_cpu(reps, [&] {
        float acc = 0;
        for (uint64_t i = 0; i < pcf_n; ++i) {
          const float rec = dense[size_t(ys[i]) * side + xs[i]];
          acc += shared ? ev_mh->pcf(L, xs[i], ys[i], 5, rec) : ev_mh->st::Evaluator::pcf(L, xs[i], ys[i], 5, rec);
        }
        g_sink = acc;
      });
    };
    const double pcf_speedup = pcf_time(false) / pcf_time(true);

    std::printf("%-9s %6u %9zu %11zu %11zu %6.3f %8.3f %8.3f %8.4f %8.4f %8.1f %8.1f %8.1f %7.2f\n", f.name.c_str(), side,
                h.node_count(), mh.size(), mmh.size(), double(mmh.size()) / double(mh.size()), t_mh, t_mmh, o_mh, o_mmh,
                ns_mh, ns_mmh, ns_array, pcf_speedup);
    out.push_back({{"field", f.name},
                   {"side", side},
                   {"hierarchy_nodes", h.node_count()},
                   {"mh_bytes", mh.size()},
                   {"mmh_bytes", mmh.size()},
                   {"mh_encode_cpu_s", t_mh},
                   {"mmh_encode_cpu_s", t_mmh},
                   {"mh_open_cpu_s", o_mh},
                   {"mmh_open_cpu_s", o_mmh},
                   {"mh_lookup_ns", ns_mh},
                   {"mmh_lookup_ns", ns_mmh},
                   {"array_lookup_ns", ns_array},
                   {"pcf5_shared_speedup_vs_25_lookups", pcf_speedup},
                   {"mmh_merges", ms.merges},
                   {"mmh_cross_level_merges", ms.cross_level_merges},
                   {"mmh_nodes_removed", ms.nodes_removed},
                   {"mmh_merge_tests", ms.tests},
                   {"mmh_quick_rejects", ms.quick_rejects},
                   {"mmh_absolute_values", ms.absolute_values}});
  }
  if (!json_path.empty()) {
    std::ofstream(json_path) << out.dump(2) << "\n";
    std::printf("wrote %s\n", json_path.c_str());
  }
  return 0;
}

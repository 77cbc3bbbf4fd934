// DAG-MH benchmark (DAG-MH 2021 §4): size (bytes per valued node, bits per texel, the
// sections, vs. an MH-quadtree estimate of 4 B per node + 4 B per value, MH §3.2),
// encode and open (validation) time, and lookup time side by side with a flat float
// array of the same map: random single lookups at the finest and a coarser level, and
// r x r PCF with shared traversal vs. r^2 independent lookups (Evaluator::pcf).
//
//   bench_dagmh [--side 2048] [--reps 5] [--json PATH] [--field scene|city|terrain|uniform]
//
// Times are medians over --reps runs of thread-CPU time (the machine is shared; wall
// time is noisier), per lookup in ns.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/options.hpp"
#include "tiles/encode/dagmh_encode.hpp"
#include "tiles/encode/encode.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
// The field generators are the tests' (the shadowtile_interval_fields library).
#include "tests/tiles/interval_fields.hpp"
#include "bench/timing.hpp"

namespace {

using st::bench::median_cpu;

volatile float g_sink = 0;

struct Row {
  std::string field;
  uint32_t side = 0;
  size_t nodes = 0, valued = 0, bytes = 0;
  st::dagmh::EncodeStats stats;
  double encode_s = 0, open_s = 0;
  double flat_ns = 0, dag_ns = 0, coarse_ns = 0;
  double pcf_shared_ns[3] = {}, pcf_naive_ns[3] = {};
};
constexpr uint32_t kPcfSizes[3] = {3, 5, 9};

Row run(const std::string& name, const st::IntervalTile& tile, int reps) {
  Row row;
  row.field = name;
  row.side = tile.width;
  const st::Hierarchy h = st::build_hierarchy(tile);
  row.nodes = h.node_count();
  row.valued = h.valued_count();
  std::vector<uint8_t> bytes;
  row.encode_s = median_cpu(std::max(1, reps / 2), [&] { bytes = st::dagmh::encode(h, &row.stats); });
  row.bytes = bytes.size();
  std::unique_ptr<st::Evaluator> e;
  row.open_s = median_cpu(reps, [&] { e = st::open_dagmh(bytes); });

  const uint32_t side = tile.width, level = h.depth;
  std::vector<float> flat(size_t(side) * side);
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) flat[size_t(j) * side + i] = tile.at(i, j).lo;
  const size_t n = size_t(1) << 20;
  st::fields::Rng rng(1);
  std::vector<uint32_t> xs(n), ys(n);
  for (size_t k = 0; k < n; ++k) xs[k] = rng.below(side), ys[k] = rng.below(side);
  const double per = 1e9 / double(n);
  row.flat_ns = per * median_cpu(reps, [&] {
    float s = 0;
    for (size_t k = 0; k < n; ++k) s += flat[size_t(ys[k]) * side + xs[k]];
    g_sink = s;
  });
  row.dag_ns = per * median_cpu(reps, [&] {
    float s = 0;
    for (size_t k = 0; k < n; ++k) s += e->depth(level, xs[k], ys[k]);
    g_sink = s;
  });
  const uint32_t coarse = level >= 4 ? level - 4 : 0;
  row.coarse_ns = per * median_cpu(reps, [&] {
    float s = 0;
    for (size_t k = 0; k < n; ++k) s += e->depth(coarse, xs[k] >> (level - coarse), ys[k] >> (level - coarse));
    g_sink = s;
  });
  const size_t m = n / 16;
  for (int p = 0; p < 3; ++p) {
    const uint32_t r = kPcfSizes[p];
    row.pcf_shared_ns[p] = 1e9 / double(m) * median_cpu(reps, [&] {
      float s = 0;
      for (size_t k = 0; k < m; ++k) s += e->pcf(level, xs[k], ys[k], r, 0.5f);
      g_sink = s;
    });
    row.pcf_naive_ns[p] = 1e9 / double(m) * median_cpu(reps, [&] {
      float s = 0;
      for (size_t k = 0; k < m; ++k) s += e->Evaluator::pcf(level, xs[k], ys[k], r, 0.5f);
      g_sink = s;
    });
  }
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  uint32_t side = 2048;
  int reps = 5;
  std::string json_path, only_field;
  st::bench::Options opt("bench_dagmh", "DAG-MH (2021, 4): size, encode and open time, lookups beside a float array");
  opt.value("--side", side, "Map side, a power of two in [16, 8192]")
      .value("--reps", reps, "Median of R runs")
      .value("--json", json_path, "Write the rows as JSON to PATH")
      .value("--field", only_field, "One field: scene, city, terrain or uniform");
  opt.parse(argc, argv);
  reps = std::max(1, reps);
  if (!st::is_power_of_two(side) || side < 16 || side > 8192) {
    std::fprintf(stderr, "bench_dagmh: --side must be a power of two in [16, 8192]\n");
    return 2;
  }
  try {
    std::vector<Row> rows;
    const std::pair<const char*, st::IntervalTile (*)(uint32_t, uint64_t)> fields[] = {
        {"scene", st::fields::scene_field}, {"city", st::fields::city_field},
        {"terrain", st::fields::terrain_field}, {"uniform", st::fields::uniform_field}};
    for (auto& [name, make] : fields)
      if (only_field.empty() || only_field == name) rows.push_back(run(name, make(side, 2), reps));

    std::printf("DAG-MH, %u x %u texels, medians of %d runs (thread CPU)\n", side, side, reps);
    std::printf("%-8s %9s %9s %10s %7s %7s %8s %9s %8s %8s\n", "field", "nodes", "valued", "bytes", "B/val",
                "bit/tx", "vs MH", "encode s", "open ms", "dag/str");
    for (const Row& r : rows) {
      const double mh = 4.0 * double(r.nodes + r.valued);
      std::printf("%-8s %9zu %9zu %10zu %7.2f %7.3f %8.3f %9.3f %8.2f %8.3f\n", r.field.c_str(), r.nodes, r.valued,
                  r.bytes, double(r.bytes) / double(r.valued), 8.0 * double(r.bytes) / (double(r.side) * r.side),
                  double(r.bytes) / mh, r.encode_s, 1e3 * r.open_s,
                  double(r.stats.dag_inner + r.stats.dag_treelets) /
                      double(std::max<uint64_t>(1, r.stats.tree_inner + r.stats.tree_treelets)));
    }
    std::printf("\n%-8s %8s %8s %8s %9s %8s | %-28s\n", "field", "flat ns", "dag ns", "ratio", "coarse ns",
                "bits/mul", "pcf 3/5/9 shared vs naive ns");
    for (const Row& r : rows) {
      std::printf("%-8s %8.1f %8.1f %8.1f %9.1f %8.1f |", r.field.c_str(), r.flat_ns, r.dag_ns, r.dag_ns / r.flat_ns,
                  r.coarse_ns,
                  double(r.stats.values.multiplier_bits) / double(std::max<uint64_t>(1, r.stats.values.multipliers)));
      for (int p = 0; p < 3; ++p) std::printf(" %.0f/%.0f", r.pcf_shared_ns[p], r.pcf_naive_ns[p]);
      std::printf("\n");
    }
    if (!json_path.empty()) {
      nlohmann::json j;
      j["benchmark"] = "dagmh";
      j["side"] = side;
      j["reps"] = reps;
      for (const Row& r : rows) {
        const auto& s = r.stats;
        j["results"].push_back({{"field", r.field}, {"nodes", r.nodes}, {"valued", r.valued}, {"bytes", r.bytes},
                                {"bytes_per_valued_node", double(r.bytes) / double(r.valued)},
                                {"mh_estimate_bytes", 4 * (r.nodes + r.valued)},
                                {"sections", {{"skip", s.skip_bytes}, {"nodes", s.node_bytes},
                                              {"treelets", s.treelet_bytes}, {"chunks", s.chunk_bytes},
                                              {"multipliers", s.multiplier_bytes}}},
                                {"inner", {s.tree_inner, s.dag_inner}}, {"treelets", {s.tree_treelets, s.dag_treelets}},
                                {"multipliers", s.values.multipliers}, {"multiplier_bits", s.values.multiplier_bits},
                                {"raw_chunks", s.values.raw_chunks}, {"encode_cpu_s", r.encode_s},
                                {"open_cpu_s", r.open_s}, {"flat_ns", r.flat_ns}, {"lookup_ns", r.dag_ns},
                                {"coarse_lookup_ns", r.coarse_ns},
                                {"pcf_shared_ns", {r.pcf_shared_ns[0], r.pcf_shared_ns[1], r.pcf_shared_ns[2]}},
                                {"pcf_naive_ns", {r.pcf_naive_ns[0], r.pcf_naive_ns[1], r.pcf_naive_ns[2]}}});
      }
      std::ofstream out(json_path);
      if (!(out << j.dump(2) << "\n")) throw st::Error("bench_dagmh: cannot write " + json_path);
    }
  } catch (const st::Error& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}

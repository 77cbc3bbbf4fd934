// Construction benchmark (MH §3.1): Mtexels/s of the bottom-up (Alg. 2) and top-down
// (Alg. 1) constructions and of the tiled construction (16 tiles + stitch), side by side
// with a plain min-max mipmap pass over the same field (the memory-bound floor of any
// bottom-up pass), on synthetic fields; node counts per result.
//
//   bench_construction [--side 4096] [--reps 5] [--json PATH] [--only METHOD] [--field NAME]
//
// Prints a table (medians over --reps runs of wall and of thread-CPU time; top-down over
// at most 3, it is the slow one) and optionally writes the same figures as JSON.
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
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
// The field generators are the tests' (one definition of "realistic" for both; the
// shadowtile_interval_fields library, tests/fixtures.cmake).
#include "tests/tiles/interval_fields.hpp"
#include "bench/timing.hpp"

namespace {

using st::bench::Clock;
using st::bench::median_time;
using st::bench::Timing;

// Reference pass: [max lo, min hi] pyramid in morton order (what a bottom-up pass must at
// least read and write), to report the constructions' speed as a ratio to it.
float minmax_pyramid(const st::IntervalTile& tile) {
  const uint32_t n = st::log2_exact(tile.width);
  if (n == 0) return tile.data[0].lo;
  std::vector<float> lo(size_t(1) << (2 * (n - 1))), hi(lo.size());
  for (size_t m = 0; m < lo.size(); ++m) {
    size_t x = st::morton_compact(m), y = st::morton_compact(m >> 1);
    const st::Interval* r0 = &tile.data[(2 * y) * tile.width + 2 * x];
    const st::Interval* r1 = r0 + tile.width;
    lo[m] = std::max(std::max(r0[0].lo, r0[1].lo), std::max(r1[0].lo, r1[1].lo));
    hi[m] = std::min(std::min(r0[0].hi, r0[1].hi), std::min(r1[0].hi, r1[1].hi));
  }
  for (size_t count = lo.size() / 4; count >= 1; count /= 4) {
    for (size_t m = 0; m < count; ++m) {
      lo[m] = std::max(std::max(lo[4 * m], lo[4 * m + 1]), std::max(lo[4 * m + 2], lo[4 * m + 3]));
      hi[m] = std::min(std::min(hi[4 * m], hi[4 * m + 1]), std::min(hi[4 * m + 2], hi[4 * m + 3]));
    }
    if (count == 1) break;
  }
  return lo[0] + hi[0];
}

st::Hierarchy build_tiled(const st::IntervalTile& map, uint32_t grid_level, st::MhConstruction method) {
  const uint32_t grid = 1u << grid_level, side = map.width / grid;
  std::vector<st::Hierarchy> tiles;
  st::IntervalTile t;
  t.width = t.height = side;
  t.data.resize(size_t(side) * side);
  for (uint32_t tj = 0; tj < grid; ++tj)
    for (uint32_t ti = 0; ti < grid; ++ti) {
      for (uint32_t j = 0; j < side; ++j)
        std::memcpy(&t.at(0, j), &map.at(ti * side, tj * side + j), sizeof(st::Interval) * side);
      tiles.push_back(st::build_hierarchy(t, method));
    }
  return st::stitch_tiles(std::move(tiles), grid_level, method);
}

struct Row {
  std::string field, method;
  Timing t;
  double ratio_to_pyramid = 0;  // pyramid CPU time / this CPU time
  size_t nodes = 0, valued = 0;
};

}  // namespace

int main(int argc, char** argv) {
  uint32_t side = 4096;
  int reps = 5;
  std::string json_path, only, only_field;  // --only METHOD, --field NAME: profile one
  st::bench::Options opt("bench_construction", "Construction (MH 3.1): bottom-up, top-down and tiled beside a min-max mipmap, on synthetic fields");
  opt.value("--side", side, "Map side, a power of two in [4, 16384]")
      .value("--reps", reps, "Median of R runs")
      .value("--json", json_path, "Write the rows as JSON to PATH")
      .value("--only", only, "Profile one method: bottom_up, bottom_up_16_tiles or top_down")
      .value("--field", only_field, "One field: scene, city, terrain or uniform");
  opt.parse(argc, argv);
  reps = std::max(1, reps);
  if (!st::is_power_of_two(side) || side < 4 || side > (1u << 14)) {
    std::fprintf(stderr, "bench_construction: --side must be a power of two in [4, 16384]\n");
    return 2;
  }
  try {
    struct Field {
      const char* name;
      st::IntervalTile (*make)(uint32_t, uint64_t);
    };
    const Field fields_list[] = {{"scene", st::fields::scene_field},
                                 {"city", st::fields::city_field},
                                 {"terrain", st::fields::terrain_field},
                                 {"uniform", st::fields::uniform_field}};
    const double mtexels = double(side) * side / 1e6;
    std::vector<Row> rows;
    for (const Field& f : fields_list) {
      if (!only_field.empty() && only_field != f.name) continue;
      st::IntervalTile tile = f.make(side, 42);
      volatile float sink = 0;
      Timing pyramid = median_time(reps, [&] { sink = sink + minmax_pyramid(tile); });
      rows.push_back({f.name, "minmax_pyramid", pyramid, 1.0, 0, 0});
      struct Method {
        const char* name;
        std::function<st::Hierarchy()> build;
        int reps;
      };
      const Method methods[] = {
          {"bottom_up", [&] { return st::build_hierarchy(tile, st::MhConstruction::bottom_up); }, reps},
          {"bottom_up_16_tiles", [&] { return build_tiled(tile, 2, st::MhConstruction::bottom_up); }, reps},
          {"top_down", [&] { return st::build_hierarchy(tile, st::MhConstruction::top_down); }, std::min(reps, 3)},
      };
      for (const Method& m : methods) {
        if (!only.empty() && only != m.name) continue;
        st::Hierarchy h;
        Timing t = median_time(m.reps, [&] { h = m.build(); });
        rows.push_back({f.name, m.name, t, pyramid.cpu / t.cpu, h.node_count(), h.valued_count()});
      }
    }

    std::printf("MH construction, %u x %u texels (%.1f Mtexels), median of %d runs (top-down: %d)\n", side, side,
                mtexels, reps, std::min(reps, 3));
    std::printf("bottom-up working memory: %.2f bytes/texel beyond the input (output: %zu bytes/node)\n",
                10.0 / 3.0, sizeof(st::HNode));
    std::printf("%-8s %-19s %8s %8s %10s %10s %8s %10s %10s %8s\n", "field", "method", "wall s", "cpu s", "Mtx/s wall",
                "Mtx/s cpu", "pyr/this", "nodes", "valued", "nodes/tx");
    for (const Row& r : rows)
      std::printf("%-8s %-19s %8.4f %8.4f %10.1f %10.1f %8.3f %10zu %10zu %8.4f\n", r.field.c_str(), r.method.c_str(),
                  r.t.wall, r.t.cpu, mtexels / r.t.wall, mtexels / r.t.cpu, r.ratio_to_pyramid, r.nodes, r.valued,
                  double(r.nodes) / (mtexels * 1e6));
    std::printf("pyr/this: CPU time of a plain [max lo, min hi] mipmap pass over the same field / this CPU time\n");
    if (!json_path.empty()) {
      nlohmann::json j;
      j["bench"] = "construction";
      j["side"] = side;
      j["reps"] = reps;
      for (const Row& r : rows)
        j["results"].push_back({{"field", r.field},
                                {"method", r.method},
                                {"wall_seconds", r.t.wall},
                                {"cpu_seconds", r.t.cpu},
                                {"mtexels_per_s_wall", mtexels / r.t.wall},
                                {"mtexels_per_s_cpu", mtexels / r.t.cpu},
                                {"ratio_to_minmax_pyramid", r.ratio_to_pyramid},
                                {"nodes", r.nodes},
                                {"valued", r.valued}});
      std::ofstream out(json_path);
      if (!(out << j.dump(2) << "\n")) throw st::Error("bench_construction: cannot write " + json_path);
    }
  } catch (const st::Error& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}

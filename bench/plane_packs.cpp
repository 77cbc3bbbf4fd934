// Pack bytes with and without plane tiles (tiles/core/PLANES.md) next to static-interval
// packs: for each scene, the CLI's default DAG-MH build (mixed tiles, dictionary) with
// default intervals, the same with --intervals static, and the default with --planes on;
// file sizes, the ratios the plane tiles are measured by, build seconds. The packs stay in
// OUT for bench_pack_bytes (per-section bytes, the planes section included).
//
//   bench_plane_packs SCENE@RES... [--out DIR] [--json PATH] [--light SPEC] [--min-shift S] [--min-nodes N] [--min-reused N]
//                     [--min-labelled N]
//                     [--no-merge] [--no-round] [--no-pack] [--no-predict] [--no-grow] [--keep-coarse] [--max-palette N] [--grow-seeds N] [--stats]
//                     [--only default,static,planes]
// (--no-grow: a labelled block's missing texels get one plane fitted to them all or none,
// PlaneFitOptions::grow_labels; --stats: where the planes build's valued nodes went,
// PlaneFitStats, printed after each scene; --max-palette 4: no wide labelled blocks, the
// version 2 tiles of before, byte for byte.)
// (--no-pack stores plane tiles as STPN instead of packed, MapBuildOptions::pack_plane_tiles;
// --no-predict packs them without predicted labels, "STPQ", MapBuildOptions::predict_plane_labels.)
// (--only builds the named variants alone; the others' columns print 0).
// e.g. bench_plane_packs /usr/share/games/openarena/baseoa/pak1-maps.pk3:maps/oa_dm1.bsp@8192
//      /usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb@4096 procedural:city@4096
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/options.hpp"
#include "common/error.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "tiles/core/resolution.hpp"

namespace {

namespace fs = std::filesystem;

struct Variant {
  const char* name;
  bool planes, static_intervals;
};

}  // namespace

int main(int argc, char** argv) try {
  std::vector<std::string> scenes;
  st::PlaneFitOptions fit;
  std::string out_dir = "bench-out/planes", json_path, light_spec = "sun:azimuth=30,elevation=50";
  std::vector<std::string> only;
  bool pack_planes = true, predict_labels = true, stats = false;
  st::bench::Options opt("bench_plane_packs", "Pack bytes with and without plane tiles beside static-interval packs");
  opt.rest("SCENE@RES", scenes, "Scenes and map sides (procedural:city@4096, FILE@8192)")
      .value("--out", out_dir, "Folder for the packs (kept for bench_pack_bytes)")
      .value("--json", json_path, "Write the rows as JSON to PATH")
      .value("--light", light_spec, "Light spec")
      .value("--min-shift", fit.min_shift, "PlaneFitOptions::min_shift")
      .value("--min-nodes", fit.min_stored_nodes, "PlaneFitOptions::min_stored_nodes")
      .value("--min-reused", fit.min_reused_nodes, "PlaneFitOptions::min_reused_nodes")
      .value("--min-labelled", fit.min_labelled_nodes, "PlaneFitOptions::min_labelled_nodes")
      .flag("--no-merge", fit.merge_surfaces, "PlaneFitOptions::merge_surfaces off", false)
      .flag("--no-round", fit.round_planes, "PlaneFitOptions::round_planes off", false)
      .flag("--no-pack", pack_planes, "Store plane tiles as STPN instead of packed", false)
      .flag("--no-predict", predict_labels, "Pack plane tiles without predicted labels (STPQ)", false)
      .flag("--keep-coarse", fit.drop_coarse_values, "PlaneFitOptions::drop_coarse_values off (the hierarchy's coarse values above the blocks)", false)
      .flag("--no-grow", fit.grow_labels, "PlaneFitOptions::grow_labels off (the old texel-order labelling)", false)
      .value("--max-palette", fit.max_palette, "PlaneFitOptions::max_palette (4: no wide labelled blocks, the form before)")
      .value("--grow-seeds", fit.grow_seeds, "PlaneFitOptions::grow_seeds (1..3)")
      .flag("--stats", stats, "Print where values go and why blocks are rejected")
      .with("--only", [&](const std::string& list) {
              std::string name;
              for (char ch : list + ',')
                if (ch == ',') only.push_back(name), name.clear();
                else name.push_back(ch);
            }, "Build the named variants alone: default, static, planes (comma-separated)");
  opt.parse(argc, argv);
  if (scenes.empty()) throw st::Error("usage: bench_plane_packs SCENE@RES... [--out DIR] [--json PATH] [--light SPEC]");
  fs::create_directories(out_dir);
  const Variant variants[] = {{"default", false, false}, {"static", false, true}, {"planes", true, false}};
  nlohmann::json rows = nlohmann::json::array();
  std::printf("%-40s %6s %12s %12s %12s %8s %8s %8s %8s %8s\n", "scene", "res", "default B", "static B", "planes B",
              "pl/stat", "def/stat", "pl/def", "t def s", "t pl s");
  for (const std::string& entry : scenes) {
    const size_t at = entry.rfind('@');
    const std::string spec = at == std::string::npos ? entry : entry.substr(0, at);
    const std::string res = at == std::string::npos ? "4096" : entry.substr(at + 1);
    const st::Scene scene = st::load_scene(spec);
    const st::LightSpace light = st::LightSpace::fit(st::LightSpec::parse(light_spec), scene.bounds());
    std::string stem = fs::path(spec.substr(spec.rfind(':') == std::string::npos ? 0 : spec.rfind(':') + 1)).stem().string();
    if (stem.empty()) stem = "scene";
    nlohmann::json row = {{"scene", spec}, {"resolution", res}};
    st::PlaneFitStats fit_stats;
    uint64_t bytes[3] = {};
    double secs[3] = {};
    for (int v = 0; v < 3; ++v) {
      if (!only.empty() && std::find(only.begin(), only.end(), variants[v].name) == only.end()) continue;
      st::MapBuildOptions o;
      o.map_level = st::parse_resolution(res);
      o.encoding = st::Encoding::dagmh;
      o.dagmh_dictionary = o.dagmh_mixed_tiles = true;  // the CLI's default build
      o.planes = variants[v].planes;
      o.plane_fit = fit;
      if (stats) o.plane_fit.stats = &fit_stats;
      o.pack_plane_tiles = pack_planes;
      o.predict_plane_labels = predict_labels;
      if (variants[v].static_intervals) o.intervals = st::IntervalRule::static_geometry;
      o.scene_spec = spec;
      o.light_spec = light_spec;
      const std::string path = out_dir + "/" + stem + "." + res + "." + variants[v].name + ".pack";
      const auto t0 = std::chrono::steady_clock::now();
      st::build_map(scene, light, o, path);
      secs[v] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      bytes[v] = fs::file_size(path);
      row[variants[v].name] = {{"bytes", bytes[v]}, {"seconds", secs[v]}, {"pack", path}};
    }
    auto ratio = [](uint64_t a, uint64_t b) { return b ? double(a) / double(b) : 0.0; };
    const double ps = ratio(bytes[2], bytes[1]), ds = ratio(bytes[0], bytes[1]), pd = ratio(bytes[2], bytes[0]);
    row["planes_over_static"] = ps;
    row["default_over_static"] = ds;
    row["planes_over_default"] = pd;
    std::printf("%-40s %6s %12llu %12llu %12llu %8.2f %8.2f %8.3f %8.1f %8.1f\n", stem.c_str(), res.c_str(),
                (unsigned long long)bytes[0], (unsigned long long)bytes[1], (unsigned long long)bytes[2], ps, ds, pd,
                secs[0], secs[2]);
    if (stats && fit_stats.tiles) {
      const st::PlaneFitStats& f = fit_stats;
      std::printf("  fit: %llu tiles searched; valued nodes %llu -> %llu left (finest texels %llu -> %llu); "
                  "%llu plane blocks, %llu labelled (%llu wide)\n",
                  (unsigned long long)f.tiles, (unsigned long long)f.values_before, (unsigned long long)f.values_after,
                  (unsigned long long)f.leaves_before, (unsigned long long)f.leaves_after,
                  (unsigned long long)f.plane_blocks, (unsigned long long)f.labelled_blocks, (unsigned long long)f.wide_blocks);
      const char* why[3] = {"fewer nodes than min_labelled", "a texel without preimage", "more planes than max_palette"};
      for (int r = 0; r < 3; ++r)
        std::printf("  8x8 left, %-30s %9llu blocks %10llu valued nodes\n", why[r], (unsigned long long)f.left_blocks[r],
                    (unsigned long long)f.left_values[r]);
      std::printf("  8x8 tried, planes the growth needs: blocks (valued nodes)\n   ");
      for (int k = 0; k <= 16; ++k)
        if (f.need_blocks[k])
          std::printf(" %s%d: %llu (%llu)", k == 16 ? ">=" : "", k, (unsigned long long)f.need_blocks[k],
                      (unsigned long long)f.need_values[k]);
      std::printf("\n");
      nlohmann::json js = {{"tiles", f.tiles.load()}, {"values_before", f.values_before.load()},
                           {"values_after", f.values_after.load()}, {"leaves_before", f.leaves_before.load()},
                           {"leaves_after", f.leaves_after.load()}, {"wide_blocks", f.wide_blocks.load()}};
      for (int k = 0; k <= 16; ++k) js["need_blocks"].push_back(f.need_blocks[k].load());
      for (int k = 0; k <= 16; ++k) js["need_values"].push_back(f.need_values[k].load());
      for (int r = 0; r < 3; ++r) js["left_blocks"].push_back(f.left_blocks[r].load()), js["left_values"].push_back(f.left_values[r].load());
      row["fit_stats"] = js;
    }
    std::fflush(stdout);
    rows.push_back(row);
  }
  if (!json_path.empty()) std::ofstream(json_path) << rows.dump(2) << "\n";
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_plane_packs: %s\n", e.what());
  return 1;
}

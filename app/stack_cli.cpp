#include <cstdio>

#include "app/command.hpp"
#include "app/progress.hpp"
#include "app/stack_cli.hpp"
#include "common/error.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "image/exr_io.hpp"
#include "image/png_io.hpp"
#include "tiles/bake/stack_build.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/stack_grid.hpp"
#include "tiles/core/stack_map.hpp"

namespace st::cli {

void run_stack_build(const StackBuildArgs& a) {
  const LightSetSpec spec = LightSetSpec::parse(a.light);
  StackBuildOptions o;
  o.map_level = parse_resolution(a.resolution);
  o.skip_level = a.skip_level;
  o.tile_bytes = a.tile_bytes;
  o.compression_level = a.compression;
  o.cells = parse_stack_cells(a.cells);
  o.split_cells = a.split_cells;
  o.planes = a.planes;
  o.scene_spec = a.scene;
  o.light_spec = a.light;
  SceneOptions so;
  so.up = parse_up_axis(a.up);
  const Scene scene = load_scene(a.scene, so);
  if (!a.quiet) std::printf("%s\n", summary(scene).c_str());
  Progress progress("build " + a.out, "slices");
  if (!a.quiet) o.progress = [&](uint32_t done, uint32_t total) { progress.update(done, total, 0); };
  const StackBuildReport r = build_stack_pack(scene, spec, o, a.out);
  progress.finish();
  const double side = double(uint64_t(1) << r.map_level);
  std::printf("built %s: stack of %u slices of %.0f^2, octree skip level %u (%llu cells), %llu tiles (largest %llu B), "
              "%.2f MiB (%.4f%% of the raw float32 slices)\n",
              a.out.c_str(), r.slices, side, r.skip_level, (unsigned long long)r.cells, (unsigned long long)r.tiles,
              (unsigned long long)r.max_tile_bytes, double(r.pack_bytes) / (1 << 20),
              100.0 * double(r.pack_bytes) / (side * side * 4 * r.slices));
  if (r.split_cells) std::printf("  %llu cells split below the skip level (tiles over %u B)\n",
                                 (unsigned long long)r.split_cells, a.tile_bytes);
  if (r.slice_cells) std::printf("  %llu of the %llu tiles per slice (stored smaller than the octree)\n",
                                 (unsigned long long)r.slice_cells, (unsigned long long)r.tiles);
  std::printf("  trace %.1f s (%s), octree+encode %.1f s (%llu nodes, %llu blocks of level %u), top+patch %.1f s, "
              "write %.1f s; exit depths %s; spilled %.1f MiB\n",
              r.trace_seconds, r.bounds_by.c_str(), r.octree_seconds, (unsigned long long)r.octree_nodes,
              (unsigned long long)r.blocks, r.block_level, r.cut_seconds, r.write_seconds,
              r.exit_depths ? "yes" : "no (no closed mesh)", double(r.spill_bytes) / (1 << 20));
}

void verify_stack_pack(const std::string& pack, const std::string& scene_spec, const std::string& up,
                       uint64_t max_mismatches) {
  std::shared_ptr<const PackReader> reader = PackReader::open(pack);
  try {
    reader->verify();
    reader->check_depth_range();
  } catch (const FormatError& e) {
    std::printf("verify %s: FAILED structure/checksum check: %s\n", pack.c_str(), e.what());
    exit_with(kExitMismatch);
  }
  const StackGrid& g = *reader->stack();
  std::printf("verify %s: all %zu octree tiles, checksums and the stack grid are intact\n", pack.c_str(),
              reader->tiles().size());
  SceneOptions so;
  so.up = parse_up_axis(up);
  const Scene scene = load_scene(scene_spec, so);
  if (scene.content_hash() != reader->header().scene_hash)
    std::printf("warning: the scene's hash differs from the one the pack was built from\n");
  const ResidentStack rs(*reader);
  const uint32_t n = g.geo.n;
  const uint64_t side = uint64_t(1) << n;
  if (double(side) * double(side) * g.slices > double(kMaxResidentStackTexels))
    throw Error("verify: the stack's " + std::to_string(g.slices) + " slices of " + std::to_string(side) +
                "^2 exceed the 2^28 texels verify re-traces");
  // Re-trace with the builder the pack records (packs from before it: Embree).
  std::string builder = "embree";
  for (const auto& [k, v] : reader->params())
    if (k == "builder") builder = v;
  uint64_t bad = 0, checked = 0;
  for (uint32_t w = 0; w < g.slices; ++w) {
    const IntervalTile t = trace_slice(scene, g.light(w), {n, 0, 0, uint32_t(side), uint32_t(side)}, builder != "raster");
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x) {
        const Interval iv = t.data[y * side + x];
        const float v = rs.map().depth(x, y, w, n);
        ++checked;
        if (iv.lo <= v && v <= iv.hi) continue;
        if (bad++ < 10)
          std::printf("  mismatch: slice %u texel (%llu, %llu): stored %.9g outside [%.9g, %.9g]\n", w,
                      (unsigned long long)x, (unsigned long long)y, double(v), double(iv.lo), double(iv.hi));
        if (bad >= max_mismatches) break;
      }
    if (bad >= max_mismatches) break;
  }
  if (bad) {
    std::printf("verify %s: FAILED: %llu of %llu re-traced texels break the lossless invariant\n", pack.c_str(),
                (unsigned long long)bad, (unsigned long long)checked);
    exit_with(kExitMismatch);
  }
  std::printf("verify %s: every texel of all %u slices (%llu) re-traced: the lossless invariant holds\n",
              pack.c_str(), g.slices, (unsigned long long)checked);
}

void export_stack_slice(const std::string& pack, uint32_t slice, std::optional<uint32_t> level_arg,
                        const std::string& out) {
  std::shared_ptr<const PackReader> reader = PackReader::open(pack);
  if (!reader->stack()) throw Error("export --slice: '" + pack + "' is not a stack pack");
  reader->check_depth_range();
  const StackGrid& g = *reader->stack();
  if (slice >= g.slices)
    throw Error("--slice " + std::to_string(slice) + ": the stack has slices 0.." + std::to_string(g.slices - 1));
  const uint32_t level = level_arg.value_or(std::min<uint32_t>(g.geo.n, 12));
  if (level > g.geo.n)
    throw Error("--level " + std::to_string(level) + " exceeds the stack's finest level " + std::to_string(g.geo.n));
  if (level > 13) throw Error("export --slice: level " + std::to_string(level) + " exceeds 8192^2 texels");
  const ResidentStack rs(*reader);
  const uint64_t side = uint64_t(1) << level;
  IntervalTile t;
  t.level = level, t.width = uint32_t(side), t.height = uint32_t(side);
  t.data.resize(side * side);
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const float v = rs.map().depth(x, y, slice, level);
      t.data[y * side + x] = {v, v};
    }
  ExrLightInfo info;
  info.space = g.light(slice);
  info.spec = info.space->spec().to_string();
  write_interval_exr(out, t, info);
  std::string png = out;
  auto dot = png.rfind('.');
  png = (dot == std::string::npos ? png : png.substr(0, dot)) + ".png";
  write_depth_preview_png(png, t);
  std::printf("exported slice %u level %u (%llu^2) of %s to %s and %s\n", slice, level, (unsigned long long)side,
              pack.c_str(), out.c_str(), png.c_str());
}

void inspect_stack(const PackReader& r, nlohmann::json& j, bool print) {
  const StackGrid& g = *r.stack();
  uint64_t tiles = 0;
  for (const StackEntry& e : g.entries) tiles += e.kind == 1;
  j["stack"] = {{"slices", g.slices},       {"xy_level", g.geo.n},      {"w_level", g.geo.k},
                {"octree_levels", g.geo.levels()}, {"skip_level", g.skip_level}, {"cells", g.entries.size()},
                {"tile_cells", tiles},      {"light_set", g.spec}};
  if (print)
    std::printf("  stack        %u slices of %llu^2 (w padded to %u), octree skip level %u: %zu cells, %llu tiles\n"
                "  light set    %s\n",
                g.slices, (unsigned long long)(uint64_t(1) << g.geo.n), 1u << g.geo.k, g.skip_level, g.entries.size(),
                (unsigned long long)tiles, g.spec.c_str());
}

}  // namespace st::cli

// shadowtile build: scene + light -> pack file.
#include <bit>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <optional>

#include "scene/scene_limits.hpp"
#include "tiles/bake/deep_build.hpp"
#include "tiles/bake/deep_exr.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "app/scene_limits_option.hpp"
#include "app/command.hpp"
#include "app/html_page.hpp"
#ifdef SHADOWTILE_HAVE_MPI
#include "app/build_mpi.hpp"
#endif
#include "app/progress.hpp"
#include "app/stack_cli.hpp"
#include "tiles/core/light_set.hpp"
#include "common/error.hpp"
#include "tiles/core/pack_format.hpp"

namespace st::cli {
namespace {

// --raster-skip auto picks regions from this map level (131072^2) up; with --intervals
// static from 16384^2 up, where open layers are proven (world of 25 Quake 3 levels at
// 16384^2: 15.5 s regions vs 25.3 s exact; oa_dm1: 6.9 vs 23.9 s; equal at 4096^2).
constexpr uint32_t kAutoRegionsLevel = 17, kAutoRegionsLevelStatic = 14;

std::atomic<bool> g_cancel{false};
extern "C" void on_sigint(int) { g_cancel = true; }

TexelRegion parse_region(const std::string& text) {
  uint64_t v[4];
  if (std::sscanf(text.c_str(), "%lu,%lu,%lu,%lu", &v[0], &v[1], &v[2], &v[3]) != 4)
    throw Error("--region: expected X,Y,W,H, got '" + text + "'");
  return {v[0], v[1], v[2], v[3]};
}

struct BuildArgs {
  std::string scene_limits;  // --scene-limits (scene/scene_limits.hpp)
  std::string scene, light, resolution = "4096", encoding = "dagmh", out, report, region,
                     construction = "bottom-up", up, intervals = "default", shard,
              builder = "auto", skip = "auto";
  std::optional<uint32_t> skip_level;
  uint32_t tile_bytes = 64 * 1024, depth_bits = 16;
  int compression = 6;
  bool resume = false, quiet = false, mpi = false;
  // Deep tiles (scenes with partial occluders): level (default min(L, 11)), tile side,
  // samples per texel side, epsilon (negative: 0.25 / samples, DSM 2000 §4).
  std::optional<uint32_t> deep_level;
  uint32_t deep_tile = 16, deep_samples = 4;
  double deep_epsilon = -1;
  std::string deep_from;  // a deep OpenEXR to take the deep map from instead of sampling
  std::string dagmh_dictionary = "on";  // tiles/PACK.md "DAG-MH dictionary"
  std::string dagmh_tiles = "mixed";     // tiles/PACK.md "Mixed tiles"
  std::string planes = "auto";           // tiles/core/PLANES.md
  bool split_cells = true;               // stack packs: split only overflowing cells (tiles/core/MHOCT.md "Split cells")
  std::string stack_cells = "smaller";   // light sets: tiles/core/MHOCT.md "Per-slice cells"
};

// What the pack's deep directory records of the deep map.
struct DeepPart {
  DeepMapBuild map;
  double epsilon = 0;
  uint32_t samples_per_side = 1;
};

// Functions held in memory when a deep map is read from a deep EXR (4096^2 texels).
constexpr uint64_t kMaxDeepFromTexels = uint64_t(4096) * 4096;

void check_deep_tile(const BuildArgs& a) {
  if (a.deep_tile < 1 || a.deep_tile > 256 || (a.deep_tile & (a.deep_tile - 1)))
    throw Error("--deep-tile: a power of two in 1..256, got " + std::to_string(a.deep_tile));
}

std::string hex64(uint64_t v) {
  char buf[20];
  std::snprintf(buf, sizeof buf, "%016llx", (unsigned long long)v);
  return buf;
}

// --deep-from FILE: the deep map read from a deep OpenEXR (deep_exr.hpp), as `export
// --deep` writes it or another tool's tidy deep image of a whole map, instead of sampling
// the scene. The file must hold a whole level; when it records its light and scene they
// must be this build's. Its functions are kept as they are when it records their bound
// (epsilon), else compressed with --deep-epsilon (default 0.25 / --deep-samples); an
// explicit --deep-epsilon always compresses them again (the bounds add up).
DeepPart deep_from_exr(const BuildArgs& a, const Scene& scene, const LightSpec& spec, bool quiet) {
  if (!a.shard.empty() || a.mpi)
    throw Error("--deep-from with --shard/--mpi: a sharded build does not carry a deep part yet");
  check_deep_tile(a);
  DeepExrInfo info;
  const DeepRegion map = read_deep_exr(a.deep_from, &info, kMaxDeepFromTexels);
  const TraceRegion& r = map.region;
  const uint64_t side = uint64_t(1) << r.level;
  if (r.x0 != 0 || r.y0 != 0 || r.width != side || r.height != side)
    throw Error("--deep-from " + a.deep_from + ": holds texels " + std::to_string(r.x0) + "," + std::to_string(r.y0) +
                " " + std::to_string(r.width) + "x" + std::to_string(r.height) + " of level " +
                std::to_string(r.level) + ", not the whole " + std::to_string(side) +
                "^2 map (export it without --region)");
  if (a.deep_level && *a.deep_level != r.level)
    throw Error("--deep-from " + a.deep_from + ": its map is level " + std::to_string(r.level) +
                ", --deep-level says " + std::to_string(*a.deep_level));
  if (!info.light.empty() && info.light != spec.to_string())
    throw Error("--deep-from " + a.deep_from + ": exported for light '" + info.light + "', this build's light is '" +
                spec.to_string() + "'");
  if (!info.scene_hash.empty() && info.scene_hash != hex64(scene.content_hash()))
    throw Error("--deep-from " + a.deep_from + ": exported from another scene (content hash " + info.scene_hash +
                ", this scene's " + hex64(scene.content_hash()) + ")");
  const double base = std::max(info.epsilon, 0.0);
  double recompress = -1;
  if (a.deep_epsilon >= 0) recompress = a.deep_epsilon;
  else if (info.epsilon < 0) recompress = DeepSampleOptions{a.deep_samples, 1, -1}.effective_epsilon();
  DeepPart p;
  p.epsilon = base + std::max(recompress, 0.0);
  p.samples_per_side = info.samples_per_side ? info.samples_per_side : a.deep_samples;
  try {
    p.map = deep_tiles_from_functions(map, uint32_t(std::countr_zero(a.deep_tile)), recompress, p.epsilon,
                                      a.tile_bytes);
  } catch (const Error& e) {
    throw Error("--deep-from " + a.deep_from + ": " + e.what());
  }
  if (!quiet)
    std::printf("deep: from %s, %llu^2 texels, %zu tiles of %u^2 (%llu empty), %.1f KiB, epsilon %g%s\n",
                a.deep_from.c_str(), (unsigned long long)side, p.map.tiles.size(), a.deep_tile,
                (unsigned long long)p.map.empty_tiles, double(p.map.bytes) / 1024, p.epsilon,
                recompress >= 0 ? " (recompressed)" : "");
  return p;
}

// The deep tiles of a scene's partial occluders (DSM 2000), traced before the opaque map
// so that a bad option fails early; the pack gets them through before_finish.
std::optional<DeepPart> build_deep_part(const BuildArgs& a, const Scene& scene, const LightSpec& spec,
                                        const LightSpace& light, uint32_t map_level, bool quiet) {
  if (!a.deep_from.empty()) return deep_from_exr(a, scene, spec, quiet);
  if (!scene.any_partial()) return std::nullopt;
  if (!a.shard.empty() || a.mpi)
    throw Error("--shard/--mpi: this scene has partial occluders, whose deep tiles a sharded build does not make yet");
  check_deep_tile(a);
  // Default min(L, 11): leaf shadows need deep texels near the opaque map's size to match
  // the rays as an opaque scene does. A 4K^2 forest (render --diff, 960x540) differs on
  // 1.09% of receivers at deep level 9, 0.29% at 11 (the city: 0.25%), for 50 s of
  // sampling and 11 MiB of deep tiles against 3 s and 0.9 MiB.
  const uint32_t level = a.deep_level.value_or(std::min(map_level, 11u));
  DeepSampleOptions so;
  so.samples_per_side = a.deep_samples;
  so.epsilon = a.deep_epsilon;
  DeepSampler sampler(scene, light);
  DeepMapBuild d = build_deep_tiles(sampler, level, uint32_t(std::countr_zero(a.deep_tile)), so, a.tile_bytes);
  if (!quiet)
    std::printf("deep: %u^2 texels (%u^2 samples each), %zu tiles of %u^2 (%llu empty), %.1f KiB, epsilon %g, %.1f s\n",
                1u << level, a.deep_samples, d.tiles.size(), a.deep_tile, (unsigned long long)d.empty_tiles,
                double(d.bytes) / 1024, so.effective_epsilon(), d.sampling.seconds);
  return DeepPart{std::move(d), so.effective_epsilon(), a.deep_samples};
}

void run_build(const BuildArgs& a) {
  if (a.planes != "on" && a.planes != "off" && a.planes != "auto")
    throw Error("--planes: expected auto, on or off, got '" + a.planes + "'");
  if (LightSetSpec::names_light_set(a.light)) {  // a stack (app/stack_cli.cpp)
    if (a.resume || a.mpi || !a.shard.empty() || !a.region.empty())
      throw Error("build: --resume, --mpi, --shard and --region are not supported for light sets (stack packs)");
    return run_stack_build({a.scene, a.light, a.resolution, a.out, a.up, a.skip_level, a.tile_bytes, a.compression,
                            a.quiet, a.stack_cells, a.split_cells, a.planes != "off"});
  }
  MapBuildOptions o;
  o.map_level = parse_resolution(a.resolution);
  o.encoding = parse_encoding(a.encoding);
  o.skip_level = a.skip_level;
  o.tile_bytes = a.tile_bytes;
  o.vsdag_z_bits = a.depth_bits;
  o.resume = a.resume;
  o.compression_level = a.compression;
  if (a.construction == "bottom-up") o.construction = MhConstruction::bottom_up;
  else if (a.construction == "top-down") o.construction = MhConstruction::top_down;
  else throw Error("--construction: expected bottom-up or top-down, got '" + a.construction + "'");
  if (!a.region.empty()) o.region = parse_region(a.region);
  if (a.intervals == "static") o.intervals = IntervalRule::static_geometry;
  else if (a.intervals != "default")
    throw Error("--intervals: expected default or static, got '" + a.intervals + "'");
  o.builder = parse_bounds_builder(a.builder);
  // auto: whole proven regions (regions) from 128K^2 up (16K^2 up for static intervals),
  // where tracing every texel takes hours; below, the exact per-tile skip (the
  // definition's bits on every texel).
  const uint32_t regions_level =
      o.intervals == IntervalRule::static_geometry ? kAutoRegionsLevelStatic : kAutoRegionsLevel;
  o.raster_skip = a.skip == "auto" ? (o.map_level >= regions_level ? RasterSkip::regions : RasterSkip::exact)
                                   : parse_raster_skip(a.skip);
  if (a.dagmh_dictionary != "on" && a.dagmh_dictionary != "off")
    throw Error("--dagmh-dictionary: expected on or off, got '" + a.dagmh_dictionary + "'");
  o.dagmh_dictionary = a.dagmh_dictionary == "on" && o.encoding == Encoding::dagmh;
  if (a.dagmh_tiles != "mixed" && a.dagmh_tiles != "exhaustive" && a.dagmh_tiles != "dagmh")
    throw Error("--dagmh-tiles: expected mixed, exhaustive or dagmh, got '" + a.dagmh_tiles + "'");
  o.dagmh_mixed_tiles = a.dagmh_tiles != "dagmh" && o.encoding == Encoding::dagmh;
  o.dagmh_mixed_exhaustive = a.dagmh_tiles == "exhaustive";
  if (a.planes == "on" && o.encoding == Encoding::vsdag) throw Error("--planes on: vsdag has no plane tiles (mh, mmh, dagmh do)");
  o.planes = a.planes == "on" || (a.planes == "auto" && o.encoding != Encoding::vsdag);
  if (!a.shard.empty()) o.shard = BuildShard::parse(a.shard);
  if (a.mpi && o.shard) throw Error("--mpi and --shard: choose one (a shard is one process's slice)");
#ifdef SHADOWTILE_HAVE_MPI
  if (a.mpi) mpi_init(nullptr, nullptr);
  const bool quiet = a.quiet || mpi_rank() != 0;  // only rank 0 reports
#else
  if (a.mpi) throw Error("--mpi: this shadowtile was built without MPI (install libopenmpi-dev, reconfigure)");
  const bool quiet = a.quiet;
#endif
  o.scene_spec = a.scene;
  o.light_spec = a.light;

  SceneOptions so;
  so.up = parse_up_axis(a.up);
  Scene scene = load_scene(a.scene, so, parse_scene_limits(a.scene_limits));
  LightSpec spec = LightSpec::parse(a.light);
  LightSpace light = LightSpace::fit(spec, scene.bounds());
  if (!quiet) std::printf("%s\n", summary(scene).c_str());
  const std::optional<DeepPart> deep = build_deep_part(a, scene, spec, light, o.map_level, quiet);
  if (deep) {
    scene = opaque_part(scene);  // the opaque map holds the opaque casters alone
    o.before_finish = [&deep](PackWriter& w) { append_deep_map(w, deep->map, deep->epsilon, deep->samples_per_side); };
  }

  Progress progress("build " + a.out, "texels");
  if (!quiet)
    o.progress = [&](uint64_t done, uint64_t total, uint64_t texels) { progress.update(done, total, texels); };
  g_cancel = false;
  o.cancel = &g_cancel;
  auto old_int = std::signal(SIGINT, on_sigint);
  auto old_term = std::signal(SIGTERM, on_sigint);
  MapBuildReport r;
  try {
#ifdef SHADOWTILE_HAVE_MPI
    if (a.mpi) {
      auto done = build_map_mpi(scene, light, o, a.out);
      progress.finish();
      if (!done) return;  // ranks other than 0 report nothing
      r = std::move(done->first);
      std::string per_rank;
      for (size_t i = 0; i < done->second.cells_by_rank.size(); ++i)
        per_rank += (i ? ", " : "") + std::to_string(done->second.cells_by_rank[i]);
      if (!quiet)
        std::printf("mpi: %d ranks built cells %s (rank 0 first); %.2f MiB of journal sent to rank 0\n",
                    done->second.ranks, per_rank.c_str(), double(done->second.bytes_received) / (1 << 20));
    } else
#endif
      r = build_map(scene, light, o, a.out);
  } catch (...) {
    progress.finish();
    std::signal(SIGINT, old_int);
    std::signal(SIGTERM, old_term);
    if (g_cancel) {
      std::fprintf(stderr, "shadowtile: build interrupted; '%s.tmp' kept, continue with --resume\n",
                   a.out.c_str());
      exit_with(kExitInterrupted);
    }
    throw;
  }
  progress.finish();
  std::signal(SIGINT, old_int);
  std::signal(SIGTERM, old_term);

  const double res = double(uint64_t(1) << r.map_level);
  if (o.shard)
    std::printf("built part %s: shard %s of a %.0f^2 %s map, %llu cells (%llu resumed), %.2f MiB; "
                "join the parts with: shadowtile merge PARTS... -o PACK\n",
                a.out.c_str(), o.shard->to_string().c_str(), res, r.encoding.c_str(),
                (unsigned long long)r.cells_total, (unsigned long long)r.cells_resumed,
                double(r.pack_bytes) / (1 << 20));
  else
    std::printf("built %s: %.0f^2 %s, skip level %u, %llu tiles (%llu index), %.2f MiB "
                "(%.4f%% of the raw float32 map)\n",
                a.out.c_str(), res, r.encoding.c_str(), r.skip_level, (unsigned long long)r.tile_count,
                (unsigned long long)r.index_tile_count, double(r.pack_bytes) / (1 << 20),
                100.0 * double(r.pack_bytes) / (res * res * 4));
  std::printf("  %.1f s wall, %.2f Mtexels/s, cells %llu built + %llu resumed + %llu outside region, "
              "constant entries %.1f%%, exit depths %s, peak memory %.0f MiB\n",
              r.wall_seconds, double(r.texels_traced) / r.wall_seconds / 1e6,
              (unsigned long long)r.cells_built, (unsigned long long)r.cells_resumed,
              (unsigned long long)r.cells_outside_region,
              r.grid_entries ? 100.0 * double(r.constant_entries) / double(r.grid_entries) : 0.0,
              r.exit_depths ? "yes" : "no (no closed mesh)", double(r.peak_rss_bytes) / (1 << 20));
  std::printf("  bounds by %s (%s)\n", r.builder.c_str(),
              r.builder == "raster" ? ("light-space rasterizer of the canonical coverage, skip " +
                                       std::string(to_string(o.raster_skip)))
                                          .c_str()
                                    : "Embree tracer; the rasterizer handles sun lights with the default intervals");
  if (r.texels_in_regions)
    std::printf("  regions: %.4g texels proven by their corners (no per-texel work), %.4g traced (%.3f%% of the map)\n",
                double(r.texels_in_regions), double(r.texels_traced), 100.0 * double(r.texels_traced) / (res * res));
  if (r.dictionary_bytes)
    std::printf("  DAG-MH dictionary: %.1f KiB shared by the tiles, %llu tiles rewritten, tiles' raw bytes %.2f -> %.2f MiB\n",
                double(r.dictionary_bytes) / 1024, (unsigned long long)r.dictionary_tiles_rewritten,
                double(r.dictionary_raw_before) / (1 << 20), double(r.dictionary_raw_after) / (1 << 20));
  else if (!r.dictionary_skipped.empty())
    std::printf("  DAG-MH dictionary: none (%s)\n", r.dictionary_skipped.c_str());
  std::printf("  thread-seconds: trace %.1f, hierarchy %.1f, cut+encode %.1f, compress+write %.1f\n",
              r.trace_seconds, r.hierarchy_seconds, r.cut_encode_seconds, r.write_seconds);
  if (!a.report.empty()) {
    std::ofstream f(a.report);
    f << r.to_json() << "\n";
    if (!f) throw Error("--report: cannot write '" + a.report + "'");
    f.close();
    // The page beside the JSON: build.json -> build.html.
    std::string page = a.report;
    if (page.size() > 5 && page.compare(page.size() - 5, 5, ".json") == 0) page.resize(page.size() - 5);
    write_html_page("build", a.report, page + ".html");
  }
}

void setup_build(CLI::App& app) {
  auto a = std::make_shared<BuildArgs>();
  app.footer(
      "Example:\n  shadowtile build procedural:city --light sun:azimuth=30,elevation=50 "
      "--resolution 64k --encoding dagmh -o city.pack --report build.json\n"
      "Interrupted builds (Ctrl-C, kill) leave OUT.tmp; the same command with --resume continues it.");
  app.add_option("scene", a->scene, "Scene file (any format assimp reads) or procedural:NAME[,k=v...]")
      ->required();
  app.add_option("--light", a->light,
                 "sun:azimuth=DEG,elevation=DEG[,margin=F] or spot:pos=X,Y,Z,target=X,Y,Z,fov=DEG")
      ->required();
  app.add_option("--resolution", a->resolution, "Map side: a power of two (4096, 16k, 64k, 1m)")
      ->capture_default_str();
  app.add_option("--encoding", a->encoding, "Tile encoding: dagmh, mmh, mh or vsdag (voxel shadow DAG)")->capture_default_str();
  app.add_option("--depth-bits", a->depth_bits, "vsdag: 2^N depth slabs per tile, N in 3..20 (exact beyond one slab of a surface)")
      ->capture_default_str();
  app.add_option("--skip-level", a->skip_level,
                 "Skip level K: the 2^K x 2^K grid fetched when a map opens (default min(ceil(L/2), 8))");
  app.add_option("--tile-bytes", a->tile_bytes,
                 "Bound on one tile's encoded size, in " + tile_bytes_bounds() +
                     "; larger subtrees are cut deeper into index tiles")
      ->capture_default_str();
  app.add_option("-o,--output", a->out, "Pack file to write (built as OUT.tmp, renamed when complete)")
      ->required();
  app.add_option("--report", a->report, "Write a JSON build report (stage times, sizes, histogram, memory) and an HTML page beside it");
  app.add_flag("--resume", a->resume, "Continue OUT.tmp left by an interrupted build");
  app.add_option("--construction", a->construction, "MH construction: bottom-up or top-down (MH §3.1)")
      ->capture_default_str();
  app.add_option("--region", a->region,
                 "Build only cells touching texels X,Y,W,H of the finest level (the rest constant)");
  app.add_option("--compression", a->compression, "zlib level 0..12 (libdeflate)")->capture_default_str();
  add_scene_file_options(app, a->up, a->scene_limits);
  app.add_option("--intervals", a->intervals,
                 "default: [first hit, exit of closed objects]; static: an open surface's interval also "
                 "reaches to just below the next surface (lossless for receivers on surfaces only)")
      ->capture_default_str();
  app.add_option("--shard", a->shard,
                 "I/N: build only shard I of N (the cells whose Z-order index is I mod N) into a part "
                 "file at OUT; `shadowtile merge` joins the N parts into the pack");
  app.add_flag("--mpi", a->mpi,
                "Run under mpirun: the cells spread over the ranks (dynamic scheduling), rank 0 writes "
                "the pack; --resume continues after a rank died");
  app.add_option("--builder", a->builder,
                 "Depth bounds producer: raster (light-space rasterizer; sun lights, either interval rule), "
                 "embree (ray tracer; every light), or auto (raster where it applies)")
      ->capture_default_str();
  app.add_option("--raster-skip", a->skip,
                 "Rasterizer tiles covered by one closed object's entry and exit (with --intervals static also "
                 "by one open layer with everything else beyond it): exact (their intervals "
                 "from the two planes, the same bits as off), narrow (one sub-interval per tile: lossless, "
                 "recorded as intervals_narrowed=yes), regions (narrow, and whole quadtree regions of a cell "
                 "proven by their corners become one node: work follows the edges between surfaces, not "
                 "the texel count; for the largest maps), off (every texel through the coverage tests) or auto "
                 "(regions from 128K^2 up, with --intervals static from 16K^2 up, else exact)")
      ->capture_default_str();
  app.add_option("--deep-level", a->deep_level,
                 "Scenes with partial occluders: the deep map is 2^N texels a side (default min(L, 11))");
  app.add_option("--deep-tile", a->deep_tile, "Deep tile side in texels, a power of two <= 256")->capture_default_str();
  app.add_option("--deep-samples", a->deep_samples, "Deep map: jittered samples per texel side (1..64)")
      ->capture_default_str();
  app.add_option("--deep-epsilon", a->deep_epsilon,
                 "Deep map: compression bound on transmittance (default 0.25 / samples, DSM 2000 §4)");
  app.add_option("--deep-from", a->deep_from,
                 "Take the deep map from this deep OpenEXR (as `export --deep` writes, or another tool's tidy "
                 "deep image of a whole map in this light's depth) instead of sampling the scene; the opaque "
                 "map is still built from the scene's opaque meshes");
  app.add_option("--dagmh-dictionary", a->dagmh_dictionary,
                 "dagmh: on (default) moves subtrees found in two or more tiles into one pack-wide dictionary "
                 "that clients fetch once with the skip grid (smaller tiles, same answers); off keeps every tile "
                 "self-contained")
      ->capture_default_str();
  app.add_option("--stack-cells", a->stack_cells,
                 "light sets (stack packs): smaller (default) stores each cell as the stack's octree or as its "
                 "slices' own DAG-MH/MMH tiles, whichever is smaller; octree stores every cell as the octree "
                 "(the packs of earlier versions, byte for byte); slices stores every cell per slice. Every "
                 "reader, the GPU passes included, takes all three")
      ->check(CLI::IsMember({"octree", "smaller", "slices"}))
      ->capture_default_str();
  app.add_flag("--split-cells,!--no-split-cells", a->split_cells,
               "light sets (stack packs): on (default) where a cell overflows --tile-bytes split only that "
               "cell one level deeper (feature stack_split_cells; smaller packs; every reader, the GPU passes "
               "included, takes them); --no-split-cells (or --split-cells=false) moves the whole cut deeper "
               "instead (the uniform cut, a pack readers before split cells open)");
  app.add_option("--planes", a->planes,
                 "on: a tile may store blocks of texels that one plane answers exactly as planes over the "
                 "encoding of the rest, where that stores smaller (open surfaces; tiles/core/PLANES.md); "
                 "auto (default): on for mh, mmh and dagmh, off for vsdag, on for light sets (a per-slice "
                 "cell's slices); off: never")
      ->capture_default_str();
  app.add_option("--dagmh-tiles", a->dagmh_tiles,
                 "dagmh: mixed (default) writes a tile as MMH where that is likely to store in fewer bytes "
                 "(mostly zero-width intervals: open meshes), encoding both only where unsure; exhaustive "
                 "encodes every tile both ways and keeps the smaller (never larger than MMH's tile for tile; "
                 "slower); dagmh writes every tile as DAG-MH")
      ->capture_default_str();
  app.add_flag("-q,--quiet", a->quiet, "No summary or progress");
  app.callback([a]() { run_build(*a); });
}

Register reg_build{"build", "Build a pack: depth bounds -> hierarchy -> encode -> tiles (out of core)", setup_build};

}  // namespace
}  // namespace st::cli

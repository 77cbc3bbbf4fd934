// The GPU tile cache inside a rasterizer, as an engine uses it (examples/raster, engine mode):
//
// 1. The lookup a GPU is judged by: in the same shading pass of the same frame (a depth
//    pre-pass, then each visible pixel's fragment shader once), st_shadow over the GPU tile
//    cache against a plain R32F shadow map of the map's finest level sampled in the same
//    fragment shader (texelFetch, the same texel, lit test and PCF taps), single tap and
//    5x5 PCF, and the pass with no lookup. Shading-pass times from device timestamps,
//    medians over --reps interleaved frames; the ratio is shadowtile / R32F (the whole pass,
//    and the lookups alone: each less the pass without lookups).
// 2. Engine mode's frame path: per frame, --arriving tiles land in the client's cache (fetched
//    between frames, off the frame path) and the frame's GpuMap calls (retire, record_uploads,
//    record_end_of_frame) are timed on the host; the frame's bus bytes (tile + page-table +
//    feedback) against its tile + page-table bytes. Before each timed frame the device is let
//    finish the frames in flight (not retired: the timed retire() still collects them), since
//    a CPU device (lavapipe) runs them on the same cores and would take the CPU from the timed
//    calls, which a GPU never does; --overlap records while they still run.
//
//   bench_raster [--scenes procedural:city,FILE...] [--light sun:azimuth=30,elevation=50]
//                [--res 2k] [--encoding dagmh] [--tile-bytes 65536] [--width 1920] [--height 1080]
//                [--reps 5] [--kernels 1,5] [--arriving 100] [--arrival-frames 10] [--device NAME]
//                [--out bench-out/raster] [--json PATH] [--no-frame-path] [--overlap] [--no-ratio] [--no-r32f]
//                [--cpu-time]
//                [--region X,Y,W,H] [--scene-limits seconds=S,...]
//
// --kernels: the PCF kernel sides timed (odd, 1..9), each against R32F with the same kernel.
// --cpu-time: the timed frames run one at a time and the process's CPU time per frame is kept
// too (JSON cpu_*; cpu_lookup_ratioN = (st - none) / (R32F - none) in CPU time): on a CPU
// device under load (lavapipe on a shared machine) a steadier figure than the timestamps.
// On lavapipe (Mesa 22.3) set MESA_SHADER_CACHE_DISABLE=true: a fragment shader loaded from
// Mesa's disk cache shaded about 2x slower in every mode ("none" too) than one compiled fresh,
// so runs mixing the two differ by that, and the ratio reads lower with the cached one.
// Where lavapipe's shadowtile time goes (Mesa 22.3, LLVM 15, a profile of the shading
// threads over the JIT code): llvmpipe compiles each storage-buffer read of a fragment
// shader (ST_POOL / ST_PAGE, constant addresses too) to a loop over the 8 lanes with a
// branch on each lane's mask bit and a bounds test (the fragment shader's ~450 read
// sites); about two thirds of the shader's samples fall in such loops, about half even when
// every lane is off. The R32F baseline's texelFetch is
// one vectorised gather. The lookup's cost on lavapipe follows its count of buffer reads.
// Branches are lane masks there (an `if` or early return skips nothing), so the "none" and
// R32F frames of this one shader also run the lookup's code with every lane off.
// Texel buffers (shadowtile.glsl's ST_TEXEL_BUFFERS, GpuOptions::texel_buffers: the pool and
// page table read with texelFetch on usamplerBuffers) did not help here: the same command
// (2k maps, 4096-byte tiles, 640x360, --reps 5 --kernels 1,5 --no-frame-path --cpu-time,
// MESA_SHADER_CACHE_DISABLE=true), main's storage-buffer shader (A) and the texel one (B)
// alternated A B A B, load 21-29: ratio to R32F 1 tap / 5x5, city A 2.06/2.24, 2.01/2.30,
// B 2.02/2.81, 1.97/2.98; 2CylinderEngine.glb A 1.86/3.33, 1.79/4.26, B 1.76/4.38, 1.85/4.03.
// Process CPU per frame (st 5x5 / R32F 5x5, ms): engine A 512/157, 447/136, B 505/134, 417/118;
// the R32F frames (whose page reads became fetches too) got cheaper, the 5x5 lookup hardly.
// So the example keeps storage buffers; the texel mode stays for engines (tested bit-exact).
// Plane tiles: the real open mesh's pack has them (features plane-tiles, mixed-tiles; the
// city's has none), and st_pcf_plane used to send every tap of a plane tile to its second
// loop, through st_answer and every decoder: about a third of the engine's 5x5 cost. Taken in
// the first loop (a plane block answers the texel alone, else the inner buffer), the same
// command (load 8-18, main's binary A and the new one B alternated) gave the engine's 5x5
// ratio A 5.62/6.47/5.56 (process CPU 5.20/4.96/4.65) against B 4.32/4.04/4.75 (CPU
// 3.71/3.59/3.40; the first two B with the bounds test below still in); city and
// the single tap unchanged (city 5x5 A 2.25/2.13, B 2.17/2.34). A DAG-MH tile's value bounds
// from its chunk infos (every kernel tap in the tile lit or none at once) did not move it:
// within noise, even when every such kernel was answered with no tap at all (a non-exact
// test build), so it was not kept.
// Plane blocks by groups: st_pcf_plane's first loop answered a plane tile's taps one a pass,
// each with its own block search and the plane's six reads. Now one search finds the block of
// the first tap not counted and every kernel tap in that block with the same plane (the
// block's, or the tap's label's palette entry) counts in the same pass from the plane's words
// read once; the first loop also walks and opens the tile once a pass, the walk's taps in an
// inner loop. The same command (load 6-33, alternated; main A, this B; B1-B4 the
// intermediate builds, B5-B6 the final one), ratio to R32F 5x5 device / process CPU:
// 2CylinderEngine.glb A 3.57/3.54, 3.38/3.15, 4.06/3.60, 4.19/3.69, B 2.41/2.30, 2.48/2.23,
// 2.65/2.32, 2.68/2.25, 2.13/2.14, 2.45/2.24; city A 2.23/2.33, 2.56/2.36, 2.35/2.29,
// 2.10/1.97, B 2.79/2.58, 2.48/2.28, 2.47/2.48, 2.39/2.23, 2.02/2.00, 2.49/2.37 (no plane
// tiles: its change is noise). The single tap did not move (engine ~1.7-2.0 CPU).
// Buffer-read sites per loop pass: llvmpipe compiles each storage-buffer load to a loop over the
// 8 lanes (one loop per load, all its components inside), run on every pass of the enclosing
// loop. The GLSL PCF now reads runs of tile words as the uvec4 quads that hold them (ST_POOL4:
// a DAG-MH chunk, skip entry, treelet, tile header, a plane's and a block's labels' six words),
// the page table's header once a call, an MH tile's header and root once a walk, and its second
// loop decodes voxel tiles alone: scene.frag's read sites 426 -> 324. The same command (load
// 15-34, main A and the new binary B alternated, 4 rounds each; the first B without the MH and
// plane-header reads once a walk), ratio to R32F 5x5 process CPU
// (device): city A 2.30/2.20/2.11/2.28 (2.07/2.10/2.70/2.46), B 2.12/2.23/2.16/2.14
// (1.98/2.28/2.71/2.16); 2CylinderEngine.glb A 2.14/2.33/2.39/2.30 (2.50/2.91/2.42/2.75),
// B 2.12/2.05/2.13/2.09 (2.11/2.37/2.75/2.80). CPU ms per 5x5 frame: city A 1125-1326, B 904-1022;
// engine A 339-423, B 249-296; the "none" and R32F frames, which run this shader with the
// lookup's lanes off, got cheaper too (city "none" A 416-541, B 377-458), so the ratio moved less.
// A plane tile's taps in a loop of their own (st_pcf_plane: the plane block search and plane
// reads in a plane loop, taps no block answers left pending to a decode loop that carries the
// DAG-MH/MH decoders alone): the same command, fresh MESA_SHADER_CACHE_DIR per run, main A and
// the new shader B alternated in 5 rounds at load 12-27, ratio to R32F 5x5 device / process CPU:
// city A 2.50/2.20, 2.72/2.26, 2.55/2.45, 2.17/2.23, 2.29/2.17, B 2.39/2.29, 2.46/2.62,
// 2.35/2.02, 2.57/2.22, 2.08/2.25 (no plane tiles: within noise); 2CylinderEngine.glb A
// 2.61/2.19, 2.62/2.12, 2.98/2.18, 1.90/2.00, 2.02/2.12, B 2.10/1.96, 2.38/2.10, 2.24/2.03,
// 2.61/2.03, 2.38/2.06 (medians A 2.61/2.12, B 2.38/2.03; CPU ms per 5x5 frame 271 -> 260).
// The DAG-MH dictionary in the pool (GPU_LAYOUT.md layout 9: a node word of either side is
// one pool read, where the page-table dictionary made it a page read and a pool read per
// word): the same command, fresh MESA_SHADER_CACHE_DIR per run, main A and B alternated in
// 10 pairs at load 16-29, ratio to R32F 5x5 medians device / process CPU: city A 2.42/2.15,
// B 2.23/2.07 (B lower in 7 of 10 pairs, both); 2CylinderEngine.glb (no dictionary: only the
// masked page reads left) A 2.33/2.03, B 2.33/2.01 (CPU lower in 8 of 10). Median CPU ms
// none / 1 tap / 5x5 / R32F 5x5: city A 359/763/948/405, B 337/680/856/409; the first tap
// (st 1 - none: A 404, B 343 ms) is most of a 5x5's lookup (st 5x5 - none: A 589, B 519).
// --region builds only a window of the map (finest texels; the rest lit): a 64K^2 map in
// minutes; the camera then looks at the window. The R32F map (the finest level, 4^L floats)
// is skipped with --no-r32f, with --region, and above 16K^2: its rows print '-'.
// Each scene's pack is built once into --out (reused), served by an in-process server and
// fetched whole into the client's cache before the ratio (so no frame has holes: asserted);
// the frame-path run starts from an empty cache. The camera looks down at the scene's
// footprint from its world frame (loadgen::map_world_frame). Default scenes: the procedural
// city and a real open mesh, Debian's assimp test model 2CylinderEngine.glb (a CAD engine).
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <nlohmann/json.hpp>
#include <thread>

#include "bench/options.hpp"
#include "bench/bench_map.hpp"
#include "examples/raster/flat_mesh.hpp"
#include "examples/raster/raster.hpp"
#include "loadgen/load_run.hpp"
#include "server/catalog.hpp"
#include "server/server.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene_limits.hpp"

namespace {

using namespace st;
using namespace st::bench;

// The process's CPU time (every thread: a CPU Vulkan device such as lavapipe shades in its own
// threads), in ms: steadier than device timestamps on a loaded machine.
double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

struct Args {
  std::string scenes = "procedural:city,/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
  std::string light = "sun:azimuth=30,elevation=50", res = "2k", encoding = "dagmh", device;
  std::string out = "bench-out/raster", json;
  std::vector<uint32_t> kernels = {1, 5};
  uint32_t tile_bytes = 64 * 1024, width = 1920, height = 1080, reps = 5, arriving = 100, arrival_frames = 10;
  bool frame_path = true, ratio = true, r32f = true, idle = true;
  bool cpu_time = false;  // --cpu-time: timed frames one at a time, the process's CPU time per frame too
  std::optional<TexelRegion> region;  // --region: a window of the map built (the rest constant, lit)
  SceneLimits limits;                 // --scene-limits: the scene reader's (a loaded machine reads slowly)
};

Args parse(int argc, char** argv) {
  Args a;
  Options opt("bench_raster", "Lookups in a rasterizer's fragment shader against an R32F shadow map, and engine mode's frame path");
  opt.value("--scenes", a.scenes, "Scene specs, comma-separated")
      .value("--light", a.light, "Light spec")
      .value("--res", a.res, "Map side")
      .value("--encoding", a.encoding, "mh, mmh or dagmh")
      .value("--tile-bytes", a.tile_bytes, "Tile budget in bytes")
      .value("--width", a.width, "Framebuffer width")
      .value("--height", a.height, "Framebuffer height")
      .value("--reps", a.reps, "Median of R frames")
      .with("--kernels", [&](const std::string& list) {
              a.kernels.clear();
              for (const std::string& v : split_list(list)) {
                const unsigned long r = v.find_first_not_of("0123456789") == std::string::npos && !v.empty() ? std::stoul(v) : 0;
                if (r < 1 || r > 9 || r % 2 == 0) throw Error("--kernels takes odd sides 1..9, got '" + v + "'");
                a.kernels.push_back(uint32_t(r));
              }
            }, "PCF sides, odd 1..9, comma-separated [1,5]")
      .value("--arriving", a.arriving, "Tiles arriving per frame in the frame path (> 0)")
      .value("--arrival-frames", a.arrival_frames, "Timed frame-path frames with arrivals")
      .value("--device", a.device, "Vulkan device (by name)")
      .value("--out", a.out, "Prefix of the pictures and packs written")
      .value("--json", a.json, "Write the rows as JSON to PATH [OUT.json]")
      .flag("--no-frame-path", a.frame_path, "Skip engine mode's frame path (part 2)", false)
      .flag("--overlap", a.idle, "Frame path: record while the frames in flight still run", false)
      .with("--scene-limits", [&](const std::string& v) { a.limits = parse_scene_limits(v, a.limits); },
            "What reading a scene file may cost, KEY=VALUE[,...] (scene/scene_limits.hpp)")
      .flag("--no-ratio", a.ratio, "Skip the lookup ratio (part 1)", false)
      .flag("--no-r32f", a.r32f, "Skip the R32F baseline (its rows print '-')", false)
      .flag("--cpu-time", a.cpu_time, "Timed frames one at a time, the process's CPU time per frame too")
      .with("--region", [&](const std::string& v) {
              TexelRegion r;
              if (std::sscanf(v.c_str(), "%lu,%lu,%lu,%lu", &r.x, &r.y, &r.w, &r.h) != 4 || r.w == 0 || r.h == 0)
                throw Error("--region X,Y,W,H (finest texels), got '" + v + "'");
              a.region = r;
            }, "A window X,Y,W,H of the map built (finest texels; the rest constant, lit)");
  opt.parse(argc, argv);
  if (a.reps == 0 || a.width == 0 || a.height == 0 || a.arriving == 0) throw Error("bench_raster: counts must be > 0");
  if (a.kernels.empty()) throw Error("bench_raster: --kernels needs at least one side");
  if (a.json.empty()) a.json = a.out + ".json";
  return a;
}

std::string short_name(const std::string& scene) {
  const std::string base = std::filesystem::path(scene).stem().string();
  std::string s = scene.rfind("procedural:", 0) == 0 ? scene.substr(11) : base;
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return s;
}

struct Mode {
  const char* name;
  raster::Lookup lookup;
  uint32_t kernel;
};

struct Served {
  std::unique_ptr<server::Server> srv;
  uint64_t tiles = 0;
};

client::Map open_map(const Served& s, const std::string& name, uint32_t slots, std::unique_ptr<client::Client>& cl) {
  client::ClientOptions co;
  co.max_slot_bytes = 64u << 20;
  co.request_timeout = std::chrono::milliseconds(60000);
  co.cache_slots = slots;
  co.want_capacity = slots;
  cl = std::make_unique<client::Client>(client::Endpoint{"127.0.0.1", s.srv->port()}, co);
  return cl->open(name);
}

raster::FrameInput camera_of(const client::Map& map, const std::optional<TexelRegion>& window) {
  const loadgen::WorldFrame w = loadgen::map_world_frame(map);
  const Vec3d c = w.centre();
  const double span = w.span(), height = std::max(w.top - w.ground, 1e-3 * span);
  raster::FrameInput in;
  in.eye = {c.x + 0.55 * span, w.ground + height + 0.45 * span, c.z + 0.55 * span};
  in.target = {c.x, w.ground + 0.3 * height, c.z};
  in.fov_deg = 60;
  const client::MapInfo info = map.info();
  const client::WorldPoint f = info.light.forward();
  in.light = {-f.x, -f.y, -f.z};
  in.texel = info.light.texel_size({c.x, c.y, c.z}, info.finest_level);
  in.filter = false;  // the finest level: what the R32F map holds
  if (window) {  // look down at the window's centre from about its size away
    const uint64_t cx = window->x + window->w / 2, cy = window->y + window->h / 2, side = uint64_t(1) << info.finest_level;
    const float d = map.depth(info.finest_level, cx, cy);
    const client::WorldPoint t = info.light.to_world({(double(cx) + 0.5) / double(side), (double(cy) + 0.5) / double(side),
                                                      d >= 0 && d <= 1 ? double(d) : 0.5});
    const double size = double(std::max(window->w, window->h)) * info.light.texel_size(t, info.finest_level);
    in.eye = {t.x + 0.45 * size, t.y + 0.4 * size, t.z + 0.45 * size};
    in.target = {t.x, t.y, t.z};
  }
  return in;
}

}  // namespace

int main(int argc, char** argv) try {
  const Args a = parse(argc, argv);
  const uint32_t level = parse_level(a.res);
  std::filesystem::create_directories(a.out);
  nlohmann::json report = {{"light", a.light}, {"resolution", side_name(level)}, {"encoding", a.encoding},
                           {"width", a.width}, {"height", a.height}, {"reps", a.reps}};
  nlohmann::json ratio_rows = nlohmann::json::array(), path_rows = nlohmann::json::array();
  std::vector<std::string> ratio_lines, path_lines;
  std::string device;
  for (const std::string& spec : split_list(a.scenes)) {
    const Scene scene = load_scene(spec, {}, a.limits);
    const LightSpace light = LightSpace::fit(LightSpec::parse(a.light), scene.bounds());
    const std::string name = short_name(spec) + "_" + side_name(level) + "_" + a.encoding + "_t" + std::to_string(a.tile_bytes) +
                             (a.region ? "_win" + std::to_string(a.region->w) : std::string());
    const std::string path = a.out + "/" + name + ".pack";
    if (!std::filesystem::exists(path)) {
      MapBuildOptions o;
      o.map_level = level;
      o.encoding = parse_encoding(a.encoding);
      o.tile_bytes = a.tile_bytes;
      o.scene_spec = spec;
      o.light_spec = a.light;
      o.region = a.region;
      o.dagmh_dictionary = o.dagmh_mixed_tiles = true;  // the CLI's defaults
      std::fprintf(stderr, "bench_raster: building %s\n", path.c_str());
      build_map(scene, light, o, path);
    }
    server::ServerOptions so;
    so.host = "127.0.0.1";
    so.port = 0;
    so.log = [](const std::string&) {};
    Served s;
    s.srv = std::make_unique<server::Server>(server::Catalog::scan(std::vector<std::string>{path}), so);
    s.srv->start();
    std::unique_ptr<client::Client> cl;
    s.tiles = open_map(s, name, 1, cl).info().tile_count;
    const std::vector<float> tri = raster::flat_triangles(scene);

    // ---- 1. the lookup ratio, every tile resident ----
    if (a.ratio) {
      const bool r32f = a.r32f && !a.region && level <= 14;
      client::Map map = open_map(s, name, uint32_t(s.tiles + 8), cl);
      const uint64_t side = uint64_t(1) << level;
      map.request_region(level, 0, 0, side, side, 10);
      const auto t_end = Clock::now() + std::chrono::minutes(10);
      while (!map.region_resident(level, 0, 0, side, side) && Clock::now() < t_end)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      if (!map.region_resident(level, 0, 0, side, side)) throw Error("bench_raster: the map did not arrive in 10 minutes");
      // The R32F map: the finest level read back from the cache (every tile resident), rows
      // split over the machine's threads.
      std::vector<float> depths(r32f ? side * side : 0);
      if (r32f) {
        std::vector<std::thread> pool;
        const uint32_t n = std::max(1u, std::thread::hardware_concurrency());
        for (uint32_t t = 0; t < n; ++t)
          pool.emplace_back([&, t] {
            for (uint64_t y = t; y < side; y += n)
              for (uint64_t x = 0; x < side; ++x) depths[y * side + x] = map.depth(level, x, y);
          });
        for (auto& th : pool) th.join();
      }
      raster::RasterOptions ro;
      ro.width = a.width, ro.height = a.height, ro.device = a.device;
      ro.readback = false;
      // The whole cache in the first frame (no tile is larger than --tile-bytes). Sized to the
      // pack: GpuMap writes each frame's staging buffer (budget + slot + page table) once when
      // it is made, and a 1 GiB budget made that first touch (~2 GiB for two frames in flight)
      // a third of a run's process samples, outside the timed frames.
      ro.upload_budget_bytes = std::max<uint64_t>(16u << 20, uint64_t(s.tiles + 8) * a.tile_bytes);
      if (r32f) ro.r32f_level = level, ro.r32f = depths;
      raster::Rasterizer r(map, tri, ro);
      device = r.device_name();
      raster::FrameInput in = camera_of(map, a.region);
      // Mode 0 the pass without lookups, then per kernel shadowtile and R32F (interleaved).
      std::vector<Mode> modes = {{"none", raster::Lookup::none, 1}};
      for (const uint32_t k : a.kernels) {
        modes.push_back({"st", raster::Lookup::shadowtile, k});
        modes.push_back({"r32f", raster::Lookup::r32f, k});
      }
      std::map<uint64_t, size_t> mode_of;
      std::vector<std::vector<double>> ms(modes.size()), frame_ms(modes.size()), cpu_ms(modes.size());
      uint64_t holes = 0;
      auto take = [&](std::span<const raster::FrameResult> done) {
        for (const raster::FrameResult& fr : done) {
          const auto it = mode_of.find(fr.frame);
          if (it == mode_of.end()) continue;
          ms[it->second].push_back(fr.gpu_shade_ms);
          frame_ms[it->second].push_back(fr.gpu_frame_ms);
          holes += fr.stats.holes;
        }
      };
      // Warm: the uploads (every tile in frame 1), the shaders compiled, every mode once.
      for (size_t m = 0; m < modes.size(); ++m) {
        if (!r32f && modes[m].lookup == raster::Lookup::r32f) continue;
        in.lookup = modes[m].lookup, in.kernel = modes[m].kernel;
        r.render(in), r.render(in);
      }
      r.finish();
      for (uint32_t rep = 0; rep < a.reps; ++rep)
        for (size_t m = 0; m < modes.size(); ++m) {
          if (!r32f && modes[m].lookup == raster::Lookup::r32f) continue;
          in.lookup = modes[m].lookup, in.kernel = modes[m].kernel;
          mode_of[r.frames() + 1] = m;
          if (!a.cpu_time) {
            take(r.render(in));
            continue;
          }
          take(r.finish());  // this frame alone: the process's CPU time while it renders
          const double c0 = process_cpu_ms();
          take(r.render(in));
          take(r.finish());
          cpu_ms[m].push_back(process_cpu_ms() - c0);
        }
      take(r.finish());
      if (holes) throw Error("bench_raster: " + std::to_string(holes) + " holes in timed frames (the cache was full)");
      std::vector<double> med;
      for (auto& v : ms) med.push_back(v.empty() ? 0.0 : median(v));
      const double none = med[0];
      auto only = [&](double x, double y) { return (y - none) > 0 ? (x - none) / (y - none) : 0.0; };
      auto num = [&](double v) {
        char b[32];
        std::snprintf(b, sizeof b, "%.2f", v);
        return r32f ? std::string(b) : std::string("-");
      };
      std::string line, cpu_line;
      char cell[128];
      std::snprintf(cell, sizeof cell, "%-16s %8.3f", short_name(spec).c_str(), none);
      line = cell;
      nlohmann::json row = {{"scene", spec}, {"pack", path}, {"tiles", s.tiles}, {"triangles", tri.size() / 18},
                            {"none_ms", none}, {"kernels", a.kernels}, {"runs_ms", ms}, {"frame_runs_ms", frame_ms},
                            {"r32f", r32f}};
      for (size_t k = 0; k < a.kernels.size(); ++k) {
        const double st = med[1 + 2 * k], rf = med[2 + 2 * k];
        std::snprintf(cell, sizeof cell, " | %8.3f %8s %6s %6s", st, num(rf).c_str(), num(st / rf).c_str(),
                      num(only(st, rf)).c_str());
        line += cell;
        const std::string n = std::to_string(a.kernels[k]);
        row["st" + n + "_ms"] = st;
        if (r32f) row["r32f" + n + "_ms"] = rf, row["ratio" + n] = st / rf, row["lookup_ratio" + n] = only(st, rf);
        if (a.cpu_time && r32f) {
          const double cn = median(cpu_ms[0]), cs = median(cpu_ms[1 + 2 * k]), cr = median(cpu_ms[2 + 2 * k]);
          row["cpu_none_ms"] = cn, row["cpu_st" + n + "_ms"] = cs, row["cpu_r32f" + n + "_ms"] = cr;
          row["cpu_lookup_ratio" + n] = cr > cn ? (cs - cn) / (cr - cn) : 0.0;
          std::snprintf(cell, sizeof cell, " [cpu %.0f/%.0f/%.0f ms]", cn, cs, cr);
          cpu_line += cell;
        }
      }
      if (a.cpu_time) row["cpu_runs_ms"] = cpu_ms;
      if (!cpu_line.empty()) line += cpu_line;
      ratio_lines.push_back(line);
      if (a.region) row["region"] = {a.region->x, a.region->y, a.region->w, a.region->h};
      ratio_rows.push_back(row);
    }

    // ---- 2. the frame path with tiles arriving ----
    if (a.frame_path) {
      client::Map map = open_map(s, name, uint32_t(s.tiles + 8), cl);
      raster::RasterOptions ro;
      ro.width = a.width, ro.height = a.height, ro.device = a.device;
      ro.readback = false;
      ro.feedback_capacity = 1024;
      raster::Rasterizer r(map, tri, ro);
      raster::FrameInput in = camera_of(map, a.region);
      in.kernel = 1;  // the frame path's host work does not depend on it; lavapipe's frames do
      // Finest-level squares in scan order, each queued until --arriving tiles are on their way.
      const uint64_t side = uint64_t(1) << level, step = std::max<uint64_t>(1, side >> 5);
      uint64_t next_square = 0;
      std::map<uint64_t, uint64_t> arrived;  // frame -> tiles that arrived before it
      // One finest-level square at a time, each fetched whole, until --arriving tiles arrived.
      auto arrive = [&]() -> uint64_t {
        const uint64_t before = map.stats().tiles_received;
        const auto t_end = Clock::now() + std::chrono::seconds(60);
        while (map.stats().tiles_received - before < a.arriving && next_square < (side / step) * (side / step) &&
               Clock::now() < t_end) {
          const uint64_t x = (next_square % (side / step)) * step, y = (next_square / (side / step)) * step;
          ++next_square;
          map.request_region(level, x, y, step, step, 100);
          while (!map.region_resident(level, x, y, step, step) && Clock::now() < t_end)
            std::this_thread::sleep_for(std::chrono::microseconds(200));
        }
        return map.stats().tiles_received - before;
      };
      struct PathFrame {
        uint64_t frame, tiles;
        double host_us, retire_us, uploads_us;
        gpu::FrameStats st;
      };
      std::vector<PathFrame> got;
      auto take = [&](std::span<const raster::FrameResult> done) {
        for (const raster::FrameResult& fr : done)
          if (arrived.count(fr.frame)) got.push_back({fr.frame, arrived[fr.frame], fr.host_us, fr.retire_us, fr.uploads_us, fr.stats});
      };
      // Untimed: the page table's first upload, the shader's compile, and the tiles the view's
      // feedback asks for (until a frame has no holes), so later arrivals are ours alone.
      for (int warm = 0; warm < 40; ++warm) {
        r.render(in);
        const std::span<const raster::FrameResult> w = r.finish();
        if (warm >= 2 && !w.empty() && w.back().stats.holes == 0) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
      for (uint32_t f = 0; f < a.arrival_frames; ++f) {
        const uint64_t n = arrive();
        arrived[r.frames() + 1] = n;
        if (a.idle) r.wait_idle();
        take(r.render(in));
      }
      take(r.finish());
      std::vector<double> host, tiles, ratio;
      uint64_t tile_b = 0, page_b = 0, fb_b = 0, io_b = 0;
      for (const PathFrame& p : got) {
        if (p.st.slots_uploaded == 0) continue;  // frames with arrivals only (the map may run out)
        host.push_back(p.host_us);
        tiles.push_back(double(p.st.slots_uploaded));
        tile_b += p.st.tile_bytes, page_b += p.st.page_bytes, fb_b += p.st.feedback_bytes, io_b += p.st.host_io_bytes;
        const double payload = double(p.st.tile_bytes + p.st.page_bytes);
        ratio.push_back(payload > 0 ? double(p.st.tile_bytes + p.st.page_bytes + p.st.feedback_bytes + p.st.host_io_bytes) / payload
                                    : 0.0);
      }
      if (host.empty()) throw Error("bench_raster: no tile arrived in the frame path (the view fetched them all: a larger map)");
      const double n = std::max<double>(1, double(host.size()));
      const double overhead_pct = 100.0 * double(fb_b + io_b) / std::max<double>(1, double(tile_b + page_b));
      char line[512];
      std::snprintf(line, sizeof line, "%-16s %7.0f %9.1f %9.1f %12.0f %10.0f %10.0f %9.3f%%", short_name(spec).c_str(),
                    median(tiles), median(host), *std::max_element(host.begin(), host.end()), double(tile_b) / n,
                    double(page_b) / n, double(fb_b + io_b) / n, overhead_pct);
      path_lines.push_back(line);
      nlohmann::json frames = nlohmann::json::array();
      for (const PathFrame& p : got)
        frames.push_back({{"frame", p.frame}, {"tiles_arrived", p.tiles}, {"slots_uploaded", p.st.slots_uploaded},
                          {"host_us", p.host_us}, {"retire_us", p.retire_us}, {"record_uploads_us", p.uploads_us},
                          {"tile_bytes", p.st.tile_bytes}, {"page_bytes", p.st.page_bytes},
                          {"feedback_bytes", p.st.feedback_bytes}, {"host_io_bytes", p.st.host_io_bytes}});
      path_rows.push_back({{"scene", spec}, {"tiles_uploaded_median", median(tiles)}, {"host_us_median", median(host)},
                           {"host_us_max", *std::max_element(host.begin(), host.end())},
                           {"frames_with_arrivals", host.size()},
                           {"tile_bytes_per_frame", double(tile_b) / n}, {"page_bytes_per_frame", double(page_b) / n},
                           {"other_bytes_per_frame", double(fb_b + io_b) / n}, {"overhead_pct", overhead_pct},
                           {"frames", frames}});
    }
    s.srv->stop();
  }
  std::printf("device '%s', %ux%u, %s %s maps, medians of %u frames (device timestamps, the shading pass)\n",
              device.c_str(), a.width, a.height, side_name(level).c_str(), a.encoding.c_str(), a.reps);
  std::string head;
  char cell[128];
  std::snprintf(cell, sizeof cell, "%-16s %8s", "scene", "none ms");
  head = cell;
  for (const uint32_t k : a.kernels) {
    const std::string n = k == 1 ? "1" : std::to_string(k) + "x" + std::to_string(k);
    std::snprintf(cell, sizeof cell, " | %8s %8s %6s %6s", ("st " + n).c_str(), ("R32F " + n).c_str(), "ratio", "lookup");
    head += cell;
  }
  std::printf("%s\n", head.c_str());
  for (const auto& l : ratio_lines) std::printf("%s\n", l.c_str());
  if (a.frame_path) {
    std::printf("\nengine frame path (retire + record_uploads + record_end_of_frame, host), %u tiles arriving per frame\n",
                a.arriving);
    std::printf("(medians over the frames that uploaded tiles; bytes per such frame)\n");
    std::printf("%-16s %7s %9s %9s %12s %10s %10s %10s\n", "scene", "tiles", "host us", "max us", "tile B/frame",
                "page B", "other B", "overhead");
    for (const auto& l : path_lines) std::printf("%s\n", l.c_str());
  }
  report["device"] = device;
  report["ratio"] = ratio_rows;
  report["frame_path"] = path_rows;
  std::ofstream(a.json) << report.dump(2) << "\n";
  std::printf("wrote %s\n", a.json.c_str());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_raster: %s\n", e.what());
  return 1;
}

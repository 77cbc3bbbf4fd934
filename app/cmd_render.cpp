// `shadowtile render (PACK | --server HOST:PORT --map NAME) --scene SCENE --camera ...
//  [--size WxH] [--pcf SIDE] [--filter] [--diff] [--time T | --soft] -o view.exr`: the scene from a
// camera, Lambert-shaded with the map's shadows (render/render.hpp), as RGB float EXR and
// PNG; --diff also ray-traces the shadows and writes where the two differ. A stack pack (a
// light set) is drawn at --time T (the two nearest slices blended) or --soft (the average
// over every sample), and --diff traces the same samples with the same weights.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <thread>

#include "scene/scene_limits.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"
#include "app/connect_options.hpp"
#include "app/scene_limits_option.hpp"
#include "app/command.hpp"
#include "app/pcf_option.hpp"
#include "app/public_map.hpp"
#include "common/error.hpp"
#include "tiles/core/deep_pack.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/stack_map.hpp"

namespace st::cli {

client::Endpoint parse_endpoint(const std::string& option, const std::string& text);  // cmd_load.cpp

namespace {
// A tile given up (undecodable, refused, unanswered) answers from a coarser level: an
// image made so is not the map's. One line, and a failure exit.
void check_no_failed_tiles(const client::Map& map) {
  const client::MapStats s = map.stats();
  if (s.tiles_failed == 0) return;
  throw Error("render: " + std::to_string(s.tiles_failed) + " tile(s) could not be had from the server (" +
              std::to_string(s.decode_errors) + " decode errors, " + std::to_string(s.crc_errors) + " CRC errors, " +
              std::to_string(s.tiles_unanswered) + " never answered, " + std::to_string(s.tiles_received) +
              " received): the image would show coarser levels there");
}

// The timeout's line: says when the cache cannot hold the view (slots all used, evicting).
Error view_timeout(const client::Map& map, const std::string& what, std::chrono::milliseconds timeout) {
  const client::MapStats s = map.stats();
  const uint64_t slots = uint64_t(s.cache.resident) + s.cache.pinned + s.cache.free;
  std::string why;
  if (s.cache.free == 0 && s.cache.evictions > 0)
    why = ": the cache's " + std::to_string(slots) + " slots of " + std::to_string(map.slot_bytes()) +
          " bytes (--cache-mb) are full and evicting; the view needs more: raise --cache-mb";
  return Error("render: " + what + " did not all arrive within " + std::to_string(timeout.count()) + " ms (" +
               std::to_string(s.tiles_received) + " tiles received)" + why);
}
}  // namespace

// Requests every tile the receivers' lookups need and waits (bounded) until they are
// resident (the public API: app/public_map.hpp): the finest level's, or with pixel_angle
// (--filter) each receiver's two filter levels' (filter_levels of its footprint, at the
// filtered lookup point). Returns the number of cells; throws st::Error on timeout.
size_t fetch_for_receivers(client::Map& map, const std::vector<Receiver>& rec, const LightSpace& light,
                           double pixel_angle, std::chrono::milliseconds timeout) {
  const uint32_t L = map.finest_level();
  std::vector<std::vector<std::pair<double, double>>> uv(L + 1);  // per level
  for (const Receiver& r : rec) {
    if (!r.hit || r.n_dot_l <= 0) continue;
    if (!(pixel_angle > 0)) {
      const LightPoint p = lookup_point(r, light, L);
      uv[L].emplace_back(p.u, p.v);
      continue;
    }
    LightPoint p;
    ReceiverPlane plane;
    if (!receiver_plane_at(light, L, r.pos, r.normal, r.closed, p, plane)) continue;
    const FilterLevels f = filter_levels(L, receiver_footprint_texels(r, light, L, pixel_angle));
    uv[f.fine].emplace_back(p.u, p.v);
    if (f.t != 0.0f) uv[f.coarse].emplace_back(p.u, p.v);
  }
  size_t n = 0;
  for (uint32_t level = 0; level <= L; ++level) {
    if (uv[level].empty()) continue;
    const std::vector<TexelCell> cells = cells_under(uv[level], level, map.info().skip_level);
    if (!fetch_cells(map, level, cells, timeout, [&] { check_no_failed_tiles(map); }))
      throw view_timeout(map, "the view's tiles", timeout);
    n += cells.size();
  }
  return n;
}

// The deep part of a served map (partial occluders): waits (bounded) for its directory
// and every deep tile under the receivers' deep lookup points (Map::deep_resident);
// returns the count of cells asked (points grouped by 1/1024 of the map: no deep tile is
// smaller).
size_t fetch_deep_for_receivers(const client::Map& map, const std::vector<Receiver>& rec, const LightSpace& light,
                                std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  auto wait_or_throw = [&] {
    if (std::chrono::steady_clock::now() > deadline)
      throw Error("render: the view's deep tiles did not all arrive within " + std::to_string(timeout.count()) + " ms");
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  };
  while (map.deep_level() == 0) wait_or_throw();  // the directory is on its way
  constexpr double kCells = 1024;  // 2^kMaxTilesPerSideBits: a deep tile spans whole cells
  std::vector<uint64_t> cells;
  for (const Receiver& r : rec) {
    if (!r.hit || r.n_dot_l <= 0) continue;
    const LightPoint p = deep_lookup_point(r, light, map.finest_level(), map.deep_level());
    if (!(p.u >= 0 && p.u < 1 && p.v >= 0 && p.v < 1)) continue;
    cells.push_back((uint64_t(p.v * kCells) << 32) | uint64_t(p.u * kCells));
  }
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  for (;;) {
    bool all = true;
    for (uint64_t c : cells) {
      const double u = (double(c & 0xFFFFFFFFu) + 0.5) / kCells, v = (double(c >> 32) + 0.5) / kCells;
      all = map.deep_resident(u, v, u, v) && all;
    }
    if (all) return cells.size();
    wait_or_throw();
  }
}

namespace {

struct RenderArgs {
  std::string pack, server, map, scene, camera, size = "960x540", out, up;
  std::string scene_limits;  // --scene-limits (scene/scene_limits.hpp)
  ConnectArgs connect;
  uint32_t pcf = 1;  // kernel side
  bool diff = false;
  bool filter = false;
  double timeout = 60;
  double cache_mb = 256;
  std::optional<double> time;
  bool soft = false;
};

std::string stem(const std::string& out) {
  const auto dot = out.rfind('.');
  const auto slash = out.rfind('/');
  return dot != std::string::npos && (slash == std::string::npos || dot > slash) ? out.substr(0, dot) : out;
}

void write_outputs(const RenderArgs& a, const RenderResult& r) {
  const std::string base = stem(a.out);
  write_rgb_exr(a.out, r.width, r.height, r.image);
  write_rgb_preview_png(base + ".png", r.width, r.height, r.image);
  std::printf("rendered %ux%u (%llu lit-facing receivers), map shadows %.1f ms: %s, %s.png\n", r.width, r.height,
              (unsigned long long)r.receivers, r.map_seconds * 1e3, a.out.c_str(), base.c_str());
  if (a.diff) {
    write_rgb_exr(base + "_traced.exr", r.width, r.height, r.traced_image);
    write_rgb_preview_png(base + "_traced.png", r.width, r.height, r.traced_image);
    write_rgb_preview_png(base + "_diff.png", r.width, r.height, r.diff_image);
    std::printf("ray-traced shadows %.1f ms: %s_traced.{exr,png}; differences: %s_diff.png\n",
                r.traced_seconds * 1e3, base.c_str(), base.c_str());
    std::printf("differing pixels: %llu of %llu receivers (%.4f%%)\n", (unsigned long long)r.differing,
                (unsigned long long)r.receivers, 100 * r.differing_fraction());
    std::printf("mean |map - traced| light over the receivers: %.4f\n", r.mean_abs_difference);
  }
}

// A stack pack (local or served): the view at --time T or --soft (render_stack_view).
void run_stack(const RenderArgs& a, const RenderOptions& ro, const Camera& cam, const Scene& scene,
               const PackReader* reader, client::Map* map) {
  if (a.soft && a.time) throw Error("render: give --time T or --soft, not both");
  std::vector<LightSpace> samples;  // the light set's samples: the pack's, or the served map's (MapInfo)
  if (reader)
    for (uint32_t w = 0; w < reader->stack()->slices; ++w) samples.push_back(reader->stack()->light(w));
  else
    for (const client::LightTransform& t : map->info().slice_lights) samples.push_back(light_of(t));
  const uint32_t map_level = reader ? reader->stack()->geo.n : map->finest_level();
  const double time = a.time.value_or(0.0);
  // The slices read, and the sample that shades (n.l) and sizes the normal offset.
  const uint32_t n = uint32_t(samples.size());
  const double s = std::clamp(time, 0.0, 1.0) * double(n - 1);
  const uint32_t w0 = a.soft ? 0 : uint32_t(std::floor(s)), w1 = a.soft ? n - 1 : std::min(n - 1, uint32_t(std::ceil(s)));
  const LightSpace& shading = samples[a.soft ? n / 2 : uint32_t(std::nearbyint(s))];
  const SceneTracer tracer(scene, shading);
  const auto rec = tracer.primary(cam, ro.width, ro.height);
  StackRenderOptions o;
  o.width = ro.width, o.height = ro.height, o.pcf_radius = ro.pcf_radius, o.pixel_angle = ro.pixel_angle;
  o.diff = ro.diff, o.soft = a.soft, o.time = time;
  std::unique_ptr<ResidentStack> rs;
  StackMapLookups vis;
  if (reader) {
    rs = std::make_unique<ResidentStack>(*reader);
    const StackMap& m = rs->map();
    if (a.soft) vis.all = [&m, &o](const Vec3d& p, float fp) { return m.soft_visibility_filtered(p, o.pcf_radius, fp); };
    else vis.all = [&m, &o](const Vec3d& p, float fp) { return m.visibility_filtered(p, o.time, o.pcf_radius, fp); };
    vis.sample = [&m, &o](const Vec3d& p, uint32_t w, float fp) { return m.filtered(p, w, o.pcf_radius, fp); };
  } else {
    const auto t0 = std::chrono::steady_clock::now();
    const auto deadline = t0 + std::chrono::milliseconds(int64_t(a.timeout * 1000));
    map->request_slices(w0, w1, 1000);
    while (!map->slices_resident(w0, w1)) {
      if (std::chrono::steady_clock::now() > deadline)
        throw view_timeout(*map, "slices " + std::to_string(w0) + ".." + std::to_string(w1),
                           std::chrono::milliseconds(int64_t(a.timeout * 1000)));
      map->request_slices(w0, w1, 1000);
      check_no_failed_tiles(*map);  // a given-up cell never becomes resident: say so now
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    check_no_failed_tiles(*map);
    std::printf("fetched slices %u..%u in %.0f ms\n", w0, w1,
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    const client::Map& m = *map;
    if (a.soft)
      vis.all = [&m, &o](const Vec3d& p, float fp) {
        return m.soft_visibility_filtered({p.x, p.y, p.z}, fp, 2 * o.pcf_radius + 1);
      };
    else
      vis.all = [&m, &o](const Vec3d& p, float fp) {
        return m.time_visibility_filtered({p.x, p.y, p.z}, o.time, fp, 2 * o.pcf_radius + 1);
      };
    // One sample: the time lookup at the sample's own time is exactly that slice.
    vis.sample = [&m, &o, n](const Vec3d& p, uint32_t w, float fp) {
      return m.time_visibility_filtered({p.x, p.y, p.z}, n > 1 ? double(w) / double(n - 1) : 0.0, fp,
                                        2 * o.pcf_radius + 1);
    };
  }
  std::printf("stack of %u slices: %s\n", n,
              a.soft ? "soft shadows, every sample averaged"
                     : (w0 == w1 ? "time " + std::to_string(time) + ", slice " + std::to_string(w0)
                                 : "time " + std::to_string(time) + ", slices " + std::to_string(w0) + " and " +
                                       std::to_string(w1) + " blended")
                           .c_str());
  const RenderResult r = render_stack_view(tracer, rec, samples, map_level, vis, o);
  write_outputs(a, r);
}

void run_render(const RenderArgs& a) {
  if (a.pack.empty() == (a.server.empty() || a.map.empty()))
    throw Error("render: give either a PACK or --server HOST:PORT with --map NAME");
  if (a.time && !(*a.time >= 0 && *a.time <= 1)) throw Error("--time: expected a time in [0, 1]");
  RenderOptions o;
  if (std::sscanf(a.size.c_str(), "%ux%u", &o.width, &o.height) != 2 || o.width == 0 || o.height == 0 ||
      o.width > 16384 || o.height > 16384)
    throw Error("--size: expected WxH (1..16384), got '" + a.size + "'");
  o.pcf_radius = (checked_pcf_side("--pcf", a.pcf) - 1) / 2;  // the renderer's kernels: side 2R+1
  o.diff = a.diff;
  const Camera cam = parse_camera(a.camera);
  // Hierarchical filtering: one pixel's angle from the vertical field of view.
  if (a.filter) o.pixel_angle = 2 * std::tan(cam.fov_deg * 3.14159265358979323846 / 360) / o.height;
  SceneOptions so;
  so.up = parse_up_axis(a.up);
  const Scene scene = load_scene(a.scene, so, parse_scene_limits(a.scene_limits));

  std::shared_ptr<const PackReader> reader;
  std::unique_ptr<PackEvaluator> pack_eval;
  std::unique_ptr<PackDeepMap> pack_deep;
  std::unique_ptr<client::Client> cl;
  client::Map map;
  std::unique_ptr<MapEvaluator> map_eval;
  const Evaluator* eval = nullptr;
  LightSpace light;
  uint64_t scene_hash = 0;
  if (!a.pack.empty()) {
    reader = PackReader::open(a.pack);
    if (reader->stack()) {
      if (reader->header().scene_hash != scene.content_hash())
        std::fprintf(stderr, "shadowtile render: warning: scene '%s' is not the scene the map was built from\n",
                     a.scene.c_str());
      return run_stack(a, o, cam, scene, reader.get(), nullptr);
    }
    pack_eval = std::make_unique<PackEvaluator>(reader, 4096);
    eval = pack_eval.get();
    pack_deep = PackDeepMap::load(*reader);
    if (pack_deep) {
      const DeepMap& dm = pack_deep->map();
      o.deep.level = dm.level();
      o.deep.transmittance = [&dm](double u, double v, float d, double width) {
        return width > 0 ? dm.filtered(u, v, d, width) : dm.transmittance(u, v, d);
      };
    }
    light = reader->light();
    scene_hash = reader->header().scene_hash;
  } else {
    client::ClientOptions co;
    co.client_name = "shadowtile-render";
    apply_connect_options(a.connect, co);
    // The same rule as load and view: the budget holds the map's metadata and everything
    // per slot, whatever the pack's tile bound (client.hpp cache_bytes).
    co.cache_bytes = uint64_t(a.cache_mb * 1048576.0);
    cl = std::make_unique<client::Client>(parse_endpoint("--server", a.server), co);
    map = cl->open(a.map);
    const client::MapInfo info = map.info();
    if (map.slices()) {
      if (info.scene_hash != scene.content_hash())
        std::fprintf(stderr, "shadowtile render: warning: scene '%s' is not the scene the map was built from\n",
                     a.scene.c_str());
      return run_stack(a, o, cam, scene, nullptr, &map);
    }
    map_eval = std::make_unique<MapEvaluator>(map);
    eval = map_eval.get();
    light = light_of(info.light);
    scene_hash = info.scene_hash;
  }
  if (a.time || a.soft) throw Error("render: --time and --soft need a stack pack (built with a light set)");
  // A pack with a deep part records the hash of the scene's opaque part (its opaque map's).
  if (scene_hash != scene.content_hash() && !(scene.any_partial() && scene_hash == opaque_part(scene).content_hash()))
    std::fprintf(stderr, "shadowtile render: warning: scene '%s' is not the scene the map was built from\n",
                 a.scene.c_str());
  const SceneTracer tracer(scene, light);
  const auto rec = tracer.primary(cam, o.width, o.height);
  if (map.valid()) {
    const auto t0 = std::chrono::steady_clock::now();
    const size_t cells =
        fetch_for_receivers(map, rec, light, o.pixel_angle, std::chrono::milliseconds(int64_t(a.timeout * 1000)));
    // The filtered path (--filter, or a light other than a sun) through the public filtered
    // lookup with normals: the receiver plane counted inside the client's window walks.
    o.filtered = filtered_lookups(map, 2 * o.pcf_radius + 1);
    std::printf("fetched the view's %zu cell(s) in %.0f ms\n", cells,
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (map.has_deep()) {
      const auto t1 = std::chrono::steady_clock::now();
      const size_t n = fetch_deep_for_receivers(map, rec, light, std::chrono::milliseconds(int64_t(a.timeout * 1000)));
      std::printf("fetched the view's deep tiles (%zu cell(s) of the light's image) in %.0f ms\n", n,
                  std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count());
      o.deep.level = map.deep_level();
      o.deep.transmittance = [&map](double u, double v, float d, double width) {
        const client::Transmittance t = map.transmittance_at({u, v, double(d)}, width);
        return std::array<float, 3>{t.r, t.g, t.b};
      };
    }
  }
  if (o.deep) std::printf("partial occluders: the deep map's transmittance (level %u) times the opaque map's visibility\n", o.deep.level);
  const RenderResult r = render_view(tracer, rec, *eval, o);
  write_outputs(a, r);
}

Register reg_render{"render", "Render a camera view shaded with the map's shadows (EXR + PNG)", [](CLI::App& sub) {
  auto a = std::make_shared<RenderArgs>();
  sub.add_option("pack", a->pack, "Pack file (or use --server and --map)");
  sub.add_option("--server", a->server, "Server HOST:PORT");
  add_connect_options(sub, a->connect, "With --server: ");
  sub.add_option("--map", a->map, "Map name on the server");
  sub.add_option("--scene", a->scene, "Scene the map was built from (primary rays)")->required();
  add_scene_file_options(sub, a->up, a->scene_limits);
  sub.add_option("--camera", a->camera, "pos=X,Y,Z,target=X,Y,Z[,fov=DEG]")->required();
  sub.add_option("--size", a->size, "Image size WxH")->capture_default_str();
  sub.add_option("--pcf", a->pcf, "PCF kernel side: odd, 1..9 (1: single tap, 3: 3x3, ...)")->capture_default_str();
  sub.add_flag("--filter", a->filter,
               "Hierarchical filtering: the level from each pixel's footprint, two levels blended (MH 2016 3.3)");
  sub.add_flag("--diff", a->diff, "Also ray-trace shadows and write where they differ");
  sub.add_option("--time", a->time,
                 "Stack packs: the light set's time in [0, 1] (sample w at w / (N - 1); the two nearest blended)");
  sub.add_flag("--soft", a->soft, "Stack packs: soft shadows, the fraction of the light set's samples that are lit");
  sub.add_option("--timeout", a->timeout, "Seconds to wait for the view's tiles (--server)")->capture_default_str();
  sub.add_option("--cache-mb", a->cache_mb, "Tile cache (MiB, --server)")->capture_default_str();
  sub.add_option("-o,--out", a->out, "Output EXR (the PNG preview goes beside it)")->required();
  sub.callback([a] { run_render(*a); });
}};

}  // namespace
}  // namespace st::cli

// GPU lookup speed: per encoding, single taps, 3x3 and 5x5 PCF per second and the shadow
// pass over a width x height G-buffer, timed with device timestamps, each next to the same
// work on the map's finest level as an uncompressed R32F image on the same device (where
// it fits one storage buffer), and the upload throughput of arriving tiles (a cold mirror
// synced from a full cache).
//
//   bench_gpu [--scene procedural:city] [--light sun:azimuth=30,elevation=50] [--res 2k]
//             [--encodings mh,mmh,dagmh] [--lookups 262144] [--reps 5] [--width 1920]
//             [--height 1080] [--device NAME] [--out bench-out/gpu] [--json PATH]
//             [--tile-bytes 65536] [--max-r32f-bytes 2147483648]
//             [--camera pos=X,Y,Z,target=X,Y,Z,fov=D [--view-size 480x270] [--view-pcf 5]
//              [--view-out DIR]]
//
// With --camera, the first encoding's map also shades a camera view (Embree primary rays
// -> G-buffer of positions and normals, light-facing receivers only, moved 1.5 finest texels
// along the normal) through the GPU shadow pass with --view-pcf and the neighbour
// footprint, with the receiver plane and without, next to the CPU's filtered render
// (render_view, --filter's rule) and the ray-traced shadows: DIR/{gpu_plane,gpu_flat,
// cpu_filtered,traced}.png, the passes timed alternated, and each picture's receivers
// whose lit test (>= 0.5) differs from the rays counted.
//
// The map is built once per encoding into --out (reused when present), served by an
// in-process server on 127.0.0.1, fetched whole into a client cache and mirrored by a
// GpuMap. Queries are random finest texels; half the receivers sit on the stored depth
// (lit), half just behind it (shadowed), so the GPU answers are checked against the R32F
// image's (they must agree: the map is lossless). The G-buffer is a plane across the light
// box whose receivers sit on the map's surface. Figures are medians over --reps. Each
// shadow pass row also reports its frame's host <-> device bytes by kind (FrameStats: tile,
// page-table, feedback, and the G-buffer in and visibility out that only the own-device
// mode moves). The pass is timed with one receiver depth ("pass ms", the R32F pass's rule)
// and with the receiver plane ("plane ms": ShadowPassInput::receiver_plane, each tap
// against the plane of the pixel's normal, here the map surface's own), alternated rep by
// rep; "moved": the pixels whose answer the plane changed.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "bench/options.hpp"
#include "bench/bench_map.hpp"
#include "client/map_access.hpp"
#include "gpu/gpu_map.hpp"
#include "bench/baselines/r32f_image.hpp"
#include "gpu/shadow_reference.hpp"
#include "server/catalog.hpp"
#include "server/server.hpp"
#include "render/render.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/core/camera.hpp"
#include "tiles/core/receiver_plane.hpp"

namespace {

using namespace st;
using namespace st::bench;

struct Args {
  std::string scene = "procedural:city", light = "sun:azimuth=30,elevation=50", res = "2k";
  std::string encodings = "mh,mmh,dagmh", device, out = "bench-out/gpu", json = "bench-out/gpu.json";
  uint32_t lookups = 1u << 18, reps = 5, width = 1920, height = 1080, tile_bytes = 64 * 1024;
  uint64_t max_r32f_bytes = 2ull << 30;
  std::string camera, view_size = "480x270", view_out;  // --camera: the view pictures (first encoding)
  uint32_t view_kernel = 5;
};

Args parse(int argc, char** argv) {
  Args a;
  Options opt("bench_gpu", "GPU lookups through the tile cache beside an uncompressed R32F image on the same device");
  opt.value("--scene", a.scene, "Scene spec")
      .value("--light", a.light, "Light spec")
      .value("--res", a.res, "Map side")
      .value("--encodings", a.encodings, "mh, mmh, dagmh (comma-separated)")
      .value("--lookups", a.lookups, "Lookups per pass")
      .value("--reps", a.reps, "Median of R passes")
      .value("--width", a.width, "Screen width")
      .value("--height", a.height, "Screen height")
      .value("--tile-bytes", a.tile_bytes, "Tile budget in bytes")
      .value("--device", a.device, "Vulkan device (by name)")
      .value("--max-r32f-bytes", a.max_r32f_bytes, "Largest R32F image the baseline allocates")
      .value("--out", a.out, "Prefix of the pictures written")
      .value("--json", a.json, "Write the rows as JSON to PATH")
      .value("--camera", a.camera, "Camera spec of the view pictures (first encoding)")
      .value("--view-size", a.view_size, "The view pictures' WxH (1..8192)")
      .value("--view-out", a.view_out, "Where the view pictures go")
      .value("--view-pcf", a.view_kernel, "The view pictures' PCF side");
  opt.parse(argc, argv);
  if (a.lookups == 0 || a.reps == 0 || a.width == 0 || a.height == 0) throw Error("bench_gpu: counts must be > 0");
  return a;
}

template <class F>
double median_ms(uint32_t reps, F&& f) {
  std::vector<double> v;
  for (uint32_t i = 0; i < reps; ++i) v.push_back(f());
  return median(v);
}

uint32_t view_pixels(const Args& a) {
  uint32_t w = 0, h = 0;
  if (std::sscanf(a.view_size.c_str(), "%ux%u", &w, &h) != 2 || w == 0 || h == 0 || w > 8192 || h > 8192)
    throw Error("bench_gpu: --view-size: expected WxH (1..8192), got '" + a.view_size + "'");
  return w * h;
}

// The shading of render_view (render.cpp shade_image): sky, ambient + Lambert x visibility.
std::vector<float> shade(const std::vector<Receiver>& rec, const std::vector<float>& vis, double ambient) {
  std::vector<float> img(rec.size() * 3);
  for (size_t i = 0; i < rec.size(); ++i) {
    float* px = &img[3 * i];
    if (!rec[i].hit) {
      px[0] = 0.55f, px[1] = 0.7f, px[2] = 0.9f;
      continue;
    }
    const double lambert = (1 - ambient) * std::max(0.0, rec[i].n_dot_l) * vis[i];
    const float albedo[3] = {rec[i].closed ? 0.8f : 0.6f, rec[i].closed ? 0.78f : 0.7f, rec[i].closed ? 0.72f : 0.55f};
    for (int k = 0; k < 3; ++k) px[k] = float(albedo[k] * (ambient + lambert));
  }
  return img;
}

// --camera: the GPU pass over a camera view's G-buffer, with and without the receiver
// plane, beside the CPU's filtered render and the rays (file comment).
nlohmann::json view_pictures(const Args& a, const Scene& scene, const LightSpace& light, const client::Map& map,
                             gpu::GpuMap& g) {
  RenderOptions o;
  view_pixels(a);
  std::sscanf(a.view_size.c_str(), "%ux%u", &o.width, &o.height);
  Camera cam = parse_camera(a.camera);
  cam.aspect = double(o.width) / o.height;
  o.pcf_radius = (a.view_kernel - 1) / 2;
  o.pixel_angle = 2 * std::tan(cam.fov_deg * 3.14159265358979323846 / 360) / o.height;
  o.diff = true;
  const SceneTracer tracer(scene, light);
  const std::vector<Receiver> rec = tracer.primary(cam, o.width, o.height);
  const Evaluator& cpu = client::evaluator(map);
  const RenderResult r = render_view(tracer, rec, cpu, o);
  const uint32_t level = map.finest_level();
  const double texel = light.texel_size(light.origin(), level);
  const size_t pixels = rec.size();
  std::vector<float> pos(pixels * 4, 0.0f), nrm(pixels * 4, 0.0f);
  for (size_t i = 0; i < pixels; ++i) {
    if (!rec[i].hit || rec[i].n_dot_l <= 0) continue;  // faces away: unlit whatever the map says
    pos[4 * i] = float(rec[i].pos.x), pos[4 * i + 1] = float(rec[i].pos.y), pos[4 * i + 2] = float(rec[i].pos.z);
    pos[4 * i + 3] = 1;
    nrm[4 * i] = float(rec[i].normal.x), nrm[4 * i + 1] = float(rec[i].normal.y), nrm[4 * i + 2] = float(rec[i].normal.z);
  }
  gpu::ShadowPassInput in;
  in.positions = pos;
  in.normals = nrm;
  in.width = o.width;
  in.height = o.height;
  in.kernel = a.view_kernel;
  in.normal_offset = float(kOpenReceiverOffsetTexels * texel);
  in.neighbour_footprint = true;
  in.receiver_plane = false;
  gpu::ShadowPassInput in_plane = in;
  in_plane.receiver_plane = true;
  std::vector<float> flat(pixels), plane(pixels);
  std::vector<double> flat_ms, plane_ms;
  for (uint32_t rep = 0; rep < a.reps; ++rep) {
    flat_ms.push_back(g.wait(g.submit_shadow_pass(in), flat).gpu_ms);
    plane_ms.push_back(g.wait(g.submit_shadow_pass(in_plane), plane).gpu_ms);
  }
  // Receivers whose lit test (>= 0.5) differs from the rays', over the light-facing ones.
  std::vector<float> rays(pixels, 0.0f);
  for (size_t i = 0; i < pixels; ++i)
    if (rec[i].hit && rec[i].n_dot_l > 0) rays[i] = tracer.traced(rec[i]);
  auto differing = [&](const std::vector<float>& v) {
    uint64_t n = 0;
    for (size_t i = 0; i < pixels; ++i)
      if (rec[i].hit && rec[i].n_dot_l > 0) n += (v[i] >= 0.5f) != (rays[i] >= 0.5f);
    return n;
  };
  std::vector<float> cpu_vis(pixels, 0.0f);
  for (size_t i = 0; i < pixels; ++i) cpu_vis[i] = rec[i].hit && rec[i].n_dot_l > 0 ? r.visibility[i] : 0.0f;
  const std::string dir = a.view_out.empty() ? a.out + "/view" : a.view_out;
  std::filesystem::create_directories(dir);
  write_rgb_preview_png(dir + "/gpu_plane.png", o.width, o.height, shade(rec, plane, o.ambient));
  write_rgb_preview_png(dir + "/gpu_flat.png", o.width, o.height, shade(rec, flat, o.ambient));
  write_rgb_preview_png(dir + "/cpu_filtered.png", o.width, o.height, r.image);
  write_rgb_preview_png(dir + "/traced.png", o.width, o.height, r.traced_image);
  const double fms = median(flat_ms), pms = median(plane_ms);
  std::printf("view %ux%u PCF %u (%llu light-facing receivers): pass ms one depth %.3f, receiver plane %.3f (%.2fx); "
              "differ from the rays: GPU one depth %llu, GPU plane %llu, CPU filtered %llu; pictures in %s\n",
              o.width, o.height, a.view_kernel, (unsigned long long)r.receivers, fms, pms, fms > 0 ? pms / fms : 0,
              (unsigned long long)differing(flat), (unsigned long long)differing(plane),
              (unsigned long long)differing(cpu_vis), dir.c_str());
  return {{"width", o.width}, {"height", o.height}, {"kernel", a.view_kernel}, {"receivers", r.receivers},
          {"flat_pass_ms", fms}, {"plane_pass_ms", pms}, {"differ_flat", differing(flat)},
          {"differ_plane", differing(plane)}, {"differ_cpu_filtered", differing(cpu_vis)}};
}

}  // namespace

int main(int argc, char** argv) try {
  const Args a = parse(argc, argv);
  const uint32_t level = parse_level(a.res);
  std::filesystem::create_directories(a.out);
  const Scene scene = load_scene(a.scene);
  const LightSpace light = LightSpace::fit(LightSpec::parse(a.light), scene.bounds());
  nlohmann::json report = {{"scene", a.scene}, {"light", a.light}, {"resolution", side_name(level)},
                           {"lookups", a.lookups}, {"width", a.width}, {"height", a.height}};
  nlohmann::json rows = nlohmann::json::array();
  std::printf("%-6s %-5s %12s %12s %8s | %10s %10s %7s | %9s %8s %6s | %9s %6s %8s\n", "enc", "op", "GPU Mlook/s",
              "R32F Mlook/s", "ratio", "pass ms", "R32F ms", "ratio", "upload", "MB/s", "agree", "plane ms", "/flat",
              "moved");
  for (const std::string& name : split_list(a.encodings)) {
    const Encoding enc = parse_encoding(name);
    const std::string path = a.out + "/" + side_name(level) + "_" + name + ".pack";
    if (!std::filesystem::exists(path)) {
      MapBuildOptions o;
      o.map_level = level;
      o.encoding = enc;
      o.tile_bytes = a.tile_bytes;
      o.scene_spec = a.scene;
      o.light_spec = a.light;
      std::fprintf(stderr, "bench_gpu: building %s\n", path.c_str());
      build_map(scene, light, o, path);
    }
    server::ServerOptions so;
    so.host = "127.0.0.1";
    so.port = 0;
    so.log = [](const std::string&) {};
    const std::vector<std::string> paths{path};
    server::Server srv(server::Catalog::scan(paths), so);
    srv.start();
    client::ClientOptions co;
    co.max_slot_bytes = 64u << 20;
    co.request_timeout = std::chrono::milliseconds(60000);
    uint64_t tiles = 0;
    {
      client::Client probe({"127.0.0.1", srv.port()}, co);
      tiles = probe.open(std::filesystem::path(path).stem().string()).info().tile_count;
    }
    co.cache_slots = uint32_t(tiles + 8);
    co.want_capacity = uint32_t(tiles + 8);
    client::Client cl({"127.0.0.1", srv.port()}, co);
    client::Map map = cl.open(std::filesystem::path(path).stem().string());
    const uint64_t side = uint64_t(1) << level;
    map.request_region(level, 0, 0, side, side, 10);
    const auto t_end = Clock::now() + std::chrono::minutes(10);
    while (!map.region_resident(level, 0, 0, side, side) && Clock::now() < t_end)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (!map.region_resident(level, 0, 0, side, side)) throw Error("bench_gpu: the map did not arrive within 10 minutes");
    const Evaluator& cpu = client::evaluator(map);

    gpu::GpuOptions go;
    go.device = a.device;
    go.max_queries = a.lookups;
    go.max_pixels = std::max(a.width * a.height, a.camera.empty() ? 0u : view_pixels(a));
    go.upload_budget_bytes = 256u << 20;
    gpu::GpuMap g(map, go);
    const auto t0 = Clock::now();
    g.sync();
    const double upload_s = seconds_since(t0);
    const gpu::GpuStats gs = g.stats();
    const double upload_mbs = double(gs.bytes_uploaded) / 1e6 / std::max(upload_s, 1e-9);

    std::mt19937_64 rng(1);
    std::vector<gpu::GpuQuery> q(a.lookups);
    for (auto& x : q) {
      x.x = uint32_t(rng() % side), x.y = uint32_t(rng() % side), x.level = level;
      const float d = cpu.depth(level, x.x, x.y);
      x.receiver = rng() % 2 ? d : std::nextafter(d, 2.0f);
    }
    std::unique_ptr<gpu::R32fImage> img;
    std::string no_image;
    try {
      // One storage buffer holds at most 4 GiB - 1 on any device (128 MiB on lavapipe):
      // beyond --max-r32f-bytes the image is not painted at all.
      if (side * side * 4 > a.max_r32f_bytes) throw Error("R32F image of " + std::to_string(side * side * 4) + " bytes does not fit one buffer");
      std::vector<float> values(size_t(side) * side);
      std::vector<std::thread> painters;
      const unsigned n = std::max(1u, std::thread::hardware_concurrency());
      for (unsigned t = 0; t < n; ++t)
        painters.emplace_back([&, t] {
          for (uint64_t y = t; y < side; y += n)
            for (uint64_t x = 0; x < side; ++x) values[y * side + x] = cpu.depth(level, x, y);
        });
      for (auto& t : painters) t.join();
      img = std::make_unique<gpu::R32fImage>(g.device_name(), level, values, std::max(a.lookups, a.width * a.height));
    } catch (const std::exception& e) {
      no_image = e.what();
    }
    std::vector<float> got(q.size()), want(q.size());
    // The G-buffer: a plane across the light box, receivers on the map's surface, each
    // with the normal of that surface (the map's depths at the pixel's neighbours, toward
    // the light; where the map holds no surface, facing the light): the receiver plane's
    // slopes are the scene's own.
    const uint64_t pixels = uint64_t(a.width) * a.height;
    std::vector<float> pos(pixels * 4), nrm(pixels * 4);
    auto surface = [&](double u, double v) {
      const auto t = LightSpace::texel_of(level, u, v);
      const double d = cpu.depth(level, t[0], t[1]) * 0.999;
      const double e = light.extent_uv(), z = light.near_plane() + d * (light.far_plane() - light.near_plane());
      return light.origin() + light.axis_u() * (u * e) + light.axis_v() * (v * e) + light.forward() * z;
    };
    for (uint32_t y = 0; y < a.height; ++y)
      for (uint32_t x = 0; x < a.width; ++x) {
        const size_t p = size_t(y) * a.width + x;
        const double u = (x + 0.5) / a.width, v = (y + 0.5) / a.height;
        const Vec3d w = surface(u, v);
        pos[4 * p] = float(w.x), pos[4 * p + 1] = float(w.y), pos[4 * p + 2] = float(w.z), pos[4 * p + 3] = 1;
        const Vec3d du = surface(u + 1.0 / a.width, v) - w, dv = surface(u, v + 1.0 / a.height) - w;
        Vec3d n = cross(du, dv);
        if (dot(n, light.forward()) > 0) n = n * -1.0;
        const double len = length(n);
        n = len > 0 && std::isfinite(len) && std::fabs(dot(n, light.forward())) > 1e-3 * len ? n * (1.0 / len)
                                                                                            : light.forward() * -1.0;
        nrm[4 * p] = float(n.x), nrm[4 * p + 1] = float(n.y), nrm[4 * p + 2] = float(n.z);
      }
    for (uint32_t r : {1u, 3u, 5u}) {
      for (auto& x : q) x.r = r;
      const double gms = median_ms(a.reps, [&] { return g.evaluate(q, got).gpu_ms; });
      double ims = 0;
      bool agree = true;
      if (img) {
        ims = median_ms(a.reps, [&] { return img->evaluate(q, want); });
        for (size_t i = 0; i < q.size(); ++i) agree &= std::bit_cast<uint32_t>(got[i]) == std::bit_cast<uint32_t>(want[i]);
      }
      gpu::ShadowPassInput in;
      in.positions = pos;
      in.normals = nrm;
      in.width = a.width;
      in.height = a.height;
      in.kernel = r;
      in.neighbour_footprint = false;
      in.footprint = 1;
      in.receiver_plane = false;  // one receiver depth: the R32F pass's rule, compared bit for bit
      gpu::ShadowPassInput in_plane = in;
      in_plane.receiver_plane = true;
      std::vector<float> vis(pixels), vis_img(pixels), vis_plane(pixels);
      gpu::FrameStats pass_stats;
      // The pass with one receiver depth and with the receiver plane, alternated rep by rep.
      std::vector<double> flat_ms, plane_ms;
      for (uint32_t rep = 0; rep < a.reps; ++rep) {
        pass_stats = g.wait(g.submit_shadow_pass(in), vis);
        flat_ms.push_back(pass_stats.gpu_ms);
        plane_ms.push_back(g.wait(g.submit_shadow_pass(in_plane), vis_plane).gpu_ms);
      }
      const double pms = median(flat_ms), plms = median(plane_ms);
      size_t plane_moved = 0;
      for (size_t i = 0; i < pixels; ++i) plane_moved += std::bit_cast<uint32_t>(vis[i]) != std::bit_cast<uint32_t>(vis_plane[i]);
      double pims = 0;
      if (img) {
        pims = median_ms(a.reps, [&] { return img->shadow_pass(in, gpu::shadow_light(client::pack_header(map)), vis_img); });
        for (size_t i = 0; i < pixels; ++i) agree &= std::bit_cast<uint32_t>(vis[i]) == std::bit_cast<uint32_t>(vis_img[i]);
      }
      const std::string op = r == 1 ? "tap" : std::to_string(r) + "x" + std::to_string(r);
      const double glps = gms > 0 ? double(q.size()) / (gms * 1e3) : 0, ilps = ims > 0 ? double(q.size()) / (ims * 1e3) : 0;
      std::printf("%-6s %-5s %12.1f %12.1f %8.2f | %10.3f %10.3f %7.2f | %7.1fMB %8.0f %6s | %9.3f %6.2f %7.2f%%\n",
                  name.c_str(), op.c_str(), glps, ilps, ilps > 0 ? glps / ilps : 0, pms, pims, pims > 0 ? pms / pims : 0,
                  double(gs.bytes_uploaded) / 1e6, upload_mbs, img ? (agree ? "yes" : "NO") : "n/a", plms,
                  pms > 0 ? plms / pms : 0, 100.0 * double(plane_moved) / double(pixels));
      rows.push_back({{"encoding", name}, {"op", op}, {"gpu_mlookups_per_s", glps}, {"r32f_mlookups_per_s", ilps},
                      {"gpu_ms", gms}, {"r32f_ms", ims}, {"pass_ms", pms}, {"r32f_pass_ms", pims},
                      {"pass_vs_r32f", pims > 0 ? pms / pims : 0}, {"plane_pass_ms", plms},
                      {"plane_vs_flat", pms > 0 ? plms / pms : 0}, {"plane_moved_pixels", plane_moved},
                      {"upload_bytes", gs.bytes_uploaded},
                      {"upload_mb_per_s", upload_mbs}, {"slots", gs.slot_count}, {"agree_with_r32f", agree},
                      {"r32f", img ? "yes" : no_image},
                      // One shadow pass frame's host <-> device bytes by kind (FrameStats): what
                      // engine mode moves is tile + page + feedback (its G-buffer stays on the GPU).
                      {"pass_tile_bytes", pass_stats.tile_bytes}, {"pass_page_bytes", pass_stats.page_bytes},
                      {"pass_feedback_bytes", pass_stats.feedback_bytes}, {"pass_host_io_bytes", pass_stats.host_io_bytes}});
      std::printf("%-6s %-5s   pass frame bytes: tile %llu, page table %llu, feedback %llu | G-buffer in + visibility out "
                  "%llu (own-device mode only)\n",
                  name.c_str(), op.c_str(), (unsigned long long)pass_stats.tile_bytes,
                  (unsigned long long)pass_stats.page_bytes, (unsigned long long)pass_stats.feedback_bytes,
                  (unsigned long long)pass_stats.host_io_bytes);
    }
    if (!a.camera.empty() && report.find("view") == report.end()) report["view"] = view_pictures(a, scene, light, map, g);
    srv.stop();
  }
  report["rows"] = rows;
  std::filesystem::create_directories(std::filesystem::path(a.json).parent_path().empty() ? "." : std::filesystem::path(a.json).parent_path());
  std::ofstream(a.json) << report.dump(2) << "\n";
  std::printf("wrote %s\n", a.json.c_str());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_gpu: %s\n", e.what());
  return 1;
}

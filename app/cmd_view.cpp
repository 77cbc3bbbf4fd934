// `shadowtile view --server HOST:PORT --map NAME --scene SCENE [--path flyover | --camera pos=..,target=..]
//  [--frames 24] [--fps 24] [--size 1920x1080] [--pcf 3] [--seed 1] [--device NAME] [--cache-mb 256]
//  [--upload-mb 16] [--frames-in-flight 2] [--time T | --time-sweep A..B | --soft] [--twin] [--out view-out]
//  [--json PATH]`: a headless viewer that renders as a game engine would. It flies a load-tester
// camera path (loadgen/camera_path.hpp), or holds one camera (--camera, as `render` takes it),
// over a map streamed from `shadowtile serve`, and draws the scene with a real GPU rasterizer
// (examples/raster: the renderer examples/engine_raster uses): a depth pre-pass and a shading pass
// whose fragment shader looks the shadows up in the GPU tile cache (shadowtile.glsl) at each
// pixel's footprint, with frames in flight (no per-frame wait: a frame is collected when its
// fence has signalled) and the tiles asked for only by the fragment shader's feedback (nothing
// is prefetched). Public API only: the client (client.hpp, cache_view.hpp) and engine mode
// (gpu.hpp). Prints per frame, as each completes, the GPU time of the frame and of its
// shading pass (timestamp queries), the host time of the frame path, the tiles requested from
// feedback, holes (pixels answered from a coarser level) and residency; then a summary, a
// contact sheet and JSON. Never waits for the network: frames advance at --fps of simulated
// time whatever has arrived.
//
// A stack map (a pack built with a light set, `--light sun-path:...` or `area:...`) is drawn
// at the light set's time: --time T for every frame, or --time-sweep A..B from A at the first
// frame to B at the last (the sun moves while the camera flies). The fragment shader blends the
// two nearest slices (gpu::stack_time), the shading follows the light between them, and each
// frame also asks for the slices the next frame's time reads (at a low priority, under the
// feedback's). With --soft it averages all N samples (an area light's soft shadow, or a day's
// mean sun), shaded toward the samples' mean light.
//
// --twin: the last frame's lookups are answered again on the CPU at the receivers and
// footprints the fragment shader used (gpu::receiver_lookup_reference: the shader's float
// light transform, the Map's cache), and the pixels whose bits differ counted. The
// client's own lookups (Map::visibility_filtered) transform in double: where the float
// transform rounds onto a texel's edge they read the neighbouring texel, so they are not
// the shader's twin.
//
// Before the rasterizer, `view` ray-traced a G-buffer with Embree on the CPU and ran the GPU
// compute pass over it, waiting for every frame; --full-walks (a compute-pass setting) went
// with it.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <thread>

#include "app/command.hpp"
#include "app/connect_options.hpp"
#include "app/pcf_option.hpp"
#include "app/scene_limits_option.hpp"
#include "common/error.hpp"
#include "examples/raster/flat_mesh.hpp"
#include "examples/raster/raster.hpp"
#include "loadgen/camera_path.hpp"
#include "loadgen/load_run.hpp"
#include "shadowtile/cache_view.hpp"
#include "image/png_io.hpp"
#include "scene/scene.hpp"
#include "scene/scene_limits.hpp"
#include "tiles/core/light.hpp"

namespace st::cli {

client::Endpoint parse_endpoint(const std::string& option, const std::string& text);  // cmd_load.cpp
void parse_time_range(const std::string& option, const std::string& text, double& a, double& b);  // cmd_load.cpp

namespace {

struct ViewArgs {
  std::string server, map, scene, path = "flyover", camera, size = "1920x1080", device, out = "view-out", json, up;
  std::string scene_limits;  // --scene-limits (scene/scene_limits.hpp)
  ConnectArgs connect;
  std::string time, time_sweep;
  bool soft = false, twin = false, validation = false;
  bool cache_mb_given = false;  // --cache-mb on the command line (else the default, clamped to fit the device)
  uint32_t frames = 24, pcf = 3, in_flight = 2;
  double fps = 24, cache_mb = 256, upload_mb = 16;
  uint64_t seed = 1;
};

double med(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

void run_view(const ViewArgs& a) {
  uint32_t width = 0, height = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &width, &height) != 2 || width == 0 || height == 0 || width > 8192 ||
      height > 8192)
    throw Error("--size: expected WxH (1..8192), got '" + a.size + "'");
  if (a.frames == 0 || a.frames > 100000) throw Error("--frames: 1..100000");
  cli::checked_pcf_side("--pcf", a.pcf);
  if (!(a.fps > 0)) throw Error("--fps must be > 0");
  if (a.in_flight < 1 || a.in_flight > 4) throw Error("--frames-in-flight: 1..4");
  if (!a.time.empty() + !a.time_sweep.empty() + a.soft > 1) throw Error("view: give one of --time, --time-sweep, --soft");
  double time0 = 0, time1 = 0;
  if (!a.time.empty()) parse_time_range("--time", a.time, time0, time1);
  if (!a.time_sweep.empty()) {
    if (a.time_sweep.find("..") == std::string::npos) throw Error("--time-sweep: expected A..B, got '" + a.time_sweep + "'");
    parse_time_range("--time-sweep", a.time_sweep, time0, time1);
  }
  std::optional<Camera> fixed;
  if (!a.camera.empty()) fixed = parse_camera(a.camera);
  SceneOptions so;
  so.up = parse_up_axis(a.up);
  const Scene scene = load_scene(a.scene, so, parse_scene_limits(a.scene_limits));
  client::ClientOptions co;
  co.client_name = "shadowtile-view";
  apply_connect_options(a.connect, co);
  co.cache_slots = 1;  // a probe: the slot size, in one slot
  auto cl = std::make_unique<client::Client>(parse_endpoint("--server", a.server), co);
  client::Map map = cl->open(a.map);
  // The budget holds everything per slot (client.hpp cache_bytes); the queue follows the slots.
  co.cache_bytes = uint64_t(a.cache_mb * 1048576.0);
  co.want_capacity = std::max<uint32_t>(
      co.want_capacity, uint32_t(std::min<uint64_t>(4 * (co.cache_bytes / (map.slot_bytes() + client::kSlotOverheadBytes)),
                                                    uint64_t(1) << 20)));
  cl = std::make_unique<client::Client>(parse_endpoint("--server", a.server), co);
  map = cl->open(a.map);
  co.cache_slots = map.stats().cache.resident + map.stats().cache.pinned + map.stats().cache.free;
  // The default cache shrinks until its slot pool (one storage buffer on the GPU) fits the
  // device's maxStorageBufferRange (GpuMap::max_cache_slots; 2^27 bytes on lavapipe): a
  // default must work on the device at hand. A --cache-mb given keeps GpuMap's clear error.
  if (!a.cache_mb_given) {
    gpu::GpuOptions probe;
    probe.device = a.device;
    uint32_t fit = 0;
    const uint64_t dict = map.stats().dictionary_bytes;  // in the pool after the slots
    try {
      fit = gpu::GpuMap::max_cache_slots(probe, map.slot_bytes(), dict);
    } catch (const gpu::GpuError&) {  // several devices, none named: the raster takes the first
      fit = gpu::GpuMap::max_cache_slots(gpu::GpuMap::kAnyDeviceStorageRange, map.slot_bytes(), dict);
    }
    const uint32_t asked = co.cache_slots;
    for (int i = 0; i < 16 && co.cache_slots > fit; ++i) {
      co.cache_bytes = uint64_t(double(co.cache_bytes) * std::min(double(fit) / double(co.cache_slots), 0.99));
      cl = std::make_unique<client::Client>(parse_endpoint("--server", a.server), co);
      map = cl->open(a.map);
      co.cache_slots = map.stats().cache.resident + map.stats().cache.pinned + map.stats().cache.free;
    }
    if (co.cache_slots != asked)
      std::printf("view: default cache clamped from %u to %u slots (%.0f MiB) so its slot pool fits the device's "
                  "storage-buffer range (%u slots); give --cache-mb to choose\n",
                  asked, co.cache_slots, double(co.cache_bytes) / 1048576.0, fit);
  }
  const client::MapInfo info = map.info();
  if (info.scene_hash != scene.content_hash() &&
      !(scene.any_partial() && info.scene_hash == opaque_part(scene).content_hash()))
    std::fprintf(stderr, "shadowtile view: warning: scene '%s' is not the scene the map was built from\n", a.scene.c_str());
  const uint32_t slices = map.slices();
  if (!slices && !(a.time.empty() && a.time_sweep.empty() && !a.soft))
    throw Error("view: --time, --time-sweep and --soft need a stack map (a pack built with --light sun-path:... or "
                "area:...)");
  // The lights to shade toward: the map's, or a stack's samples (slice w = sample w).
  std::vector<LightSpace> samples;
  if (slices) {
    const client::CacheView cv(map);
    for (const client::LightParams& lp : cv.stack()->lights) samples.push_back(LightSpace::from_array(LightKind(lp.kind), lp.params));
  } else {
    samples.push_back(LightSpace::from_array(LightKind(info.light.kind_id()), info.light.to_array()));
  }
  // Shading toward a light between samples (weights per sample): a sun's mean direction, or
  // a spot's mean position (an area light's samples are points of its rectangle).
  auto shade_light = [&](const std::vector<std::pair<uint32_t, double>>& ws, raster::FrameInput& in) {
    Vec3d acc{0, 0, 0};
    for (const auto& [w, k] : ws) acc = acc + (samples[w].parallel() ? samples[w].forward() * -k : samples[w].origin() * k);
    const bool point = !samples[ws[0].first].parallel();
    if (!point) acc = normalize(acc);
    in.light = {acc.x, acc.y, acc.z};
    in.light_is_point = point;
  };
  std::vector<std::pair<uint32_t, double>> all_samples;
  for (uint32_t w = 0; w < samples.size(); ++w) all_samples.push_back({w, 1.0 / double(samples.size())});
  const loadgen::WorldFrame world = loadgen::map_world_frame(map);
  const loadgen::CameraPath path(loadgen::parse_path(a.path), world, a.seed, 0);

  raster::RasterOptions ro;
  ro.width = width, ro.height = height, ro.device = a.device;
  ro.frames_in_flight = a.in_flight;
  ro.upload_budget_bytes = uint64_t(a.upload_mb * 1048576.0);
  ro.twin = a.twin;
  ro.validation = a.validation;
  const std::vector<float> triangles = raster::flat_triangles(scene);
  if (triangles.empty()) throw Error("view: scene '" + a.scene + "' has no triangles to draw");
  raster::Rasterizer r(map, triangles, ro);
  std::printf("device '%s', %ux%u, %u frames of %s, cache %u slots, %u frames in flight\n", r.device_name().c_str(),
              width, height, a.frames, fixed ? ("camera " + to_string(*fixed)).c_str() : ("path " + a.path).c_str(),
              co.cache_slots, a.in_flight);
  if (slices)
    std::printf("stack of %u slices (%s lights), %s\n", slices, info.light.kind_name(),
                a.soft                 ? "soft (every sample averaged)"
                : a.time_sweep.empty() ? ("time " + std::to_string(time0)).c_str()
                                       : ("time " + std::to_string(time0) + ".." + std::to_string(time1) + " swept").c_str());
  // The light set's time of frame f (a sweep: A at the first frame, B at the last).
  auto time_of = [&](uint32_t f) {
    return a.frames > 1 ? time0 + (time1 - time0) * double(std::min(f, a.frames - 1)) / double(a.frames - 1) : time0;
  };

  std::filesystem::create_directories(a.out);
  const size_t pixels = size_t(width) * height;
  std::vector<Rgb8> image(pixels);
  const uint32_t thumb = 8, tw = std::max(1u, width / thumb), th = std::max(1u, height / thumb);
  const uint32_t cols = std::min<uint32_t>(a.frames, 6), rows = (a.frames + cols - 1) / cols;
  std::vector<Rgb8> sheet(size_t(tw) * cols * th * rows);
  // One finest texel in world units (a spot's at the world's centre): the footprint's unit.
  const double texel = samples[0].texel_size(world.centre(), info.finest_level);
  nlohmann::json frames = nlohmann::json::array();
  std::printf("%6s %9s %9s %9s %9s %10s %9s %9s %11s%s\n", "frame", "gpu ms", "shade ms", "host us", "path us",
              "requested", "holes", "hole %", "resident", slices && !a.soft ? "     time" : "");
  std::vector<double> gpu_ms, shade_ms, host_us, path_us, holes_pct, times(a.frames, 0.0);
  std::vector<double> record_us(a.frames, 0.0);
  std::vector<Camera> cams(a.frames);
  raster::FrameResult last;
  std::vector<float> last_rec, last_vis, last_slopes;
  auto collect = [&](std::span<const raster::FrameResult> done) {
    for (const raster::FrameResult& fr : done) {
      const uint32_t f = uint32_t(fr.frame - 1);
      for (size_t p = 0; p < pixels; ++p) image[p] = {fr.rgba[4 * p], fr.rgba[4 * p + 1], fr.rgba[4 * p + 2]};
      char name[64];
      std::snprintf(name, sizeof(name), "/frame_%04u.png", f);
      write_png(a.out + name, width, height, image);
      const uint32_t cx = (f % cols) * tw, cy = (f / cols) * th;
      for (uint32_t y = 0; y < th; ++y)
        for (uint32_t x = 0; x < tw; ++x)
          sheet[size_t(cy + y) * tw * cols + cx + x] =
              image[size_t(std::min(height - 1, y * thumb)) * width + std::min(width - 1, x * thumb)];
      const client::MapStats ms = map.stats();
      const gpu::FrameStats& fs = fr.stats;
      const double hole_pct = 100.0 * fs.holes / double(pixels);
      gpu_ms.push_back(fr.gpu_frame_ms), shade_ms.push_back(fr.gpu_shade_ms), host_us.push_back(fr.host_us);
      path_us.push_back(record_us[f]);
      holes_pct.push_back(hole_pct);
      std::printf("%6u %9.3f %9.3f %9.1f %9.1f %10u %9u %8.2f%% %5u/%-5u", f, fr.gpu_frame_ms, fr.gpu_shade_ms, fr.host_us,
                  record_us[f], fs.requested, fs.holes, hole_pct, ms.cache.resident, co.cache_slots);
      if (slices && !a.soft) std::printf(" %8.4f", times[f]);
      std::printf("\n");
      std::fflush(stdout);
      frames.push_back({{"frame", f}, {"gpu_ms", fr.gpu_frame_ms}, {"shade_ms", fr.gpu_shade_ms},
                        {"depth_ms", fr.gpu_depth_ms}, {"upload_ms", fr.gpu_upload_ms}, {"host_us", fr.host_us},
                        {"frame_path_us", record_us[f]}, {"requested", fs.requested},
                        {"feedback_tiles", fs.feedback_tiles}, {"holes", fs.holes}, {"holes_pct", hole_pct},
                        {"resident", ms.cache.resident}, {"slots_uploaded", fs.slots_uploaded},
                        {"tile_bytes", fs.tile_bytes}, {"page_bytes", fs.page_bytes},
                        {"feedback_bytes", fs.feedback_bytes}, {"host_io_bytes", fs.host_io_bytes},
                        {"tiles_received", ms.tiles_received}, {"camera", to_string(cams[f])}});
      if (slices && !a.soft) frames.back()["time"] = times[f];
      if (a.twin && fr.frame == a.frames) {
        last = fr;
        last_rec.assign(fr.receivers.begin(), fr.receivers.end());
        last_vis.assign(fr.visibility.begin(), fr.visibility.end());
        last_slopes.assign(fr.slopes.begin(), fr.slopes.end());
      }
    }
  };

  raster::FrameInput in;
  in.kernel = a.pcf;
  in.filter = true;
  in.texel = texel;
  in.soft = a.soft;
  if (a.soft) shade_light(all_samples, in);
  else if (!slices) shade_light({{0, 1.0}}, in);
  for (uint32_t f = 0; f < a.frames; ++f) {
    const Camera cam = fixed ? *fixed : path.at(f / a.fps);
    cams[f] = cam;
    in.eye = {cam.pos.x, cam.pos.y, cam.pos.z};
    in.target = {cam.target.x, cam.target.y, cam.target.z};
    in.fov_deg = cam.fov_deg;
    times[f] = time_of(f);
    if (slices && !a.soft) {
      const gpu::StackTime st = gpu::stack_time(slices, times[f]);
      in.slice_a = st.a, in.slice_b = st.b, in.blend = st.f;
      shade_light({{st.a, 1.0 - double(st.f)}, {st.b, double(st.f)}}, in);
      // Ask for the slices the next frame's time reads, under the feedback's priorities.
      const gpu::StackTime next = gpu::stack_time(slices, time_of(f + 1));
      if (next.a != st.a || next.b != st.b) map.request_slices(next.a, next.b, 1);
    }
    const auto t0 = std::chrono::steady_clock::now();
    const std::span<const raster::FrameResult> done = r.render(in);
    record_us[f] = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
    collect(done);
    // Simulated time: the next frame comes 1/fps later, arrivals or not.
    std::this_thread::sleep_for(std::chrono::duration<double>(1.0 / a.fps));
  }
  collect(r.finish());
  write_png(a.out + "/contact_sheet.png", tw * cols, th * rows, sheet);
  const gpu::GpuStats gs = r.stats();
  std::printf("\nsummary: gpu frame median %.3f ms, shading pass median %.3f ms, max %.3f ms; host frame path median "
              "%.1f us; holes median %.2f%%, last %.2f%%; %llu tiles uploaded (%.1f MB), %llu requested from feedback; "
              "%llu waits for a ring slot\n",
              med(gpu_ms), med(shade_ms), *std::max_element(shade_ms.begin(), shade_ms.end()), med(host_us),
              med(holes_pct), holes_pct.back(), (unsigned long long)gs.slots_uploaded, gs.bytes_uploaded / 1e6,
              (unsigned long long)gs.feedback_requested, (unsigned long long)r.ring_waits());
  nlohmann::json report = {{"device", r.device_name()}, {"width", width}, {"height", height},
                           {"path", fixed ? "camera" : a.path}, {"pcf", a.pcf}, {"frames_in_flight", a.in_flight},
                           {"gpu_ms_median", med(gpu_ms)}, {"shade_ms_median", med(shade_ms)},
                           {"host_us_median", med(host_us)}, {"holes_pct_median", med(holes_pct)},
                           {"slots_uploaded", gs.slots_uploaded}, {"bytes_uploaded", gs.bytes_uploaded},
                           {"tile_bytes", gs.tile_bytes}, {"page_bytes", gs.page_bytes},
                           {"feedback_bytes", gs.feedback_bytes}, {"host_io_bytes", gs.host_io_bytes},
                           {"feedback_requested", gs.feedback_requested}, {"ring_waits", r.ring_waits()},
                           {"frames", frames}};
  if (slices) report["stack"] = {{"slices", slices}, {"soft", a.soft}, {"time0", time0}, {"time1", time1}};
  if (a.twin) {
    // The CPU twin of the last frame: the same receivers and footprints through the
    // shader's float light transform and the client's cache (the cache now holds at least
    // what the GPU had); any bit that differs counts.
    gpu::ReceiverLookup q;
    q.kernel = a.pcf, q.soft = a.soft;
    if (slices && !a.soft) {
      const gpu::StackTime st = gpu::stack_time(slices, times[a.frames - 1]);
      q.slice_a = st.a, q.slice_b = st.b, q.blend = st.f;
    }
    std::vector<float> cpu(pixels);
    gpu::receiver_lookup_reference(map, last_rec, q, cpu, last_slopes);
    uint64_t lookups = 0, differ = 0;
    double max_diff = 0;
    for (size_t p = 0; p < pixels; ++p) {
      if (!(last_rec[4 * p + 3] >= 0)) continue;
      ++lookups;
      differ += std::bit_cast<uint32_t>(cpu[p]) != std::bit_cast<uint32_t>(last_vis[p]);
      max_diff = std::max(max_diff, std::fabs(double(cpu[p]) - double(last_vis[p])));
    }
    const double pct = lookups ? 100.0 * double(differ) / double(lookups) : 0.0;
    std::printf("twin: last frame's %llu lookups against the CPU's: %llu differ (%.3f%%), max difference %.4f; holes "
                "in that frame %u\n",
                (unsigned long long)lookups, (unsigned long long)differ, pct, max_diff, last.stats.holes);
    report["twin"] = {{"lookups", lookups}, {"differ", differ}, {"differ_pct", pct}, {"max_difference", max_diff},
                      {"holes", last.stats.holes}};
  }
  if (a.validation) {
    std::printf("validation: %llu messages%s%s\n", (unsigned long long)r.validation_messages(),
                r.validation_messages() ? "; the first: " : "", r.first_validation_message().c_str());
    report["validation_messages"] = r.validation_messages();
  }
  const std::string json = a.json.empty() ? a.out + "/view.json" : a.json;
  std::ofstream(json) << report.dump(2) << "\n";
  std::printf("wrote %s/frame_*.png, %s/contact_sheet.png, %s\n", a.out.c_str(), a.out.c_str(), json.c_str());
}

Register reg_view{"view",
             "Headless viewer: a GPU rasterizer (engine mode) draws a camera path or a camera with shadows from "
             "streamed tiles, looked up in its fragment shader (PNG frames)",
             [](CLI::App& sub) {
               auto a = std::make_shared<ViewArgs>();
               sub.footer(
                   "Renders with a Vulkan rasterizer (examples/raster, as examples/engine_raster): a depth pre-pass, "
                   "then a fragment shader that looks shadows up in the GPU tile cache (shadowtile.glsl) at each "
                   "pixel's footprint; frames in flight, tiles asked for by the shader's feedback. Changed: no "
                   "Embree G-buffer on the CPU and no wait per frame any more; columns 'gpu ms' / 'shade ms' are "
                   "the frame's and its shading pass's GPU time, 'host us' the frame path's CPU time in GpuMap; "
                   "--full-walks (a compute-pass setting) is gone; --camera, --frames-in-flight, --twin and --validation are "
                   "new.");
               sub.add_option("--server", a->server, "Server HOST:PORT")->required();
               sub.add_option("--map", a->map, "Map name")->required();
               add_connect_options(sub, a->connect);
               sub.add_option("--scene", a->scene, "The scene the map was built from (drawn by the rasterizer)")->required();
               add_scene_file_options(sub, a->up, a->scene_limits);
               sub.add_option("--path", a->path, "Camera path: flyover, orbit, walk, teleport");
               sub.add_option("--camera", a->camera,
                              "One camera for every frame, pos=X,Y,Z,target=X,Y,Z[,fov=DEG] as `render` takes it "
                              "(instead of --path)");
               sub.add_option("--frames", a->frames, "Frames to render");
               sub.add_option("--fps", a->fps, "Simulated frames per second of the path");
               sub.add_option("--size", a->size, "WxH (default 1920x1080)");
               sub.add_option("--pcf", a->pcf, "PCF kernel side: odd, 1..9 (at the two levels of each pixel's footprint)");
               sub.add_option("--seed", a->seed, "Camera path seed");
               sub.add_option("--device", a->device, "Vulkan device name (default: SHADOWTILE_VK_DEVICE)");
               CLI::Option* cache_mb = sub.add_option(
                   "--cache-mb", a->cache_mb,
                   "Tile cache size (MiB; default 256, clamped so that the GPU slot pool fits the device)");
               sub.add_option("--upload-mb", a->upload_mb, "GPU upload budget per frame");
               sub.add_option("--frames-in-flight", a->in_flight, "Frames the GPU may run behind the CPU (1..4)");
               sub.add_option("--time", a->time,
                              "Stack maps: the light set's time T in [0, 1] (slices blended; default 0)");
               sub.add_option("--time-sweep", a->time_sweep,
                              "Stack maps: time A..B swept over the frames (the sun moves while the camera flies)");
               sub.add_flag("--soft", a->soft,
                            "Stack maps: the soft shadow, every sample of the light set averaged (area lights)");
               sub.add_flag("--twin", a->twin,
                            "Answer the last frame's lookups again on the CPU (the shader's float light transform "
                            "over the client's cache) and count the pixels whose bits differ");
               sub.add_flag("--validation", a->validation,
                            "Run under VK_LAYER_KHRONOS_validation and count its warnings and errors");
               sub.add_option("--out", a->out, "Output folder (frames, contact sheet, view.json)");
               sub.add_option("--json", a->json, "JSON report path (default OUT/view.json)");
               sub.callback([a, cache_mb] {
                 a->cache_mb_given = cache_mb->count() > 0;
                 run_view(*a);
               });
             }};

}  // namespace
}  // namespace st::cli

// `shadowtile view --server HOST:PORT --map NAME --scene SCENE [--path flyover] [--frames 24]
//  [--fps 24] [--size 1920x1080] [--pcf 3] [--seed 1] [--device NAME] [--cache-mb 256]
//  [--upload-mb 16] [--time T | --time-sweep A..B | --soft] [--full-walks] [--out view-out] [--json PATH]`:
// a headless viewer. It flies a load-tester camera path (loadgen/camera_path.hpp) over a
// map streamed from `shadowtile serve`; per frame, primary visibility on the CPU (Embree) into a G-buffer, the shadow pass on
// the GPU (gpu::GpuMap) from the tiles streamed so far, Lambert shading into a PNG; the
// GPU's feedback drives the tile requests (no region is prefetched). Prints per frame the
// GPU pass time, tiles requested from feedback, holes (pixels answered from a coarser
// level), residency; then a summary table, a contact sheet and JSON. Never waits for the
// network: frames advance at --fps of simulated time whatever has arrived.
//
// A stack map (a pack built with a light set, `--light sun-path:...` or `area:...`) is drawn
// at the light set's time: --time T for every frame, or --time-sweep A..B from A at the
// first frame to B at the last (the sun moves while the camera flies). The GPU pass blends
// the two nearest slices (gpu::ShadowPassInput::time), the shading follows the light
// between them, and each frame also asks for the slices the next frame's time reads (at a
// low priority, under the feedback's), so a sweep finds its next slice on its way. With
// --soft the pass averages all N samples (gpu::ShadowPassInput::soft: an area light's soft
// shadow, or a day's mean sun), shaded toward the samples' mean light; the feedback
// streams the cells of every slice. Area lights' samples are perspective (spots).
// --full-walks walks every tile from its root (gpu::ShadowPassInput::resume_walks = false),
// to compare with the resumed walks on a device.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <thread>

#include "app/scene_limits_option.hpp"
#include "app/command.hpp"
#include "client/map_access.hpp"
#include "common/error.hpp"
#include "gpu/gpu_map.hpp"
#include "loadgen/camera_path.hpp"
#include "loadgen/load_run.hpp"
#include "tiles/core/stack_grid.hpp"
#include "tiles/bake/scene_limits.hpp"
#include "tiles/bake/png_io.hpp"
#include "tiles/bake/render.hpp"
#include "tiles/bake/scene.hpp"

namespace st::cli {

client::Endpoint parse_endpoint(const std::string& option, const std::string& text);  // cmd_load.cpp
void parse_time_range(const std::string& option, const std::string& text, double& a, double& b);  // cmd_load.cpp

namespace {

struct ViewArgs {
  std::string server, map, scene, path = "flyover", size = "1920x1080", device, out = "view-out", json, up;
  std::string scene_limits;  // --scene-limits (tiles/bake/scene_limits.hpp)
  std::string time, time_sweep;
  bool soft = false, full_walks = false;
  uint32_t frames = 24, pcf = 3;
  double fps = 24, cache_mb = 256, upload_mb = 16;
  uint64_t seed = 1;
};

void run(const ViewArgs& a) {
  uint32_t width = 0, height = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &width, &height) != 2 || width == 0 || height == 0 || width > 8192 ||
      height > 8192)
    throw Error("--size: expected WxH (1..8192), got '" + a.size + "'");
  if (a.frames == 0 || a.frames > 100000) throw Error("--frames: 1..100000");
  if (a.pcf < 1 || a.pcf > 9) throw Error("--pcf: kernel side 1..9");
  if (!(a.fps > 0)) throw Error("--fps must be > 0");
  if (!a.time.empty() + !a.time_sweep.empty() + a.soft > 1) throw Error("view: give one of --time, --time-sweep, --soft");
  double time0 = 0, time1 = 0;
  if (!a.time.empty()) parse_time_range("--time", a.time, time0, time1);
  if (!a.time_sweep.empty()) {
    if (a.time_sweep.find("..") == std::string::npos) throw Error("--time-sweep: expected A..B, got '" + a.time_sweep + "'");
    parse_time_range("--time-sweep", a.time_sweep, time0, time1);
  }
  SceneOptions so;
  so.up = parse_up_axis(a.up);
  const Scene scene = load_scene(a.scene, so, parse_scene_limits(a.scene_limits));
  client::ClientOptions co;
  co.client_name = "shadowtile-view";
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
  const PackHeader& h = client::pack_header(map);
  const LightSpace light = LightSpace::from_array(h.light_kind, h.light);  // a stack's: slice 0's
  if (h.scene_hash != scene.content_hash())
    std::fprintf(stderr, "shadowtile view: warning: scene '%s' is not the scene the map was built from\n", a.scene.c_str());
  const StackGrid* stack = client::MapAccess::remote(map).stack_grid();
  if (!stack && !(a.time.empty() && a.time_sweep.empty() && !a.soft))
    throw Error("view: --time, --time-sweep and --soft need a stack map (a pack built with --light sun-path:... or "
                "area:...)");
  if (!stack && !light.parallel())
    throw Error("view: the GPU shadow pass of a 2D map supports suns only; map '" + a.map + "' has a spot light");
  std::vector<LightSpace> samples;
  for (uint32_t w = 0; stack && w < stack->slices; ++w) samples.push_back(stack->light(w));
  // Shading toward a light between samples (weights per sample): a sun's mean direction, or
  // a spot's mean position (an area light's samples are points of its rectangle).
  auto to_light = [&](const std::vector<std::pair<uint32_t, double>>& ws, const Vec3d& p) {
    Vec3d acc{0, 0, 0};
    for (const auto& [w, k] : ws)
      acc = acc + (samples[w].parallel() ? samples[w].forward() * -k : samples[w].origin() * k);
    return normalize(samples[ws[0].first].parallel() ? acc : acc - p);
  };
  std::vector<std::pair<uint32_t, double>> all_samples;
  for (uint32_t w = 0; w < samples.size(); ++w) all_samples.push_back({w, 1.0 / double(samples.size())});
  const loadgen::WorldFrame world = stack ? loadgen::stack_world_frame(map) : loadgen::world_frame(h, client::skip_grid(map));
  const loadgen::CameraPath path(loadgen::parse_path(a.path), world, a.seed, 0);
  const SceneTracer tracer(scene, light);

  gpu::GpuOptions go;
  go.device = a.device;
  go.max_queries = 1;
  go.max_pixels = width * height;
  go.upload_budget_bytes = uint64_t(a.upload_mb * 1048576.0);
  gpu::GpuMap g(map, go);
  std::printf("device '%s', %ux%u, %u frames of path %s, cache %u slots\n", g.device_name().c_str(), width, height,
              a.frames, a.path.c_str(), co.cache_slots);
  if (stack)
    std::printf("stack of %u slices (%s), %s\n", stack->slices, stack->spec.c_str(),
                a.soft                 ? "soft (every sample averaged)"
                : a.time_sweep.empty() ? ("time " + std::to_string(time0)).c_str()
                                       : ("time " + std::to_string(time0) + ".." + std::to_string(time1) + " swept").c_str());
  // The light set's time of frame f (a sweep: A at the first frame, B at the last).
  auto time_of = [&](uint32_t f) {
    return a.frames > 1 ? time0 + (time1 - time0) * double(std::min(f, a.frames - 1)) / double(a.frames - 1) : time0;
  };

  std::filesystem::create_directories(a.out);
  const size_t pixels = size_t(width) * height;
  std::vector<float> pos(pixels * 4), nrm(pixels * 4), vis(pixels);
  std::vector<Rgb8> image(pixels);
  const uint32_t thumb = 8, tw = std::max(1u, width / thumb), th = std::max(1u, height / thumb);
  const uint32_t cols = std::min<uint32_t>(a.frames, 6), rows = (a.frames + cols - 1) / cols;
  std::vector<Rgb8> sheet(size_t(tw) * cols * th * rows);
  // One finest texel in world units (a spot's at the world's centre).
  const double texel = light.texel_size(world.centre(), h.map_level);
  nlohmann::json frames = nlohmann::json::array();
  std::printf("%6s %10s %10s %10s %9s %9s %10s%s\n", "frame", "cpu ms", "gpu ms", "requested", "holes", "hole %",
              "resident", stack && !a.soft ? "     time" : "");
  std::vector<double> gpu_ms, holes_pct;
  for (uint32_t f = 0; f < a.frames; ++f) {
    const auto t0 = std::chrono::steady_clock::now();
    auto rec = tracer.primary(path.at(f / a.fps), width, height);
    const double time = time_of(f);
    if (stack && a.soft) {
      for (Receiver& r : rec) r.n_dot_l = dot(r.normal, to_light(all_samples, r.pos));
    } else if (stack) {
      // The light between the two slices the pass blends: shading follows it (n.l).
      const gpu::StackTime st = gpu::stack_time(stack->slices, time);
      const std::vector<std::pair<uint32_t, double>> ws = {{st.a, 1.0 - double(st.f)}, {st.b, double(st.f)}};
      for (Receiver& r : rec) r.n_dot_l = dot(r.normal, to_light(ws, r.pos));
      // Ask for the slices the next frame's time reads, under the feedback's priorities.
      const gpu::StackTime next = gpu::stack_time(stack->slices, time_of(f + 1));
      if (next.a != st.a || next.b != st.b) map.request_slices(next.a, next.b, 1);
    }
    for (size_t p = 0; p < pixels; ++p) {
      const Receiver& r = rec[p];
      pos[4 * p] = float(r.pos.x), pos[4 * p + 1] = float(r.pos.y), pos[4 * p + 2] = float(r.pos.z);
      pos[4 * p + 3] = r.hit && r.n_dot_l > 0 ? 1.0f : 0.0f;  // facing away: unlit whatever the map says
      nrm[4 * p] = float(r.normal.x), nrm[4 * p + 1] = float(r.normal.y), nrm[4 * p + 2] = float(r.normal.z);
    }
    const double cpu_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    gpu::ShadowPassInput in;
    in.positions = pos;
    in.normals = nrm;
    in.width = width;
    in.height = height;
    in.kernel = a.pcf;
    in.normal_offset = float(kOpenReceiverOffsetTexels * texel);
    in.neighbour_footprint = true;
    in.time = time;
    in.soft = a.soft;
    in.resume_walks = !a.full_walks;
    const gpu::FrameStats fs = g.wait(g.submit_shadow_pass(in), vis);
    for (size_t p = 0; p < pixels; ++p) {
      const Receiver& r = rec[p];
      const double lit = r.hit ? (r.n_dot_l > 0 ? r.n_dot_l * vis[p] : 0.0) : 1.0;
      const double shade = r.hit ? 0.15 + 0.85 * lit : 0.6;
      const uint8_t c = uint8_t(std::clamp(shade * 255.0, 0.0, 255.0));
      image[p] = r.hit ? Rgb8{c, c, uint8_t(std::min(255.0, c * 0.9 + 20))} : Rgb8{140, 170, 220};
    }
    char name[64];
    std::snprintf(name, sizeof(name), "/frame_%04u.png", f);
    write_png(a.out + name, width, height, image);
    const uint32_t cx = (f % cols) * tw, cy = (f / cols) * th;
    for (uint32_t y = 0; y < th; ++y)
      for (uint32_t x = 0; x < tw; ++x)
        sheet[size_t(cy + y) * tw * cols + cx + x] = image[size_t(std::min(height - 1, y * thumb)) * width + std::min(width - 1, x * thumb)];
    const client::MapStats ms = map.stats();
    const double hole_pct = 100.0 * fs.holes / double(pixels);
    gpu_ms.push_back(fs.gpu_ms);
    holes_pct.push_back(hole_pct);
    std::printf("%6u %10.1f %10.3f %10u %9u %8.2f%% %5u/%-5u", f, cpu_ms, fs.gpu_ms, fs.requested, fs.holes, hole_pct,
                ms.cache.resident, co.cache_slots);
    if (stack && !a.soft) std::printf(" %8.4f", time);
    std::printf("\n");
    std::fflush(stdout);
    frames.push_back({{"frame", f}, {"cpu_ms", cpu_ms}, {"gpu_ms", fs.gpu_ms}, {"requested", fs.requested},
                      {"feedback_tiles", fs.feedback_tiles}, {"holes", fs.holes}, {"holes_pct", hole_pct},
                      {"resident", ms.cache.resident}, {"slots_uploaded", fs.slots_uploaded},
                      {"bytes_uploaded", fs.bytes_uploaded}, {"tiles_received", ms.tiles_received}});
    if (stack && !a.soft) frames.back()["time"] = time;
    // Simulated time: the next frame comes 1/fps later, arrivals or not.
    std::this_thread::sleep_for(std::chrono::duration<double>(1.0 / a.fps));
  }
  write_png(a.out + "/contact_sheet.png", tw * cols, th * rows, sheet);
  auto med = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v[v.size() / 2];
  };
  const gpu::GpuStats gs = g.stats();
  std::printf("\nsummary: gpu pass median %.3f ms, max %.3f ms; holes median %.2f%%, last %.2f%%; %llu tiles uploaded "
              "(%.1f MB), %llu requested from feedback\n",
              med(gpu_ms), *std::max_element(gpu_ms.begin(), gpu_ms.end()), med(holes_pct), holes_pct.back(),
              (unsigned long long)gs.slots_uploaded, gs.bytes_uploaded / 1e6, (unsigned long long)gs.feedback_requested);
  nlohmann::json report = {{"device", gs.device}, {"width", width}, {"height", height}, {"path", a.path},
                                 {"pcf", a.pcf}, {"gpu_ms_median", med(gpu_ms)}, {"holes_pct_median", med(holes_pct)},
                                 {"slots_uploaded", gs.slots_uploaded}, {"bytes_uploaded", gs.bytes_uploaded},
                                 {"feedback_requested", gs.feedback_requested}, {"frames", frames}};
  if (stack)
    report["stack"] = {{"slices", stack->slices}, {"spec", stack->spec}, {"soft", a.soft}, {"resume_walks", !a.full_walks}, {"time0", time0}, {"time1", time1}};
  const std::string json = a.json.empty() ? a.out + "/view.json" : a.json;
  std::ofstream(json) << report.dump(2) << "\n";
  std::printf("wrote %s/frame_*.png, %s/contact_sheet.png, %s\n", a.out.c_str(), a.out.c_str(), json.c_str());
}

Register reg{"view", "Headless viewer: fly a camera path, GPU shadow pass from streamed tiles (PNG frames)",
             [](CLI::App& sub) {
               auto a = std::make_shared<ViewArgs>();
               sub.add_option("--server", a->server, "Server HOST:PORT")->required();
               sub.add_option("--map", a->map, "Map name")->required();
               sub.add_option("--scene", a->scene, "The scene the map was built from")->required();
               sub.add_option("--up", a->up, "Up axis of a scene file: y or z; default: the file's own (Quake 3: z; FBX metadata; COLLADA <up_axis>), else y")->check(CLI::IsMember({"y", "z"}));
               add_scene_limits_option(sub, a->scene_limits);
               sub.add_option("--path", a->path, "Camera path: flyover, orbit, walk, teleport");
               sub.add_option("--frames", a->frames, "Frames to render");
               sub.add_option("--fps", a->fps, "Simulated frames per second of the path");
               sub.add_option("--size", a->size, "WxH (default 1920x1080)");
               sub.add_option("--pcf", a->pcf, "PCF kernel side 1..9");
               sub.add_option("--seed", a->seed, "Camera path seed");
               sub.add_option("--device", a->device, "Vulkan device name (default: SHADOWTILE_VK_DEVICE)");
               sub.add_option("--cache-mb", a->cache_mb, "Tile cache size");
               sub.add_option("--upload-mb", a->upload_mb, "GPU upload budget per frame");
               sub.add_option("--time", a->time,
                              "Stack maps: the light set's time T in [0, 1] (slices blended; default 0)");
               sub.add_option("--time-sweep", a->time_sweep,
                              "Stack maps: time A..B swept over the frames (the sun moves while the camera flies)");
               sub.add_flag("--soft", a->soft,
                            "Stack maps: the soft shadow, every sample of the light set averaged (area lights)");
               sub.add_flag("--full-walks", a->full_walks,
                            "Stack maps: walk each tile from its root (no resumed walks; for comparisons)");
               sub.add_option("--out", a->out, "Output folder (frames, contact sheet, view.json)");
               sub.add_option("--json", a->json, "JSON report path (default OUT/view.json)");
               sub.callback([a] { run(*a); });
             }};

}  // namespace
}  // namespace st::cli

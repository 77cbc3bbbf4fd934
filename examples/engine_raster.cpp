// engine_raster: a headless Vulkan rasterizer standing in for a game engine, over the GPU
// tile cache in engine mode. The renderer (raster/raster.cpp, shared with `shadowtile
// view`) owns the instance, device, queue, command buffers, fences, timestamp queries,
// vertex buffer and render targets; it draws the scene with a depth pre-pass and a shading
// pass whose fragment shader includes shadowtile.glsl (shaders/scene.frag), and hands
// GpuMap only its device: per frame GpuMap records the tile uploads into the renderer's
// command buffer and reads back the feedback of frames whose fences have signalled.
// Shadows stream in over the frames, asked for by the fragment shader's feedback (nothing
// is prefetched). Writes one PNG a frame and prints, per frame as it completes, the bytes
// that crossed the bus, the feedback, the holes and the GPU time of the frame and of its
// shading pass (the shadow lookups; timestamp queries).
//
//   engine_raster --server HOST:PORT --map NAME --scene SPEC [--size 960x540] [--frames 8]
//                 [--frame-ms 200] [--orbit 30] [--pcf 3] [--filter] [--out engine-raster-out]
//                 [--device NAME] [--validation]
//
// --pcf: kernel side at the finest level, or with --filter at the two levels the pixel's
// footprint picks (MH §3.3, Evaluator::pcf_footprint's choice; the footprint and the receiver
// offset as `shadowtile render --filter` takes them, so the two can be compared).
// 2D maps (suns, spots) and stack maps (slice 0); a 2D pack with a deep part (foliage,
// smoke, fog) shades with their transmittance per channel. --validation: under the Khronos validation
// layer, its warnings and errors counted.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "examples/raster/flat_mesh.hpp"
#include "examples/raster/raster.hpp"
#include "shadowtile/client.hpp"
#include "image/png_io.hpp"

namespace {

using namespace st;

struct Args {
  std::string server, map, scene, size = "960x540", out = "engine-raster-out", device;
  uint32_t frames = 8, frame_ms = 200, pcf = 3;
  double orbit = 30;
  bool filter = false, validation = false;
};

void print(const raster::FrameResult& r) {
  const gpu::FrameStats& s = r.stats;
  std::printf("%5llu %10llu %10llu %12llu %10u %9u %9u %9.3f %9.3f\n", (unsigned long long)r.frame,
              (unsigned long long)s.tile_bytes, (unsigned long long)s.page_bytes, (unsigned long long)s.feedback_bytes,
              s.feedback_tiles, s.requested, s.holes, r.gpu_frame_ms, r.gpu_shade_ms);
}

int run(const Args& a) {
  uint32_t width = 0, height = 0;
  if (std::sscanf(a.size.c_str(), "%ux%u", &width, &height) != 2 || width == 0 || height == 0 || width > 8192 ||
      height > 8192)
    throw std::runtime_error("--size: expected WxH, got '" + a.size + "'");
  const Scene scene = load_scene(a.scene, SceneOptions{});
  const auto colon = a.server.rfind(':');
  if (colon == std::string::npos) throw std::runtime_error("--server: expected HOST:PORT");
  client::ClientOptions co;
  co.cache_slots = 2048;
  client::Client cl({a.server.substr(0, colon), uint16_t(std::stoul(a.server.substr(colon + 1)))}, co);
  client::Map map = cl.open(a.map);
  const client::MapInfo info = map.info();  // the light and the levels, public

  raster::RasterOptions ro;
  ro.width = width, ro.height = height, ro.device = a.device;
  ro.upload_budget_bytes = 8u << 20;
  ro.validation = a.validation;
  const std::vector<float> triangles = raster::flat_triangles(scene);
  raster::Rasterizer r(map, triangles, ro);

  std::filesystem::create_directories(a.out);
  const Aabb box = scene.bounds();
  const Vec3d centre = box.center(), ext = box.extent();
  const double radius = 0.75 * std::max(ext.x, ext.z);
  const client::WorldPoint c{centre.x, centre.y, centre.z};
  raster::FrameInput in;
  in.fov_deg = 0.9 * 180 / 3.14159265358979;  // 51.57 degrees
  in.kernel = a.pcf;
  in.filter = a.filter;
  in.texel = info.light.texel_size(c, info.finest_level);  // one finest texel (a spot's: at the centre)
  if (info.light.orthographic()) {
    const client::WorldPoint f = info.light.forward();
    in.light = {-f.x, -f.y, -f.z};
  } else {
    const client::WorldPoint o = info.light.origin();
    in.light = {o.x, o.y, o.z}, in.light_is_point = true;
  }
  auto write = [&](std::span<const raster::FrameResult> done) {
    for (const raster::FrameResult& f : done) {
      print(f);
      std::vector<Rgb8> img(size_t(width) * height);
      for (size_t i = 0; i < img.size(); ++i) img[i] = {f.rgba[4 * i], f.rgba[4 * i + 1], f.rgba[4 * i + 2]};
      char name[64];
      std::snprintf(name, sizeof(name), "/frame_%03llu.png", (unsigned long long)f.frame);
      write_png(a.out + name, width, height, img);
    }
  };
  std::printf("device '%s', %ux%u, %u frames\n", r.device_name().c_str(), width, height, a.frames);
  std::printf("%5s %10s %10s %12s %10s %9s %9s %9s %9s\n", "frame", "tile B", "page B", "feedback B", "fb tiles",
              "requested", "holes", "gpu ms", "shade ms");
  for (uint32_t f = 1; f <= a.frames; ++f) {
    const double angle = (a.orbit * double(f - 1) + 20.0) * 3.14159265358979 / 180.0;
    const Vec3d eye = centre + Vec3d{std::cos(angle) * radius, 0.55 * radius, std::sin(angle) * radius};
    in.eye = {eye.x, eye.y, eye.z};
    in.target = {centre.x, centre.y, centre.z};
    std::printf("frame %u: camera pos=%.3f,%.3f,%.3f,target=%.3f,%.3f,%.3f,fov=%.4f\n", f, eye.x, eye.y, eye.z, centre.x,
                centre.y, centre.z, in.fov_deg);
    write(r.render(in));
    std::this_thread::sleep_for(std::chrono::milliseconds(a.frame_ms));  // the game's frame time: tiles arrive
  }
  write(r.finish());
  std::printf("wrote %u frames to %s (%zu triangles); %llu waits for a ring slot\n", a.frames, a.out.c_str(),
              triangles.size() / 18, (unsigned long long)r.ring_waits());
  if (a.validation)
    std::printf("validation: %llu messages%s%s\n", (unsigned long long)r.validation_messages(),
                r.validation_messages() ? "; the first: " : "", r.first_validation_message().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(k + " needs a value");
      return argv[++i];
    };
    try {
      if (k == "--server") a.server = next();
      else if (k == "--map") a.map = next();
      else if (k == "--scene") a.scene = next();
      else if (k == "--size") a.size = next();
      else if (k == "--frames") a.frames = uint32_t(std::stoul(next()));
      else if (k == "--frame-ms") a.frame_ms = uint32_t(std::stoul(next()));
      else if (k == "--orbit") a.orbit = std::stod(next());
      else if (k == "--pcf") a.pcf = uint32_t(std::stoul(next()));
      else if (k == "--out") a.out = next();
      else if (k == "--device") a.device = next();
      else if (k == "--filter") a.filter = true;
      else if (k == "--validation") a.validation = true;
      else throw std::runtime_error("unknown option " + k);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "engine_raster: %s\n", e.what());
      return 2;
    }
  }
  if (a.server.empty() || a.map.empty() || a.scene.empty() || a.frames == 0) {
    std::fprintf(stderr, "usage: engine_raster --server HOST:PORT --map NAME --scene SPEC [--size WxH] [--frames N] ...\n");
    return 2;
  }
  try {
    return run(a);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "engine_raster: %s\n", e.what());
    return 1;
  }
}

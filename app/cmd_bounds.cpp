// shadowtile bounds: trace the dual depth bounds (MH §3.1) of one region of a shadow map
// and write them as an EXR (float32 lo/hi) plus a PNG preview beside it.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>

#include "scene/scene_limits.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "image/exr_io.hpp"
#include "image/png_io.hpp"
#include "scene/scene.hpp"
#include "app/scene_limits_option.hpp"
#include "app/command.hpp"
#include "common/error.hpp"

namespace st::cli {
namespace {

struct BoundsOptions {
  std::string scene, light, resolution, region, up, output;
  std::string scene_limits;  // --scene-limits (scene/scene_limits.hpp)
  uint32_t preview_size = 2048;
};

TraceRegion parse_trace_region(const std::string& text, uint32_t level) {
  const uint64_t side = uint64_t(1) << level;
  if (text.empty()) {
    if (side * side > DepthBoundsTracer::kMaxRegionTexels)
      throw Error("--resolution " + std::to_string(side) + " gives a " + std::to_string(side) +
                  "^2 map, more than the 8192^2 texels one call traces: use --region X,Y,W,H "
                  "(e.g. --region 0,0,8192,8192) and trace the map in parts");
    return {level, 0, 0, uint32_t(side), uint32_t(side)};
  }
  uint64_t v[4];
  std::stringstream ss(text);
  std::string tok;
  int n = 0;
  while (std::getline(ss, tok, ',')) {
    if (n == 4 || tok.empty() || tok.find_first_not_of("0123456789") != std::string::npos ||
        tok.size() > 8)
      throw Error("--region: '" + text + "' is not X,Y,W,H (four non-negative integers)");
    v[n++] = std::stoull(tok);
  }
  if (n != 4) throw Error("--region: '" + text + "' is not X,Y,W,H (four non-negative integers)");
  if (v[2] == 0 || v[3] == 0) throw Error("--region: width and height must be positive");
  if (v[0] + v[2] > side || v[1] + v[3] > side)
    throw Error("--region " + text + " leaves the " + std::to_string(side) + "^2 map");
  if (v[2] * v[3] > DepthBoundsTracer::kMaxRegionTexels)
    throw Error("--region " + text + " has more than 8192^2 texels: split it into smaller regions");
  return {level, v[0], v[1], uint32_t(v[2]), uint32_t(v[3])};
}

// Progress on a terminal for long runs: a watcher thread polls the tracer's counter (not
// progress.hpp's Progress, which the CLI's other commands use).
class TraceProgress {
 public:
  TraceProgress(uint64_t total, std::atomic<uint64_t>& done)
      : total_(total), done_(done), enabled_(isatty(STDERR_FILENO) && total >= (1u << 22)) {
    if (enabled_) thread_ = std::thread([this] { run(); });
  }
  ~TraceProgress() { stop(); }
  void stop() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
    std::fprintf(stderr, "\r%60s\r", "");
  }

 private:
  void run() {
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock<std::mutex> lock(mutex_);
    while (!cv_.wait_for(lock, std::chrono::milliseconds(500), [this] { return stop_; })) {
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const uint64_t d = done_.load(std::memory_order_relaxed);
      std::fprintf(stderr, "\rbounds: %5.1f%%  %.1f Mtexels/s", 100.0 * double(d) / double(total_),
                   s > 0 ? double(d) / s * 1e-6 : 0.0);
      std::fflush(stderr);
    }
  }
  uint64_t total_;
  std::atomic<uint64_t>& done_;
  bool enabled_;
  bool stop_ = false;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::thread thread_;
};

void run_bounds(const BoundsOptions& o) {
  const uint32_t level = parse_resolution(o.resolution);
  const TraceRegion region = parse_trace_region(o.region, level);
  const LightSpec spec = LightSpec::parse(o.light);
  SceneOptions so;
  so.up = parse_up_axis(o.up);
  if (o.output.empty()) throw Error("-o: an output .exr path is required");
  {  // fail before a long trace, not after it
    const auto dir = std::filesystem::path(o.output).parent_path();
    std::error_code ec;
    if (!dir.empty() && !std::filesystem::is_directory(dir, ec))
      throw Error("-o " + o.output + ": directory '" + dir.string() + "' does not exist");
  }

  const auto t0 = std::chrono::steady_clock::now();
  Scene scene = load_scene(o.scene, so, parse_scene_limits(o.scene_limits));
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%s\n", summary(scene).c_str());
  const LightSpace light = LightSpace::fit(spec, scene.bounds());
  DepthBoundsTracer tracer(scene, light);
  std::printf("embree scene: %llu triangles built in %.3f s; exit depths %s\n",
              (unsigned long long)tracer.triangle_count(), tracer.build_seconds(),
              tracer.traces_exit_depths() ? "traced (closed meshes present)"
                                          : "skipped (no closed mesh: hi = lo)");

  std::atomic<uint64_t> done{0};
  DepthBoundsStats st;
  IntervalTile tile;
  {
    TraceProgress progress(uint64_t(region.width) * region.height, done);
    tile = tracer.trace(region, TraceMode::bounds, &st, &done);
  }
  write_interval_exr(o.output, tile, {spec.to_string(), light});
  std::string preview;
  if (o.preview_size > 0) {
    preview = std::filesystem::path(o.output).replace_extension(".png").string();
    write_depth_preview_png(preview, tile, o.preview_size);
  }
  const double texels = double(st.texels);
  std::printf("region %llu,%llu,%u,%u of the %llu^2 map (level %u): %.0f texels\n",
              (unsigned long long)region.x0, (unsigned long long)region.y0, region.width,
              region.height, (unsigned long long)(uint64_t(1) << level), level, texels);
  std::printf("hit %.2f%%  closed (hi > lo) %.2f%%  fallbacks (hi = lo) %llu\n",
              100.0 * double(st.hits) / texels, 100.0 * double(st.closed) / texels,
              (unsigned long long)st.fallbacks);
  std::printf("load %.3f s  build %.3f s  trace %.3f s: %.2f Mrays/s, %.2f Mtexels/s, "
              "%.2f traversals per texel\n",
              load_s, tracer.build_seconds(), st.seconds, double(st.rays) / st.seconds * 1e-6,
              texels / st.seconds * 1e-6, double(st.traversals) / texels);
  std::printf("wrote %s%s%s\n", o.output.c_str(), preview.empty() ? "" : " and ", preview.c_str());
}

void setup_bounds(CLI::App& sub) {
  auto o = std::make_shared<BoundsOptions>();
  sub.add_option("scene", o->scene,
                 "Scene file (any format assimp reads) or procedural:NAME[,key=value...], "
                 "e.g. procedural:city")
      ->required();
  sub.add_option("--light", o->light,
                 "Light: sun:azimuth=DEG,elevation=DEG[,margin=F] or "
                 "spot:pos=X,Y,Z,target=X,Y,Z,fov=DEG")
      ->required();
  sub.add_option("--resolution", o->resolution,
                 "Map resolution, a power of two: 4096, 16k, 1m (at most 1m = 2^20)")
      ->required();
  sub.add_option("--region", o->region,
                 "Texels X,Y,W,H of the map to trace (default: the whole map; at most "
                 "8192^2 texels per call, so larger maps need --region)");
  add_scene_file_options(sub, o->up, o->scene_limits);
  sub.add_option("-o,--output", o->output,
                 "Output EXR (channels lo, hi as float32); a PNG preview is written beside "
                 "it with the same stem")
      ->required();
  sub.add_option("--preview-size", o->preview_size,
                 "Largest side of the PNG preview in pixels (point-sampled; 0: no preview)")
      ->capture_default_str();
  sub.footer(
      "Traces per texel lo = first hit and hi = where the ray leaves all closed objects\n"
      "(hi = lo for open geometry; texels without a hit are lit: lo = hi = 1).\n"
      "Example:\n"
      "  shadowtile bounds procedural:city --light sun:azimuth=30,elevation=50 \\\n"
      "      --resolution 16k --region 4096,4096,4096,4096 -o city_r.exr\n"
      "writes city_r.exr and city_r.png and prints hit/closed fractions and Mtexels/s.");
  sub.callback([o] { run_bounds(*o); });
}

const Register reg_bounds{"bounds", "Trace dual depth bounds (lo, hi) of a shadow-map region to EXR",
                          setup_bounds};

}  // namespace
}  // namespace st::cli

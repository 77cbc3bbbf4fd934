// shadowtile export: decodes a region of any level of a pack back to an image.
#include <cstdio>
#include <thread>

#include "tiles/bake/exr_io.hpp"
#include "tiles/bake/png_io.hpp"
#include "app/command.hpp"
#include "app/pack_cli_util.hpp"
#include "common/error.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st::cli {
namespace {

struct ExportArgs {
  std::string pack, region, out;
  uint32_t level = 0;
  bool level_set = false;
};

void run(const ExportArgs& a) {
  std::shared_ptr<const PackReader> reader = PackReader::open(a.pack);
  reader->check_depth_range();  // coarse levels are decoded as they lie: refuse garbage
  const uint32_t level = a.level_set ? a.level : std::min<uint32_t>(reader->map_level(), 12);
  if (level > reader->map_level())
    throw Error("--level " + std::to_string(level) + " exceeds the pack's finest level " +
                std::to_string(reader->map_level()));
  const uint64_t side = uint64_t(1) << level;
  Rect r{0, 0, side, side};
  if (!a.region.empty()) r = parse_rect("--region", a.region);
  if (r.w == 0 || r.h == 0 || r.x >= side || r.y >= side || r.w > side - r.x || r.h > side - r.y)
    throw Error("--region lies outside the " + std::to_string(side) + "^2 map of level " +
                std::to_string(level));
  if (r.w * r.h > uint64_t(8192) * 8192)
    throw Error("export: region " + std::to_string(r.w) + "x" + std::to_string(r.h) +
                " exceeds 8192^2 texels; pass a smaller --region or a coarser --level");
  PackEvaluator eval(reader, 4096);
  IntervalTile t;
  t.level = level, t.x0 = r.x, t.y0 = r.y, t.width = uint32_t(r.w), t.height = uint32_t(r.h);
  t.data.resize(r.w * r.h);
  const unsigned n = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> workers;
  std::exception_ptr failure;
  std::mutex mu;
  for (unsigned k = 0; k < n; ++k)
    workers.emplace_back([&, k]() {
      try {
        for (uint64_t j = k; j < r.h; j += n)
          for (uint64_t i = 0; i < r.w; ++i) {
            float v = eval.depth(level, r.x + i, r.y + j);
            t.data[j * r.w + i] = {v, v};
          }
      } catch (...) {
        std::lock_guard lock(mu);
        if (!failure) failure = std::current_exception();
      }
    });
  for (auto& w : workers) w.join();
  if (failure) std::rethrow_exception(failure);
  ExrLightInfo info;
  info.spec = reader->light().spec().to_string();
  info.space = reader->light();
  write_interval_exr(a.out, t, info);
  std::string png = a.out;
  auto dot = png.rfind('.');
  png = (dot == std::string::npos ? png : png.substr(0, dot)) + ".png";
  write_depth_preview_png(png, t);
  std::printf("exported level %u region %llu,%llu,%llux%llu of %s to %s (channels lo = hi = the "
              "decoded depth) and %s\n",
              level, (unsigned long long)r.x, (unsigned long long)r.y, (unsigned long long)r.w,
              (unsigned long long)r.h, a.pack.c_str(), a.out.c_str(), png.c_str());
}

void setup(CLI::App& app) {
  auto a = std::make_shared<ExportArgs>();
  app.footer("Example:\n  shadowtile export city.pack --level 12 -o city_l12.exr\n"
             "  shadowtile export city.pack --level 16 --region 30000,30000,2048,2048 -o detail.exr");
  app.add_option("pack", a->pack, "Pack file")->required();
  app.add_option("--level", a->level, "Level to decode (each level is a complete map; default min(L, 12))")
      ->each([a](const std::string&) { a->level_set = true; });
  app.add_option("--region", a->region, "X,Y,W,H in texels of that level (default: the whole level)");
  app.add_option("-o,--output", a->out, "EXR to write (a PNG preview is written beside it)")->required();
  app.callback([a]() { run(*a); });
}

Register reg{"export", "Decode a region of any level of a pack back to an EXR image", setup};

}  // namespace
}  // namespace st::cli

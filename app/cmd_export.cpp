// shadowtile export: decodes a region of any level of a pack back to an image; with
// --deep, samples a scene's partial occluders into a deep shadow map (DSM 2000 §3.1-§3.3)
// and writes it as a deep scanline OpenEXR (tiles/bake/deep_exr.hpp).
#include <chrono>
#include <cstdio>

#include "scene/scene_limits.hpp"
#include "tiles/bake/deep_exr.hpp"
#include "image/exr_io.hpp"
#include "image/png_io.hpp"
#include "app/scene_limits_option.hpp"
#include "app/command.hpp"
#include "app/pack_cli_util.hpp"
#include "app/stack_cli.hpp"
#include "tiles/core/stack_grid.hpp"
#include "common/error.hpp"
#include "common/parallel.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st::cli {
namespace {

// --region (default: the whole map) checked against the map of `level`.
Rect region_of(const std::string& region, uint32_t level) {
  const uint64_t side = uint64_t(1) << level;
  Rect r{0, 0, side, side};
  if (!region.empty()) r = parse_rect("--region", region);
  if (r.w == 0 || r.h == 0 || r.x >= side || r.y >= side || r.w > side - r.x || r.h > side - r.y)
    throw Error("--region lies outside the " + std::to_string(side) + "^2 map of level " +
                std::to_string(level));
  return r;
}

struct ExportArgs {
  std::string scene_limits;  // --scene-limits (scene/scene_limits.hpp)
  std::string pack, region, out;
  uint32_t level = 0;
  bool level_set = false;
  // --deep
  bool deep = false;
  std::string light, up;
  uint32_t samples = 4;
  double epsilon = -1;
  uint64_t seed = 1;
  std::optional<uint32_t> slice;  // stack packs
};

constexpr uint64_t kMaxDeepRegion = uint64_t(1024) * 1024;  // functions held in memory

void run_deep(const ExportArgs& a) {
  if (a.light.empty()) throw Error("export --deep: --light is required");
  const LightSpec spec = LightSpec::parse(a.light);
  SceneOptions so;
  so.up = parse_up_axis(a.up);
  const uint32_t level = a.level_set ? a.level : 8;
  if (level > kMaxLevel) throw Error("--level " + std::to_string(level) + " exceeds " + std::to_string(kMaxLevel));
  const Rect r = region_of(a.region, level);
  if (r.w * r.h > kMaxDeepRegion)
    throw Error("export --deep: region " + std::to_string(r.w) + "x" + std::to_string(r.h) +
                " exceeds 1024^2 texels; pass a smaller --region or a coarser --level");
  const Scene scene = load_scene(a.pack, so, parse_scene_limits(a.scene_limits));
  if (!scene.any_partial())
    throw Error("export --deep: scene '" + a.pack +
                "' has no partial occluder (no transmittance, alpha texture or volume): "
                "its shadows are all in the opaque map");
  // The light is fitted to the whole scene, as `build` fits the opaque map's.
  const LightSpace light = LightSpace::fit(spec, scene.bounds());
  const DeepSampler sampler(scene, light);
  DeepSampleOptions o;
  o.samples_per_side = a.samples;
  o.epsilon = a.epsilon;
  o.seed = a.seed;
  DeepSampleStats st;
  const DeepRegion deep = sampler.trace({level, r.x, r.y, uint32_t(r.w), uint32_t(r.h)}, o, &st);
  DeepExrInfo info;  // what `build --deep-from` checks the file against
  info.epsilon = o.effective_epsilon();
  info.samples_per_side = o.samples_per_side;
  info.light = spec.to_string();
  char hash[20];
  std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)scene.content_hash());
  info.scene_hash = hash;
  write_deep_exr(a.out, deep, info);
  std::printf("exported deep level %u region %llu,%llu,%llux%llu of %s to %s: %llu rays, "
              "%.2f vertices per texel (%.2f before compression at epsilon %.4g), %llu of %llu "
              "texels monochrome, %.2f s\n",
              level, (unsigned long long)r.x, (unsigned long long)r.y, (unsigned long long)r.w,
              (unsigned long long)r.h, a.pack.c_str(), a.out.c_str(), (unsigned long long)st.rays,
              double(st.vertices_out) / double(st.texels), double(st.vertices_in) / double(st.texels),
              o.effective_epsilon(), (unsigned long long)st.monochrome,
              (unsigned long long)st.texels, st.seconds);
}

void run_export(const ExportArgs& a) {
  if (a.deep) return run_deep(a);
  if (a.slice) return export_stack_slice(a.pack, *a.slice, a.level_set ? std::optional(a.level) : std::nullopt, a.out);
  std::shared_ptr<const PackReader> reader = PackReader::open(a.pack);
  if (reader->stack()) throw Error("export: '" + a.pack + "' is a stack pack: pass --slice W (0.." +
                                   std::to_string(reader->stack()->slices - 1) + ")");
  reader->check_depth_range();  // coarse levels are decoded as they lie: refuse garbage
  const uint32_t level = a.level_set ? a.level : std::min<uint32_t>(reader->map_level(), 12);
  if (level > reader->map_level())
    throw Error("--level " + std::to_string(level) + " exceeds the pack's finest level " +
                std::to_string(reader->map_level()));
  const Rect r = region_of(a.region, level);
  if (r.w * r.h > uint64_t(8192) * 8192)
    throw Error("export: region " + std::to_string(r.w) + "x" + std::to_string(r.h) +
                " exceeds 8192^2 texels; pass a smaller --region or a coarser --level");
  PackEvaluator eval(reader, 4096);
  IntervalTile t;
  t.level = level, t.x0 = r.x, t.y0 = r.y, t.width = uint32_t(r.w), t.height = uint32_t(r.h);
  t.data.resize(r.w * r.h);
  for_each_index(r.h, 0, [&](size_t j) {
    for (uint64_t i = 0; i < r.w; ++i) {
      const float v = eval.depth(level, r.x + i, r.y + j);
      t.data[j * r.w + i] = {v, v};
    }
  });
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

void setup_export(CLI::App& app) {
  auto a = std::make_shared<ExportArgs>();
  app.footer("Example:\n  shadowtile export city.pack --level 12 -o city_l12.exr\n"
             "  shadowtile export city.pack --level 16 --region 30000,30000,2048,2048 -o detail.exr\n"
             "  shadowtile export --deep procedural:forest --light sun:azimuth=30,elevation=50 --level 8 -o forest_deep.exr\n"
             "  (then: shadowtile build procedural:forest --light sun:azimuth=30,elevation=50 --deep-from forest_deep.exr "
             "-o forest.pack)");
  app.add_option("pack", a->pack, "Pack file (with --deep: a scene file or procedural:NAME)")->required();
  app.add_flag("--deep", a->deep,
               "Sample the scene's partial occluders (transmittance, alpha textures, volumes) "
               "into a deep shadow map and write a deep scanline EXR (Z, ZBack, A or AR/AG/AB); "
               "default --level 8");
  app.add_option("--light", a->light, "With --deep: the light, as for build");
  app.add_option("--samples", a->samples, "With --deep: jittered samples per texel side (N = S^2, 1..64; default 4)");
  app.add_option("--epsilon", a->epsilon, "With --deep: compression bound (default 0.25 / sqrt(N), DSM 2000 §4)");
  app.add_option("--seed", a->seed, "With --deep: jitter seed (default 1)");
  add_scene_file_options(app, a->up, a->scene_limits, "With --deep: ");
  app.add_option("--level", a->level, "Level to decode (each level is a complete map; default min(L, 12))")
      ->each([a](const std::string&) { a->level_set = true; });
  app.add_option("--slice", a->slice, "Stack packs: the slice W (light sample) to export");
  app.add_option("--region", a->region, "X,Y,W,H in texels of that level (default: the whole level)");
  app.add_option("-o,--output", a->out, "EXR to write (a PNG preview is written beside it)")->required();
  app.callback([a]() { run_export(*a); });
}

Register reg_export{"export", "Decode a region of any level of a pack back to an EXR image", setup_export};

}  // namespace
}  // namespace st::cli

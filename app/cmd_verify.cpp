// shadowtile verify: checks a pack end to end. Every byte's checksum and every tile's
// structure (PackReader::verify), then re-traces random texels with Embree and checks the
// lossless invariant lo <= v <= hi on each (ARCHITECTURE.md "Definitions").
#include <cstdio>
#include <vector>

#include "common/hash.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/scene.hpp"
#include "app/command.hpp"
#include "app/pack_cli_util.hpp"
#include "common/error.hpp"
#include "tiles/core/pack_evaluator.hpp"

namespace st::cli {
namespace {

struct VerifyArgs {
  std::string pack, scene, up = "y";
  uint64_t samples = 1000000, seed = 1;
  uint32_t show = 10;
};

void run(const VerifyArgs& a) {
  std::shared_ptr<const PackReader> reader = PackReader::open(a.pack);
  const Encoding enc = reader->encoding();
  try {
    reader->verify([enc](std::span<const uint8_t> b) { return open_encoded(enc, b); });
    reader->check_depth_range();
  } catch (const FormatError& e) {
    std::printf("verify %s: FAILED structure/checksum check: %s\n", a.pack.c_str(), e.what());
    exit_with(kExitMismatch);
  }
  std::printf("verify %s: all %zu tiles, checksums and the page table are intact\n", a.pack.c_str(),
              reader->tiles().size());

  SceneOptions so;
  so.up = a.up == "z" ? UpAxis::z : UpAxis::y;
  Scene scene = load_scene(a.scene, so);
  if (scene.content_hash() != reader->header().scene_hash)
    std::printf("warning: the scene's hash differs from the one the pack was built from\n");
  const LightSpace light = reader->light();
  DepthBoundsTracer tracer(scene, light);
  PackEvaluator eval(reader, 1024);
  const uint32_t L = reader->map_level();
  const Rect region = built_region(*reader);

  // Samples in 8x8 blocks (coherent packets), at random positions inside the built region.
  constexpr uint32_t kBlock = 8;
  uint64_t rng = a.seed, checked = 0, bad = 0;
  const uint64_t blocks = (a.samples + kBlock * kBlock - 1) / (kBlock * kBlock);
  for (uint64_t b = 0; b < blocks; ++b) {
    uint32_t bw = uint32_t(std::min<uint64_t>(kBlock, region.w));
    uint32_t bh = uint32_t(std::min<uint64_t>(kBlock, region.h));
    uint64_t x0 = region.x + splitmix64(rng) % (region.w - bw + 1);
    uint64_t y0 = region.y + splitmix64(rng) % (region.h - bh + 1);
    IntervalTile t = tracer.trace({L, x0, y0, bw, bh});
    for (uint32_t j = 0; j < bh; ++j)
      for (uint32_t i = 0; i < bw; ++i) {
        const Interval iv = t.at(i, j);
        float v = 0;
        try {
          v = eval.depth(L, x0 + i, y0 + j);
        } catch (const FormatError& e) {
          std::printf("verify: FAILED reading texel (%llu, %llu): %s\n", (unsigned long long)(x0 + i),
                      (unsigned long long)(y0 + j), e.what());
          exit_with(kExitMismatch);
        }
        ++checked;
        if (!(iv.lo <= v && v <= iv.hi)) {
          if (bad < a.show)
            std::printf("mismatch: texel (%llu, %llu) of level %u: stored %.9g outside [%.9g, %.9g]\n",
                        (unsigned long long)(x0 + i), (unsigned long long)(y0 + j), L, v, iv.lo, iv.hi);
          ++bad;
        }
      }
  }
  if (bad) {
    std::printf("verify %s: FAILED: %llu of %llu sampled texels break the lossless invariant\n",
                a.pack.c_str(), (unsigned long long)bad, (unsigned long long)checked);
    exit_with(kExitMismatch);
  }
  std::printf("verify %s: OK: %llu random texels re-traced, every one within [lo, hi]\n", a.pack.c_str(),
              (unsigned long long)checked);
}

void setup(CLI::App& app) {
  auto a = std::make_shared<VerifyArgs>();
  app.footer("Exit code 3 when a checksum, a tile or a texel fails.\nExample:\n"
             "  shadowtile verify city.pack procedural:city --samples 1000000");
  app.add_option("pack", a->pack, "Pack file")->required();
  app.add_option("scene", a->scene, "The scene the pack was built from")->required();
  app.add_option("--samples", a->samples, "Random texels to re-trace")->capture_default_str();
  app.add_option("--seed", a->seed, "Seed of the sample positions")->capture_default_str();
  app.add_option("--show", a->show, "Mismatches to print")->capture_default_str();
  app.add_option("--up", a->up, "Up axis of the scene file: y or z")->capture_default_str();
  app.callback([a]() { run(*a); });
}

Register reg{"verify", "Check a pack's checksums and re-trace random texels against it (lossless)", setup};

}  // namespace
}  // namespace st::cli

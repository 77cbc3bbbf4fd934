// shadowtile verify: checks a pack end to end. Every byte's checksum and every tile's
// structure (PackReader::verify), then re-traces random texels (or, with --all, every
// texel of the built region) with the builder the pack records (the light-space
// rasterizer or Embree; --builder overrides) and checks the lossless invariant lo <= v <= hi
// on each (ARCHITECTURE.md "Definitions"). The re-trace gives the same canonical bounds
// as the build whatever its batching (tiles/bake/canonical_depth.hpp). A vsdag pack is
// checked against its own exactness contract instead (tiles/core/VSDAG.md: exact beyond
// one depth slab of lo and hi), at the depth resolution its build recorded.
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include "common/hash.hpp"
#include "common/parallel.hpp"
#include "scene/scene_limits.hpp"
#include "tiles/bake/deep_sampler.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "scene/scene.hpp"
#include "app/scene_limits_option.hpp"
#include "app/command.hpp"
#include "app/pack_cli_util.hpp"
#include "common/error.hpp"
#include "app/progress.hpp"
#include "app/stack_cli.hpp"
#include "tiles/core/coarse_hulls.hpp"
#include "tiles/core/deep_pack.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/vsdag_format.hpp"

namespace st::cli {
namespace {

struct VerifyArgs {
  std::string pack, scene, up, builder = "pack";
  std::string scene_limits;  // --scene-limits (scene/scene_limits.hpp)
  uint64_t samples = 1000000, seed = 1;
  uint32_t show = 10;
  bool all = false;
  uint64_t max_mismatches = 10;
  uint64_t cells = 0;          // --all --cells N: N random aligned squares instead of the whole region
  uint32_t cell_side = 256;
};

// What a stored value must satisfy against the re-traced interval: the lossless
// invariant lo <= v <= hi, or for vsdag tiles their slab contract.
struct Contract {
  uint32_t vsdag_z_bits = 0;  // 0: the lossless invariant
  bool holds(const Interval& iv, float v) const {
    return vsdag_z_bits ? vsdag::depth_within_contract(iv.lo, iv.hi, v, vsdag_z_bits) : iv.lo <= v && v <= iv.hi;
  }
  std::string within() const {
    return vsdag_z_bits ? "within one of 2^" + std::to_string(vsdag_z_bits) + " depth slabs of [lo, hi] (vsdag contract)"
                        : "within [lo, hi]";
  }
  std::string name() const {
    return vsdag_z_bits ? "the vsdag contract (within one of 2^" + std::to_string(vsdag_z_bits) + " depth slabs of [lo, hi])"
                        : "the lossless invariant";
  }
};

Contract contract_of(const PackReader& reader) {
  Contract c;
  if (reader.encoding() != Encoding::vsdag) return c;
  for (const auto& [k, v] : reader.params())
    if (k == "depth_bits") {
      char* end = nullptr;
      const unsigned long z = std::strtoul(v.c_str(), &end, 10);
      if (end == v.c_str() || *end != 0 || z < vsdag::kMinZBits || z > vsdag::kMaxZBits)
        throw Error("verify: the pack's build parameter depth_bits='" + v + "' is not a vsdag depth resolution (3..20)");
      c.vsdag_z_bits = uint32_t(z);
      return c;
    }
  throw Error("verify: this vsdag pack records no depth_bits build parameter, so its contract cannot be checked");
}

// --all: every texel of the built region, traced in chunks of kChunk^2 texels (the tracer
// parallelises each chunk), each chunk's texels checked on every hardware thread; stops
// after `max_mismatches` mismatches and prints their coordinates. Returns the number of
// mismatches found; `checked` receives the texels checked.
using TraceFn = std::function<IntervalTile(const TraceRegion&)>;

// The re-traced intervals' hulls per skip-grid cell, for the check of the skip grid's
// entries and coarse levels (coarse_hulls.hpp): a finished pack keeps no cell intervals,
// so --all recomputes them from the texels it traces anyway. A cell counts once every
// one of its texels was traced.
struct TracedHulls {
  CellHulls hulls;
  std::vector<uint64_t> texels;  // traced texels per cell
  uint32_t shift;                // log2 of a cell's side in texels: L - K
  TracedHulls(uint32_t k, uint32_t L) : hulls(k), texels(size_t(1) << (2 * k), 0), shift(L - k) {}
  void add(const IntervalTile& t, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h) {
    const size_t side = hulls.side();
    for (uint32_t j = 0; j < h; ++j)
      for (uint32_t i = 0; i < w; ++i) {
        const Interval iv = t.at(i, j);
        const size_t c = size_t((y0 + j) >> shift) * side + size_t((x0 + i) >> shift);
        hulls.lo[c] = std::min(hulls.lo[c], iv.lo);
        hulls.hi[c] = std::max(hulls.hi[c], iv.hi);
        ++texels[c];
      }
  }
  const CellHulls& finish() {
    const uint64_t full = uint64_t(1) << (2 * shift);
    // >=: --cells squares may repeat; they are used only when they cover whole cells.
    for (size_t c = 0; c < texels.size(); ++c) hulls.known[c] = texels[c] >= full;
    return hulls;
  }
};

// One texel's check (--all's rows and the random blocks): the stored depth of texel (x, y)
// of level L against its re-traced interval. A read error sets `error` ("texel (x, y): why").
enum class TexelCheck { holds, mismatch, unreadable };
TexelCheck check_texel(const PackEvaluator& eval, const Contract& contract, uint32_t L, uint64_t x, uint64_t y,
                       const Interval& iv, float& v, std::string& error) {
  try {
    v = eval.depth(L, x, y);
  } catch (const FormatError& e) {
    error = "texel (" + std::to_string(x) + ", " + std::to_string(y) + "): " + e.what();
    return TexelCheck::unreadable;
  }
  return contract.holds(iv, v) ? TexelCheck::holds : TexelCheck::mismatch;
}
void print_mismatch(uint64_t x, uint64_t y, uint32_t L, float v, const Interval& iv) {
  std::printf("mismatch: texel (%llu, %llu) of level %u: stored %.9g outside [%.9g, %.9g]\n", (unsigned long long)x,
              (unsigned long long)y, L, v, iv.lo, iv.hi);
}

// `progress` counts from `done_before` towards `grand_total` (several regions share one bar).
uint64_t verify_every_texel(const VerifyArgs& a, const TraceFn& trace,
                            const Contract& contract, const PackEvaluator& eval, uint32_t L, const Rect& region,
                            uint64_t& checked, Progress& progress, uint64_t done_before, uint64_t grand_total,
                            TracedHulls* hulls) {
  constexpr uint64_t kChunk = 1024;
  std::atomic<uint64_t> bad{0};
  std::mutex print;
  std::string read_error;
  checked = 0;
  for (uint64_t cy = region.y; cy < region.y + region.h && bad < a.max_mismatches; cy += kChunk)
    for (uint64_t cx = region.x; cx < region.x + region.w && bad < a.max_mismatches; cx += kChunk) {
      const uint32_t w = uint32_t(std::min(kChunk, region.x + region.w - cx));
      const uint32_t h = uint32_t(std::min(kChunk, region.y + region.h - cy));
      const IntervalTile t = trace({L, cx, cy, w, h});
      st::for_each_index(h, 0, [&](size_t row) {
        const uint32_t j = uint32_t(row);
        if (bad >= a.max_mismatches) return;
        for (uint32_t i = 0; i < w; ++i) {
          const Interval iv = t.at(i, j);
          float v = 0;
          std::string error;
          const TexelCheck r = check_texel(eval, contract, L, cx + i, cy + j, iv, v, error);
          if (r == TexelCheck::holds) continue;
          std::lock_guard lock(print);
          if (r == TexelCheck::unreadable) {
            if (read_error.empty()) read_error = std::move(error);
            bad = a.max_mismatches;
            return;
          }
          if (bad >= a.max_mismatches) return;
          print_mismatch(cx + i, cy + j, L, v, iv);
          ++bad;
        }
      });
      if (hulls) hulls->add(t, cx, cy, w, h);
      checked += uint64_t(w) * h;
      progress.update(done_before + checked, grand_total, done_before + checked);
    }
  if (!read_error.empty()) {
    std::printf("verify: FAILED reading %s\n", read_error.c_str());
    exit_with(kExitMismatch);
  }
  return bad;
}

// The deep part (tiles/PACK.md "Deep tiles"): `count` random texels of the deep map,
// half in stored tiles, sampled afresh (the build's samples and seed, uncompressed) and
// compared with the stored mip-0 function: within the directory's epsilon plus the
// unorm16 rounding. Returns the texels beyond it.
uint64_t verify_deep(const VerifyArgs& a, const PackReader& reader, const Scene& scene, uint64_t count) {
  const auto deep = PackDeepMap::load(reader);
  const DeepDirectory& dir = deep->directory();
  DeepSampler sampler(scene, reader.light());
  DeepSampleOptions o;
  o.samples_per_side = dir.samples_per_side;
  o.epsilon = dir.epsilon;
  const double bound = double(dir.epsilon) + deep::kQuantisation + 1e-6;
  std::vector<std::pair<uint32_t, uint32_t>> stored;
  for (uint32_t ty = 0; ty < dir.tiles_per_side(); ++ty)
    for (uint32_t tx = 0; tx < dir.tiles_per_side(); ++tx)
      if (dir.has(tx, ty)) stored.emplace_back(tx, ty);
  uint64_t rng = a.seed ^ 0xdeeb, bad = 0;
  double worst = 0;
  const uint32_t side = 1u << dir.side_bits, n = 1u << dir.level;
  for (uint64_t i = 0; i < count; ++i) {
    uint32_t x, y;
    if (i % 2 == 0) {
      const auto [tx, ty] = stored[splitmix64(rng) % stored.size()];
      x = tx * side + uint32_t(splitmix64(rng) % side), y = ty * side + uint32_t(splitmix64(rng) % side);
    } else {
      x = uint32_t(splitmix64(rng) % n), y = uint32_t(splitmix64(rng) % n);
    }
    const VisibilityFunction fresh = sampler.texel(dir.level, x, y, o, false);
    const uint32_t tx = x >> dir.side_bits, ty = y >> dir.side_bits;
    VisibilityFunction kept;  // empty (1 everywhere) where no tile is stored
    if (dir.has(tx, ty)) {
      const std::vector<uint8_t> raw = reader.read_raw(dir.tile_id(tx, ty));
      kept = DeepTileView::open(raw).function(x - tx * side, y - ty * side, 0);
    }
    const double d = max_difference(kept, fresh);
    worst = std::max(worst, d);
    if (d > bound) {
      if (bad < a.show)
        std::printf("mismatch: deep texel (%u, %u) of level %u differs from a fresh sample by %.6f > %.6f\n", x, y,
                    dir.level, d, bound);
      ++bad;
    }
  }
  std::printf("verify: deep map: %llu texels sampled afresh, largest difference %.6f (bound %.6f)\n",
              (unsigned long long)count, worst, bound);
  return bad;
}

void run_verify(const VerifyArgs& a) {
  std::shared_ptr<const PackReader> reader = PackReader::open(a.pack);
  if (reader->stack()) return verify_stack_pack(a.pack, a.scene, a.up, a.max_mismatches);
  try {
    reader->verify(reader->tile_opener());  // with the pack's DAG-MH dictionary, if any
    reader->check_depth_range();
  } catch (const FormatError& e) {
    std::printf("verify %s: FAILED structure/checksum check: %s\n", a.pack.c_str(), e.what());
    exit_with(kExitMismatch);
  }
  std::printf("verify %s: all %zu tiles, checksums and the page table are intact\n", a.pack.c_str(),
              reader->tiles().size());

  SceneOptions so;
  so.up = parse_up_axis(a.up);
  Scene scene = load_scene(a.scene, so, parse_scene_limits(a.scene_limits));
  if (reader->deep_directory()) {
    // The deep part against the scene's partial occluders; the opaque map against the rest.
    if (verify_deep(a, *reader, scene, std::min<uint64_t>(a.samples, 256))) {
      std::printf("verify %s: FAILED: deep texels beyond the deep map's bound\n", a.pack.c_str());
      exit_with(kExitMismatch);
    }
    scene = opaque_part(scene);
  }
  if (scene.content_hash() != reader->header().scene_hash)
    std::printf("warning: the scene's hash differs from the one the pack was built from\n");
  const LightSpace light = reader->light();
  PackEvaluator eval(reader, 1024);
  const uint32_t L = reader->map_level();
  const Rect region = built_region(*reader);
  // A pack of static-geometry intervals is checked under its own contract: its intervals
  // are re-traced the same way (lossless for receivers on surfaces).
  const bool static_intervals = (reader->header().flags & kFeatureStaticIntervals) != 0;
  const TraceMode mode = static_intervals ? TraceMode::static_bounds : TraceMode::bounds;
  if (static_intervals)
    std::printf("verify: static-geometry intervals: lossless for receivers that lie on surfaces\n");
  const Contract contract = contract_of(*reader);
  // Re-trace with the builder the pack was built with (its build parameter `builder`;
  // packs from before it were built by Embree), or the one --builder names.
  std::string recorded = "embree";
  for (const auto& [k, v] : reader->params())
    if (k == "builder") recorded = v;
  const BoundsBuilder builder = resolve_builder(
      parse_bounds_builder(a.builder == "pack" ? recorded : a.builder), light,
      static_intervals ? IntervalRule::static_geometry : IntervalRule::closed_objects);
  std::unique_ptr<RasterBounds> raster;
  std::unique_ptr<DepthBoundsTracer> tracer;
  TraceFn trace;
  if (builder == BoundsBuilder::raster) {
    // Without the per-tile skip: the check does not lean on the skip's own proof. Under
    // the pack's own interval rule, as the Embree branch below.
    raster = std::make_unique<RasterBounds>(scene, light, RasterSkip::off, mode);
    trace = [&](const TraceRegion& r) { return raster->trace(r); };
  } else {
    tracer = std::make_unique<DepthBoundsTracer>(scene, light);
    trace = [&](const TraceRegion& r) { return tracer->trace(r, mode); };
  }
  std::printf("verify: re-tracing with the %s builder\n", to_string(builder));
  for (const auto& [k, v] : reader->params())
    if (k == "intervals_narrowed" && v == "yes")
      std::printf("verify: built with narrowed intervals (--raster-skip narrow): stored values are checked "
                  "against the true intervals; its answers may differ from an unnarrowed build's "
                  "only where both are lossless\n");
  if (contract.vsdag_z_bits) std::printf("verify: checking %s\n", contract.name().c_str());

  // The skip grid's entries and coarse levels against the hulls of the re-traced texels
  // (the vsdag contract quantises depths, so its grid is not held to the intervals).
  std::unique_ptr<TracedHulls> hulls;
  if (a.all && !contract.vsdag_z_bits) hulls = std::make_unique<TracedHulls>(reader->grid().levels, L);
  auto check_grid = [&] {
    if (!hulls) return;
    try {
      const uint64_t n = check_coarse_hulls(reader->grid(), hulls->finish(), a.pack);
      std::printf("verify: %llu skip grid values (cell entries and coarse levels over fully re-traced cells) lie "
                  "in the hulls of the intervals below them\n",
                  (unsigned long long)n);
    } catch (const FormatError& e) {
      std::printf("verify %s: FAILED: %s\n", a.pack.c_str(), e.what());
      exit_with(kExitMismatch);
    }
  };

  if (a.all && a.cells) {
    // Every texel of `cells` random squares of cell_side^2, aligned to their side, inside
    // the built region (seeded: --seed).
    const uint64_t s = a.cell_side;
    if (s == 0 || (s & (s - 1)) || s > region.w || s > region.h)
      throw Error("verify: --cell-side " + std::to_string(s) + " must be a power of two no larger than the built region (" +
                  std::to_string(region.w) + " x " + std::to_string(region.h) + ")");
    const uint64_t nx = region.w / s, ny = region.h / s;
    if (hulls && s < (uint64_t(1) << hulls->shift)) hulls.reset();  // squares smaller than a cell
    uint64_t rng = a.seed, checked = 0, bad = 0;
    Progress progress("verify", "texels");
    for (uint64_t c = 0; c < a.cells && bad < a.max_mismatches; ++c) {
      const Rect sq{region.x + (splitmix64(rng) % nx) * s, region.y + (splitmix64(rng) % ny) * s, s, s};
      uint64_t n = 0;
      bad += verify_every_texel(a, trace, contract, eval, L, sq, n, progress, checked, a.cells * s * s, hulls.get());
      checked += n;
    }
    progress.finish();
    if (bad) {
      std::printf("verify %s: FAILED: %llu texels break %s (stopped after %llu texels of %llu squares of %llu^2)\n",
                  a.pack.c_str(), (unsigned long long)bad, contract.name().c_str(), (unsigned long long)checked,
                  (unsigned long long)a.cells, (unsigned long long)s);
      exit_with(kExitMismatch);
    }
    check_grid();
    std::printf("verify %s: OK: every texel of %llu random %llu^2 squares (%llu texels) re-traced, every one %s\n",
                a.pack.c_str(), (unsigned long long)a.cells, (unsigned long long)s, (unsigned long long)checked,
                contract.within().c_str());
    return;
  }
  if (a.all) {
    uint64_t checked = 0;
    Progress progress("verify", "texels");
    const uint64_t bad =
        verify_every_texel(a, trace, contract, eval, L, region, checked, progress, 0, region.w * region.h, hulls.get());
    progress.finish();
    if (bad) {
      std::printf("verify %s: FAILED: %llu texels break %s (stopped after %llu of "
                  "%llu texels; --max-mismatches %llu)\n",
                  a.pack.c_str(), (unsigned long long)bad, contract.name().c_str(), (unsigned long long)checked,
                  (unsigned long long)(region.w * region.h), (unsigned long long)a.max_mismatches);
      exit_with(kExitMismatch);
    }
    check_grid();
    std::printf("verify %s: OK: every texel of the built region (%llu x %llu = %llu) re-traced, every "
                "one %s\n",
                a.pack.c_str(), (unsigned long long)region.w, (unsigned long long)region.h,
                (unsigned long long)checked, contract.within().c_str());
    return;
  }

  // Samples in 8x8 blocks (coherent packets), at random positions inside the built region.
  constexpr uint32_t kBlock = 8;
  uint64_t rng = a.seed, checked = 0, bad = 0;
  const uint64_t blocks = (a.samples + kBlock * kBlock - 1) / (kBlock * kBlock);
  for (uint64_t b = 0; b < blocks; ++b) {
    uint32_t bw = uint32_t(std::min<uint64_t>(kBlock, region.w));
    uint32_t bh = uint32_t(std::min<uint64_t>(kBlock, region.h));
    uint64_t x0 = region.x + splitmix64(rng) % (region.w - bw + 1);
    uint64_t y0 = region.y + splitmix64(rng) % (region.h - bh + 1);
    IntervalTile t = trace({L, x0, y0, bw, bh});
    for (uint32_t j = 0; j < bh; ++j)
      for (uint32_t i = 0; i < bw; ++i) {
        const Interval iv = t.at(i, j);
        float v = 0;
        std::string error;
        const TexelCheck r = check_texel(eval, contract, L, x0 + i, y0 + j, iv, v, error);
        if (r == TexelCheck::unreadable) {
          std::printf("verify: FAILED reading %s\n", error.c_str());
          exit_with(kExitMismatch);
        }
        ++checked;
        if (r == TexelCheck::mismatch) {
          if (bad < a.show) print_mismatch(x0 + i, y0 + j, L, v, iv);
          ++bad;
        }
      }
  }
  if (bad) {
    std::printf("verify %s: FAILED: %llu of %llu sampled texels break %s\n", a.pack.c_str(),
                (unsigned long long)bad, (unsigned long long)checked, contract.name().c_str());
    exit_with(kExitMismatch);
  }
  std::printf("verify %s: OK: %llu random texels re-traced, every one %s\n", a.pack.c_str(),
              (unsigned long long)checked, contract.within().c_str());
}

void setup_verify(CLI::App& app) {
  auto a = std::make_shared<VerifyArgs>();
  app.footer("Exit code 3 when a checksum, a tile or a texel fails.\nExample:\n"
             "  shadowtile verify city.pack procedural:city --samples 1000000\n"
             "  shadowtile verify city.pack procedural:city --all\n"
             "  shadowtile verify city.pack procedural:city --all --cells 2000 --cell-side 256");
  app.add_option("pack", a->pack, "Pack file")->required();
  app.add_option("scene", a->scene, "The scene the pack was built from")->required();
  app.add_option("--samples", a->samples, "Random texels to re-trace")->capture_default_str();
  app.add_option("--seed", a->seed, "Seed of the sample positions")->capture_default_str();
  app.add_option("--show", a->show, "Mismatches to print")->capture_default_str();
  app.add_option("--builder", a->builder,
                 "Re-trace with: pack (the builder the pack records), raster, embree or auto")
      ->capture_default_str();
  app.add_flag("--all", a->all, "Re-trace every texel of the built region instead of samples");
  app.add_option("--max-mismatches", a->max_mismatches,
                 "With --all: stop after this many mismatches")
      ->capture_default_str()
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 40));
  app.add_option("--cells", a->cells,
                 "With --all: re-trace every texel of this many random aligned squares of the built region "
                 "(--cell-side) instead of all of it (maps too large to re-trace whole)");
  app.add_option("--cell-side", a->cell_side, "With --cells: the squares' side in texels, a power of two")
      ->capture_default_str();
  add_scene_file_options(app, a->up, a->scene_limits);
  app.callback([a]() { run_verify(*a); });
}

Register reg_verify{"verify", "Check a pack's checksums and re-trace random texels against it (lossless)", setup_verify};

}  // namespace
}  // namespace st::cli

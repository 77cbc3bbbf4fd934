#include "tiles/bake/stack_build.hpp"

#include <sys/statvfs.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>

#include "common/error.hpp"
#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "tiles/encode/stack_pack.hpp"

namespace st {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// One sample's bounds: the rasterizer (skip exact: the canonical bits) for a sun, the
// Embree tracer for a perspective sample.
class SliceTracer {
 public:
  SliceTracer(const Scene& scene, const LightSpace& light, bool embree_only = false) {
    if (light.parallel() && !embree_only)
      raster_ = std::make_unique<RasterBounds>(scene, light, RasterSkip::exact);
    else
      embree_ = std::make_unique<DepthBoundsTracer>(scene, light);
  }
  IntervalTile trace(const TraceRegion& r) const { return raster_ ? raster_->trace(r) : embree_->trace(r); }
  bool exit_depths() const { return raster_ ? raster_->traces_exit_depths() : embree_->traces_exit_depths(); }
  const char* name() const { return raster_ ? "raster" : "embree"; }

 private:
  std::unique_ptr<RasterBounds> raster_;
  std::unique_ptr<DepthBoundsTracer> embree_;
};

}  // namespace

IntervalTile trace_slice(const Scene& scene, const LightSpace& light, const TraceRegion& region, bool embree) {
  return SliceTracer(scene, light, embree).trace(region);
}

std::string trace_stack_to_spill(const Scene& scene, const LightSet& set, StackSpill& spill, bool* exit_depths,
                                 const std::function<void(uint32_t, uint32_t)>& progress,
                                 const std::function<void(uint32_t, const IntervalTile&)>& slice, bool embree_only) {
  const uint32_t n = set.size();
  const uint32_t level = spill.geo().n;
  const uint64_t side = spill.side(), bs = spill.block_side();
  if (n != spill.slices()) throw Error("build: the spill holds " + std::to_string(spill.slices()) + " slices, not " + std::to_string(n));
  // Regions of whole blocks, about 2^22 texels (32 MiB of intervals) each: full-width
  // strips, or (a block row above 2^22 texels) one block row cut across.
  const uint64_t budget = uint64_t(1) << 22;
  const uint64_t cols = slice ? side : std::max<uint64_t>(bs, std::min<uint64_t>(side, budget / bs / bs * bs));
  const uint64_t rows = slice || cols < side ? (slice ? side : bs)
                                             : std::max<uint64_t>(bs, std::min<uint64_t>(side, budget / side / bs * bs));
  if (slice && side * side > DepthBoundsTracer::kMaxRegionTexels)
    throw Error("build: whole slices of " + std::to_string(side) + "^2 texels exceed one trace call");
  std::string by;
  for (uint32_t w = 0; w < n; ++w) {
    const SliceTracer tracer(scene, set.samples[w], embree_only);
    by = tracer.name();
    if (exit_depths) *exit_depths = tracer.exit_depths();
    for (uint64_t y0 = 0; y0 < side; y0 += rows)
      for (uint64_t x0 = 0; x0 < side; x0 += cols) {
        const IntervalTile t = tracer.trace({level, x0, y0, uint32_t(cols), uint32_t(rows)});
        spill.write_region(w, x0, y0, cols, rows, t.data);
        if (slice) slice(w, t);
      }
    if (progress) progress(w + 1, n);
  }
  return by;
}

IntervalStack trace_stack(const Scene& scene, const LightSet& set, uint32_t level, bool* exit_depths,
                          const std::function<void(uint32_t, uint32_t)>& progress) {
  const uint32_t n = set.size();
  const uint64_t side = uint64_t(1) << level;
  if (level > 13 || double(n) * double(side) * double(side) > double(kMaxResidentStackTexels))
    throw Error("build: a stack of " + std::to_string(n) + " slices of " + std::to_string(side) + "^2 texels exceeds " +
                "the 2^28 texels (2 GiB of intervals) an in-memory stack holds; lower --resolution or samples=");
  IntervalStack stack{level, n, {}};
  stack.data.reserve(size_t(side * side) * n);
  for (uint32_t w = 0; w < n; ++w) {
    const SliceTracer tracer(scene, set.samples[w]);
    if (exit_depths) *exit_depths = tracer.exit_depths();
    const IntervalTile t = tracer.trace({level, 0, 0, uint32_t(side), uint32_t(side)});
    stack.data.insert(stack.data.end(), t.data.begin(), t.data.end());
    if (progress) progress(w + 1, n);
  }
  return stack;
}

double scene_ground_height(const Scene& scene) {
  const Aabb b = scene.bounds();
  if (b.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::map<double, double> area;  // height -> horizontal up-facing area there
  for (const auto& t : scene.triangles) {
    const Vec3d& a = scene.vertices[t[0]];
    const Vec3d& p = scene.vertices[t[1]];
    const Vec3d& c = scene.vertices[t[2]];
    if (a.y != p.y || a.y != c.y) continue;
    const Vec3d n = cross(p - a, c - a);
    if (!(n.y > 0)) continue;  // facing down (or degenerate)
    area[a.y] += 0.5 * n.y;
  }
  double best = std::numeric_limits<double>::quiet_NaN(), best_area = 0;
  for (const auto& [y, s] : area)
    if (s > best_area) best = y, best_area = s;
  const Vec3d e = b.extent();
  return best_area >= 0.25 * e.x * e.z ? best : std::numeric_limits<double>::quiet_NaN();
}

LightSet fit_light_set(const Scene& scene, LightSetSpec spec) {
  if (spec.kind != LightSetKind::sun_path || spec.sun_frame != SunFrame::ground) return LightSet::fit(spec, scene.bounds());
  if (std::isnan(spec.ground)) spec.ground = scene_ground_height(scene);
  // A hull of the geometry, conservative: per height band of the box, the box of the
  // vertices in it, its corners at the band's two heights (so the square covers every
  // vertex's projection; triangles project into the hull of their vertices').
  const Aabb b = scene.bounds();
  constexpr int kBands = 64;
  const double h = b.extent().y;
  std::vector<Aabb> band(kBands);
  for (const Vec3d& p : scene.vertices) {
    const int k = h > 0 ? std::clamp(int((p.y - b.lo.y) / h * kBands), 0, kBands - 1) : 0;
    band[size_t(k)].extend(p);
  }
  std::vector<Vec3d> extent;
  for (const Aabb& a : band) {
    if (a.empty()) continue;
    for (int c = 0; c < 8; ++c)
      extent.push_back({(c & 1) ? a.hi.x : a.lo.x, (c & 2) ? a.hi.y : a.lo.y, (c & 4) ? a.hi.z : a.lo.z});
  }
  return LightSet::fit(spec, b, extent);
}

StackBuildReport build_stack_pack(const Scene& scene, const LightSetSpec& spec_in, const StackBuildOptions& o,
                                  const std::string& out) {
  StackBuildReport r;
  const LightSet set = fit_light_set(scene, spec_in);
  const LightSetSpec& spec = set.spec;
  const uint32_t n = set.size();
  const uint64_t side = uint64_t(1) << o.map_level;
  if (o.map_level > 16 || double(n) * double(side) * double(side) > double(kMaxStackTexels))
    throw Error("build: a stack of " + std::to_string(n) + " slices of " + std::to_string(side) + "^2 texels exceeds " +
                "the 2^34 texels (slices up to 65536^2) a stack build spills; lower --resolution or samples=");
  uint32_t k = 0;
  while ((1u << k) < n) ++k;
  const moct::Geometry g{o.map_level, k};
  const uint32_t K = o.skip_level.value_or(default_stack_skip_level(g));
  if (K > g.depth())
    throw Error("build: skip level " + std::to_string(K) + " exceeds the octree depth " + std::to_string(g.depth()));
  const uint32_t B = stack_block_level(g, K, o.block_texels);
  std::string dir = o.spill_dir;
  if (dir.empty()) {
    dir = std::filesystem::path(out).parent_path().string();
    if (dir.empty()) dir = ".";
  }
  const std::string spill_path = (std::filesystem::path(dir) / (std::filesystem::path(out).filename().string() + ".spill")).string();
  r.spill_bytes = side * side * n * sizeof(Interval);
  struct statvfs fs {};
  if (::statvfs(dir.c_str(), &fs) == 0 && double(fs.f_bavail) * double(fs.f_frsize) < double(r.spill_bytes) * 1.05)
    throw Error("build: the stack's spill needs " + std::to_string(r.spill_bytes >> 20) + " MiB in '" + dir + "', " +
                std::to_string((uint64_t(fs.f_bavail) * fs.f_frsize) >> 20) + " MiB free");
  StackSpill spill(spill_path, o.map_level, n, B);
  auto t0 = std::chrono::steady_clock::now();
  r.bounds_by = trace_stack_to_spill(scene, set, spill, &r.exit_depths, o.progress);
  r.trace_seconds = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  BlockedCutStats bst;
  BlockedStackCut cut(spill, K, o.tile_bytes, spill_path + ".tiles", &bst, o.cells, o.split_cells,
                      o.planes ? std::optional<PlaneFitOptions>(PlaneFitOptions{}) : std::nullopt);
  r.slice_cells = cut.slice_cells;
  r.split_cells = cut.split_cells;
  r.octree_seconds = bst.reduce_seconds;
  r.cut_seconds = bst.patch_seconds;
  r.octree_nodes = bst.octree_nodes;
  r.blocks = bst.blocks;
  r.block_level = B;
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = spec.to_string();
  if (cut.grid.spec.size() > kStackMaxSpecBytes) throw Error("build: the light set's spec exceeds 4096 bytes");
  StackPackParams pp;
  pp.tile_bytes = o.tile_bytes;
  pp.flags = r.exit_depths ? uint32_t(kFeatureExitDepths) : 0u;
  pp.scene_hash = scene.content_hash();
  pp.compression_level = o.compression_level;
  pp.build_params = {{"light", o.light_spec.empty() ? spec.to_string() : o.light_spec},
                     {"scene", o.scene_spec.empty() ? scene.name : o.scene_spec},
                     {"builder", r.bounds_by},
                     {"slices", std::to_string(set.size())},
                     {"tool", "shadowtile 0.1.0"}};
  std::sort(pp.build_params.begin(), pp.build_params.end());
  t0 = std::chrono::steady_clock::now();
  r.pack_bytes = write_stack_pack(out, cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, pp);
  r.write_seconds = seconds_since(t0);
  r.slices = set.size();
  r.map_level = o.map_level;
  r.skip_level = cut.grid.skip_level;
  r.cells = cut.grid.entries.size();
  r.tiles = cut.tile_count();
  r.max_tile_bytes = cut.max_tile_bytes;
  return r;
}

}  // namespace st

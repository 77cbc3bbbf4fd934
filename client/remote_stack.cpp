// RemoteMap for stack packs (tiles/PACK.md "Stack packs"): the stack grid arrives as the
// map's skip grid, tiles are MH octrees of level-K cells (tiles/core/MHOCT.md) fetched,
// cached and retried like any tile; lookups go through StackMap, whose absent tiles
// answer the cell's level-K value (coarser while tiles stream) and queue the fetch.
#include <algorithm>
#include <cmath>
#include <mutex>
#include <shared_mutex>

#include "client/remote_map.hpp"
#include "common/error.hpp"

namespace st::client {
namespace {

// A stack tile in a cache slot: an MH octree or per-slice tiles (stack_slices.hpp), by its magic.
class StackTileEvaluator final : public Evaluator {
 public:
  explicit StackTileEvaluator(StackTile t) : tile(std::move(t)) {}
  uint32_t finest_level() const override { return tile.xy_level(); }
  float depth(uint32_t level, uint64_t x, uint64_t y) const override { return tile.ref().depth(x, y, 0, level); }
  StackTile tile;
};

struct Misses {
  static constexpr size_t kMax = 8;  // more distinct misses in one call: asked again later
  uint64_t cell[kMax] = {};
  size_t count = 0;
};
thread_local Misses t_misses;

}  // namespace

void RemoteMap::open_stack(const std::vector<uint8_t>& grid_bytes) {
  stack_grid_ = std::make_unique<StackGrid>(StackGrid::parse(grid_bytes, "map '" + name_ + "'"));
  const StackGrid& g = *stack_grid_;
  if (g.skip_level != header_.skip_level || g.geo.n != header_.map_level)
    throw FormatError("map '" + name_ + "': stack grid disagrees with the header's levels");
  stack_map_ = std::make_unique<StackMap>(
      g, [this](const uint64_t* cells, uint32_t n, StackTileRef* out) { stack_tiles(cells, n, out); });
}

SurfaceExtent RemoteMap::stack_surface() {
  // Slice 0's level-a map (a <= the skip level's x, y resolution, so the stack grid answers
  // every texel and no tile is read), as a constant skip grid.
  const StackGrid& g = *stack_grid_;
  const uint32_t a = std::min<uint32_t>(g.geo.xy_bits(g.skip_level), 7);
  CutGrid grid = CutGrid::constant(a, kLitDepth);
  for (uint64_t y = 0; y < (uint64_t(1) << a); ++y)
    for (uint64_t x = 0; x < (uint64_t(1) << a); ++x) grid.entry(x, y).value = stack_depth(0, a, x, y);
  return surface_extent(*info_light_, grid);
}

std::unique_ptr<Evaluator> RemoteMap::open_stack_tile(const StackGrid& g, uint64_t id, std::span<uint8_t> raw, uint32_t pack_flags) {
  uint64_t cell = 0;
  if (!g.cell_of(id, cell) || g.entries[cell].kind != 1) return nullptr;
  StackTile t = StackTile::open(raw);  // validates the whole buffer; throws FormatError
  const uint32_t l = g.entries[cell].level;  // K, or deeper for a split cell's child
  if (t.xy_level() != g.geo.n - g.geo.xy_bits(l) || t.w_level() != g.geo.k - g.geo.w_bits(l)) return nullptr;
  if (t.has_planes() && !(pack_flags & kFeaturePlaneTiles)) return nullptr;  // only in a pack that says so
  if (t.has_wide_planes() && !(pack_flags & kFeatureWidePlaneBlocks)) return nullptr;
  return std::make_unique<StackTileEvaluator>(std::move(t));
}

StackTileRef RemoteMap::stack_tile(uint64_t cell) const noexcept {
  const uint64_t id = stack_grid_->tile_id(cell);
  const PageEntry page = cache_.lookup(id);
  if (page.state == PageState::resident) {
    mark_used(page.slot);
    return static_cast<const StackTileEvaluator*>(slot_eval_[page.slot].get())->tile.ref();
  }
  if (page.state != PageState::constant) {  // constant: given up, the coarse value for good
    Misses& m = t_misses;
    bool noted = false;
    for (size_t i = 0; i < m.count && !noted; ++i) noted = m.cell[i] == cell;
    if (!noted && m.count < Misses::kMax) m.cell[m.count++] = cell;
  }
  return StackTileRef();
}

void RemoteMap::stack_tiles(const uint64_t* cells, uint32_t n, StackTileRef* out) const noexcept {
  constexpr uint32_t kStep = 64;  // a soft lookup's cells at once
  PageEntry page[kStep];
  for (uint32_t i0 = 0; i0 < n; i0 += kStep) {
    const uint32_t m = std::min(kStep, n - i0);
    for (uint32_t i = 0; i < m; ++i) page[i] = cache_.lookup(stack_grid_->tile_id(cells[i0 + i]));
    for (uint32_t i = 0; i < m; ++i)
      if (page[i].state == PageState::resident) __builtin_prefetch(slot_eval_[page[i].slot].get());
    for (uint32_t i = 0; i < m; ++i) {
      if (page[i].state != PageState::resident) {
        out[i0 + i] = stack_tile(cells[i0 + i]);  // notes the miss as a single call does
        continue;
      }
      mark_used(page[i].slot);
      out[i0 + i] = static_cast<const StackTileEvaluator*>(slot_eval_[page[i].slot].get())->tile.ref();
    }
  }
}

template <class Fn>
auto RemoteMap::stack_lookup(Fn&& fn) const noexcept {
  t_misses.count = 0;
  decltype(fn(*stack_map_)) r;
  {
    std::shared_lock lock(mu_);
    r = fn(*stack_map_);
  }
  if (t_misses.count) {
    std::lock_guard lock(mu_);
    for (size_t i = 0; i < t_misses.count; ++i) {
      const uint64_t cell = t_misses.cell[i];
      want_locked(stack_grid_->tile_id(cell), GridEntry{stack_grid_->entries[cell].value, EntryKind::tile, 0},
                  options_.miss_priority);
    }
  }
  return r;
}

float RemoteMap::stack_visibility(const Vec3d& world, double time, uint32_t pcf_radius, float footprint) const noexcept {
  if (!stack_map_) return 1.0f;
  if (pcf_radius == 0 && !(footprint > 0))
    return stack_lookup([&](const StackMap& m) { return m.visibility(world, time); });
  return stack_lookup([&](const StackMap& m) { return m.visibility_filtered(world, time, pcf_radius, footprint); });
}

float RemoteMap::stack_soft_visibility(const Vec3d& world, uint32_t pcf_radius, float footprint) const noexcept {
  if (!stack_map_) return 1.0f;
  if (pcf_radius == 0 && !(footprint > 0))
    return stack_lookup([&](const StackMap& m) { return m.soft_visibility(world); });
  return stack_lookup([&](const StackMap& m) { return m.soft_visibility_filtered(world, pcf_radius, footprint); });
}

void RemoteMap::stack_soft_visibility_batch(std::span<const WorldPoint> points, std::span<float> out,
                                            uint32_t pcf_radius) const noexcept {
  const size_t count = std::min(points.size(), out.size());
  if (!stack_map_ || pcf_radius != 0) {
    for (size_t i = 0; i < count; ++i) out[i] = stack_soft_visibility({points[i].x, points[i].y, points[i].z}, pcf_radius);
    return;
  }
  // Chunks bound the stack buffer and how long one call holds the shared lock.
  constexpr size_t kChunk = 256;
  Vec3d p[kChunk];
  for (size_t b = 0; b < count; b += kChunk) {
    const size_t m = std::min(kChunk, count - b);
    for (size_t i = 0; i < m; ++i) p[i] = {points[b + i].x, points[b + i].y, points[b + i].z};
    stack_lookup([&](const StackMap& sm) {
      sm.soft_visibility(std::span<const Vec3d>(p, m), out.subspan(b, m));
      return 0;
    });
  }
}

float RemoteMap::stack_depth(uint32_t slice, uint32_t level, uint64_t x, uint64_t y) const noexcept {
  if (!stack_map_) return kLitDepth;
  return stack_lookup([&](const StackMap& m) { return m.depth(x, y, slice, level); });
}

size_t RemoteMap::request_slices(uint32_t w0, uint32_t w1, uint16_t priority) noexcept {
  if (!stack_grid_) return 0;
  const StackGrid& g = *stack_grid_;
  size_t queued = 0;
  std::lock_guard lock(mu_);
  if (failed_ >= kMaxFailedTiles) return 0;  // asks for nothing more (give_up_locked): no walk of every cell
  // Every tiled cell (split cells' children too) whose slices [w << s, ((w + 1) << s) - 1]
  // meet [w0, w1].
  g.visit([&](uint64_t cell, uint32_t l, uint64_t, uint64_t, uint64_t w) {
    if (g.entries[cell].kind != 1) return;
    const uint32_t s = g.geo.k - g.geo.w_bits(l);
    if (((w + 1) << s) - 1 < w0 || (w << s) > w1) return;
    queued += want_locked(g.tile_id(cell), GridEntry{g.entries[cell].value, EntryKind::tile, 0}, priority);
  });
  return queued;
}

bool RemoteMap::slices_resident(uint32_t w0, uint32_t w1) const noexcept {
  if (!stack_grid_) return true;
  const StackGrid& g = *stack_grid_;
  std::shared_lock lock(mu_);
  bool resident = true;
  g.visit([&](uint64_t cell, uint32_t l, uint64_t, uint64_t, uint64_t w) {
    if (!resident || g.entries[cell].kind != 1) return;
    const uint32_t s = g.geo.k - g.geo.w_bits(l);
    if (((w + 1) << s) - 1 < w0 || (w << s) > w1) return;
    resident = cache_.lookup(g.tile_id(cell)).state == PageState::resident;
  });
  return resident;
}

namespace {
// A normal far from unit length made unit (a unit one kept bit for bit: visibility_plane_batch's rule).
Vec3d stack_plane_normal(const Vec3d& n) {
  const double len2 = dot(n, n);
  return len2 > 0 && std::fabs(len2 - 1.0) > 1e-3 ? n * (1.0 / std::sqrt(len2)) : n;
}
}  // namespace

float RemoteMap::stack_visibility_plane(const Vec3d& world, const Vec3d& normal, double time, uint32_t pcf_radius,
                                        float footprint, bool closed) const noexcept {
  if (!stack_map_) return 1.0f;
  const Vec3d n = stack_plane_normal(normal);
  return stack_lookup([&](const StackMap& m) {
    return m.visibility_filtered_on_plane(world, n, time, pcf_radius, footprint, closed);
  });
}

float RemoteMap::stack_soft_visibility_plane(const Vec3d& world, const Vec3d& normal, uint32_t pcf_radius,
                                             float footprint, bool closed) const noexcept {
  if (!stack_map_) return 1.0f;
  const Vec3d n = stack_plane_normal(normal);
  return stack_lookup([&](const StackMap& m) {
    return m.soft_visibility_filtered_on_plane(world, n, pcf_radius, footprint, closed);
  });
}

}  // namespace st::client

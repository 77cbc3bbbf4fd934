#include "tiles/core/stack_map.hpp"

#include <algorithm>
#include <cmath>

#include "tiles/core/evaluator.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/slice_walks.hpp"
#include "tiles/core/walk_interleave.hpp"

namespace st {

StackMap::StackMap(const StackGrid& grid, TileSource tile) : grid_(grid), tile_(std::move(tile)) {
  lights_.reserve(grid.slices);
  for (uint32_t w = 0; w < grid.slices; ++w) lights_.push_back(grid.light(w));
  texels_ = SampleTexels(lights_, grid_.geo.n);
}

uint64_t StackMap::cell_of(uint64_t x, uint64_t y, uint32_t w) const {
  const moct::Geometry& g = grid_.geo;
  const uint32_t K = grid_.skip_level;
  const uint32_t sx = g.n - g.xy_bits(K), sw = g.k - g.w_bits(K);
  return grid_.index(K, x >> sx, y >> sx, w >> sw);
}

float StackMap::depth(uint64_t x, uint64_t y, uint32_t w, uint32_t level, bool* exact) const {
  const moct::Geometry& g = grid_.geo;
  if (level > g.n || w >= grid_.slices || (x >> level) || (y >> level)) return kLitDepth;
  const uint32_t K = grid_.skip_level;
  const uint32_t T = g.level_of_xy(level);  // octree level with 2^level texels a side
  const uint32_t a = g.xy_bits(std::min(T, K)), b = g.w_bits(std::min(T, K));
  const uint64_t cx = x >> (level - a), cy = y >> (level - a), cw = uint64_t(w) >> (g.k - b);
  if (T < K) return grid_.coarse[T][grid_.index(T, cx, cy, cw)];
  const uint64_t cell = grid_.index(K, cx, cy, cw);
  const StackEntry& e = grid_.entries[cell];
  if (e.kind == 0 || T == K) return e.value;
  const StackTileRef t = tile_(cell);
  if (!t) {
    if (exact) *exact = false;
    return e.value;
  }
  const uint32_t rel = level - a;  // the tile's own x, y level
  return t.depth(x - (cx << rel), y - (cy << rel), uint32_t(w - (cw << (g.k - b))), rel);
}

void StackMap::texel(const Vec3d& p, uint32_t w, uint64_t& x, uint64_t& y, float& d) const {
  const LightPoint lp = lights_[w].to_light(p);
  const auto t = LightSpace::texel_of(grid_.geo.n, lp.u, lp.v);
  x = t[0];
  y = t[1];
  d = float(lp.d);
}

StackMap::CellTexel StackMap::cell_texel(uint64_t x, uint64_t y, uint32_t w) const {
  const moct::Geometry& g = grid_.geo;
  if ((x >> g.n) || (y >> g.n)) return {kLitDepth, false, 0, 0, 0, 0};
  const uint32_t K = grid_.skip_level, sx = g.n - g.xy_bits(K), sw = g.k - g.w_bits(K);
  const uint64_t cell = grid_.index(K, x >> sx, y >> sx, uint64_t(w) >> sw);
  const StackEntry& e = grid_.entries[cell];
  const uint64_t xy_mask = (uint64_t(1) << sx) - 1;
  return {e.value, e.kind != 0 && g.depth() != K, cell, x & xy_mask, y & xy_mask, w & ((uint32_t(1) << sw) - 1)};
}

bool StackMap::lit(const Vec3d& p, uint32_t w, bool* exact) const {
  if (w >= grid_.slices) return true;
  uint64_t x, y;
  float d;
  texel(p, w, x, y, d);
  return d <= depth(x, y, w, grid_.geo.n, exact);
}

float StackMap::visibility(const Vec3d& p, double time, bool* exact) const {
  const uint32_t n = grid_.slices;
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(n - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) return lit(p, uint32_t(near), exact) ? 1.0f : 0.0f;
  const uint32_t a = uint32_t(std::floor(s));
  const float f = float(s - double(a));
  // lit(p, a) and lit(p, a + 1), bit for bit, with what the two share done once: both
  // texels in one run of the batched transforms (lit()'s transform, sample_texels.hpp),
  // one tile fetch when both lie in one cell, and there one walk serving both: an octree
  // walk to slice a + 1 resumes from slice a's (depth_along: they share the path down to
  // the level where w splits them), two per-slice walks run in lockstep (slice_walks.hpp).
  SampleTexels::Run run;
  texels_.run(p, a, 2, run);
  const CellTexel c[2] = {cell_texel(run.x[0], run.y[0], a), cell_texel(run.x[1], run.y[1], a + 1)};
  float v[2] = {c[0].value, c[1].value};
  StackTileRef t[2];
  for (uint32_t i = 0; i < 2; ++i)
    if (c[i].tiled) {
      t[i] = i == 1 && c[0].tiled && c[0].cell == c[1].cell ? t[0] : tile_(c[i].cell);
      if (!t[i] && exact) *exact = false;
    }
  if (t[0] && c[1].tiled && c[0].cell == c[1].cell) {
    if (t[0].octree) {
      MhOctree::Path path;
      v[0] = t[0].octree->depth_along(path, c[0].lx, c[0].ly, c[0].lw);
      v[1] = t[0].octree->depth_along(path, c[1].lx, c[1].ly, c[1].lw);
    } else {
      // Per-slice tiles: a slice whose bounds decide the receiver needs no walk (the
      // answer's side of d stands in for the depth: d <= lo gives lit as the walk would,
      // d > hi unlit); the rest in one lockstep call.
      uint64_t x[2], y[2];
      uint32_t w[2], at[2], count = 0;
      for (uint32_t i = 0; i < 2; ++i) {
        const SliceTiles::Bounds b = t[0].slices->bounds(c[i].lw);
        if (run.d[i] <= b.lo) {
          v[i] = b.lo;
        } else if (run.d[i] > b.hi) {
          v[i] = b.hi;
        } else {
          x[count] = c[i].lx, y[count] = c[i].ly, w[count] = c[i].lw, at[count++] = i;
        }
      }
      float got[2];
      if (count) slice_depths(*t[0].slices, count, x, y, w, got);
      for (uint32_t k = 0; k < count; ++k) v[at[k]] = got[k];
    }
  } else {
    for (uint32_t i = 0; i < 2; ++i)
      if (t[i]) {
        const uint32_t level = t[i].octree ? t[i].octree->xy_level() : t[i].slices->xy_level();
        v[i] = t[i].depth(c[i].lx, c[i].ly, c[i].lw, level);
      }
  }
  const float la = run.d[0] <= v[0] ? 1.0f : 0.0f, lb = run.d[1] <= v[1] ? 1.0f : 0.0f;
  return la + f * (lb - la);
}

float StackMap::soft_visibility(const Vec3d& p, bool* exact) const {
  // depth(x, y, w, n) per sample, the texels a run of samples at a time (SampleTexels:
  // lit()'s transform bit for bit). Per run, settle_run answers every sample that needs no
  // octree walk (per-slice cells in lockstep across their tiles); the octree samples then
  // walk in order, consecutive ones in the same cell sharing the walk
  // (MhOctree::depth_along: each starts from the deepest node its path shares with the
  // previous one). The lit count is a sum of per-sample tests, so the order is free.
  MhOctree::Path path;
  SampleTexels::Run run;
  const MhOctree* oct[SampleTexels::kRun];
  uint64_t path_cell = ~uint64_t(0);
  uint32_t lit_samples = 0;
  for (uint32_t w0 = 0; w0 < grid_.slices; w0 += SampleTexels::kRun) {
    const uint32_t m = std::min(SampleTexels::kRun, grid_.slices - w0);
    texels_.run(p, w0, m, run);
    lit_samples += settle_run(run, w0, m, oct, exact);
    for (uint32_t i = 0; i < m; ++i) {
      if (!oct[i]) continue;
      const CellTexel c = cell_texel(run.x[i], run.y[i], w0 + i);
      if (c.cell != path_cell) path_cell = c.cell, path.valid = false;
      lit_samples += run.d[i] <= oct[i]->depth_along(path, c.lx, c.ly, c.lw);
    }
  }
  return float(lit_samples) / float(grid_.slices);
}

uint32_t StackMap::settle_run(const SampleTexels::Run& run, uint32_t w0, uint32_t m, const MhOctree** oct,
                              bool* exact) const {
  // Every sample of the run but those in octree cells (oct[i] = the octree, else nullptr):
  // outside the slice or in a constant cell its entry's value, in an absent tile its
  // entry's value (exact cleared), in a per-slice cell its slice's bounds (SliceTiles::
  // bounds: every answer of the slice within [lo, hi], so d <= lo is lit and d > hi
  // shadowed exactly as the walk would say) or else its walk. A day's sun moves a raised
  // receiver's texel across cells from one sample to the next (2CylinderEngine.glb at
  // 1024^2 x 64: 1.7 samples a cell), so the walks are gathered over the whole run, each
  // in its own tile, and run in lockstep (slice_walks.hpp): their misses overlap.
  static_assert(SampleTexels::kRun <= kMaxSliceWalks);
  const SliceTiles* tiles[SampleTexels::kRun];
  uint64_t x[SampleTexels::kRun], y[SampleTexels::kRun];
  uint32_t w[SampleTexels::kRun], at[SampleTexels::kRun];
  float v[SampleTexels::kRun];
  uint32_t lit = 0, count = 0;
  uint64_t last_cell = ~uint64_t(0);
  StackTileRef last;
  for (uint32_t i = 0; i < m; ++i) {
    oct[i] = nullptr;
    const CellTexel c = cell_texel(run.x[i], run.y[i], w0 + i);
    if (!c.tiled) {
      lit += run.d[i] <= c.value;
      continue;
    }
    if (c.cell != last_cell) last_cell = c.cell, last = tile_(c.cell);
    if (last.octree) {
      oct[i] = last.octree;
    } else if (!last.slices) {
      if (exact) *exact = false;
      lit += run.d[i] <= c.value;
    } else {
      const SliceTiles::Bounds b = last.slices->bounds(c.lw);
      const float d = run.d[i];
      if (d <= b.lo) {
        ++lit;
      } else if (!(d > b.hi)) {
        tiles[count] = last.slices, x[count] = c.lx, y[count] = c.ly, w[count] = c.lw, at[count] = i;
        ++count;
      }
    }
  }
  if (count) slice_depths(tiles, count, x, y, w, v);
  for (uint32_t k = 0; k < count; ++k) lit += run.d[at[k]] <= v[k];
  return lit;
}

void StackMap::soft_visibility(std::span<const Vec3d> points, std::span<float> out, bool* exact) const {
  // soft_visibility(p) above as a resumable job per point (walk_interleave.hpp): the same
  // texels, runs settled the same way and octree walks in the same order, so the same
  // answers; a lane yields where its octree walk steps onto a new cache line.
  const uint32_t slices = grid_.slices;
  struct Lane {
    MhOctree::Path path;
    MhOctree::Walk walk;
    SampleTexels::Run run;  // samples w - w % kRun onward
    const MhOctree* oct[SampleTexels::kRun];  // per sample of the run: its octree, or settled
    uint64_t path_cell = 0;
    size_t i = 0;
    uint32_t w = 0, lit = 0;
    bool walking = false;
  };
  auto start = [&](Lane& ln, size_t i) {
    ln.path_cell = ~uint64_t(0);
    ln.i = i, ln.w = 0, ln.lit = 0, ln.walking = false;
  };
  auto run = [&](Lane& ln) {
    // The lane's scalars live in registers while it runs and go back at a yield.
    MhOctree::Path& path = ln.path;
    uint32_t w = ln.w, lit = ln.lit;
    bool walking = ln.walking;
    MhOctree::Walk k = ln.walk;
    for (;;) {
      if (walking) {
        const MhOctree& tile = *ln.oct[w % SampleTexels::kRun];
        if (step_until_new_line(tile, path, k)) {
          ln.w = w, ln.lit = lit, ln.walking = true, ln.walk = k;
          return true;
        }
        lit += ln.run.d[w % SampleTexels::kRun] <= tile.along_value(k);
        ++w;
        walking = false;
      }
      if (w == slices) {
        out[ln.i] = float(lit) / float(slices);
        return false;
      }
      const uint32_t j = w % SampleTexels::kRun;
      if (j == 0) {
        const uint32_t m = std::min(SampleTexels::kRun, slices - w);
        texels_.run(points[ln.i], w, m, ln.run);
        lit += settle_run(ln.run, w, m, ln.oct, exact);
      }
      if (!ln.oct[j]) {
        ++w;
        continue;
      }
      const CellTexel c = cell_texel(ln.run.x[j], ln.run.y[j], w);
      if (c.cell != ln.path_cell) ln.path_cell = c.cell, path.valid = false;
      k = ln.oct[j]->along_begin(path, c.lx, c.ly, c.lw);
      walking = true;
    }
  };
  run_interleaved<Lane>(std::min(points.size(), out.size()), start, run);
}

float StackMap::filtered(const Vec3d& p, uint32_t w, uint32_t pcf_radius, float footprint, bool* exact) const {
  if (w >= grid_.slices) return 1.0f;
  const uint32_t n = grid_.geo.n;
  const LightSpace& ls = lights_[w];
  const LightPoint lp = ls.to_light(p);
  const float d = float(lp.d);
  const uint32_t r = 2 * std::min<uint32_t>(pcf_radius, (Evaluator::kMaxPcf - 1) / 2) + 1;
  FilterLevels f{n, n, 0.0f};
  if (footprint > 0) {
    // One finest texel's side in world units at p (a spot's grows with the distance).
    const double texel = ls.texel_size(p, n);
    f = filter_levels(n, float(double(footprint) / texel));
  }
  auto kernel = [&](uint32_t level) {
    const auto t = LightSpace::texel_of(level, lp.u, lp.v);
    if (r == 1) return d <= depth(t[0], t[1], w, level, exact) ? 1.0f : 0.0f;
    const uint64_t side = uint64_t(1) << level;
    uint32_t lit_taps = 0;
    for (uint32_t j = 0; j < r; ++j)
      for (uint32_t i = 0; i < r; ++i)
        lit_taps += d <= depth(pcf_tap(t[0], i, r, side), pcf_tap(t[1], j, r, side), w, level, exact);
    return float(lit_taps) / float(r * r);
  };
  const float a = kernel(f.fine);
  if (f.t == 0.0f) return a;
  return filter_blend(a, kernel(f.coarse), f.t);
}

float StackMap::visibility_filtered(const Vec3d& p, double time, uint32_t pcf_radius, float footprint,
                                    bool* exact) const {
  const uint32_t n = grid_.slices;
  const double s = std::clamp(std::isnan(time) ? 0.0 : time, 0.0, 1.0) * double(n - 1);
  const double near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) return filtered(p, uint32_t(near), pcf_radius, footprint, exact);
  const uint32_t a = uint32_t(std::floor(s));
  const float f = float(s - double(a));
  const float va = filtered(p, a, pcf_radius, footprint, exact), vb = filtered(p, a + 1, pcf_radius, footprint, exact);
  return va + f * (vb - va);
}

float StackMap::soft_visibility_filtered(const Vec3d& p, uint32_t pcf_radius, float footprint, bool* exact) const {
  float sum = 0;
  for (uint32_t w = 0; w < grid_.slices; ++w) sum += filtered(p, w, pcf_radius, footprint, exact);
  return sum / float(grid_.slices);
}

}  // namespace st

#include "common/error.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {

ResidentStack::ResidentStack(const PackReader& pack) {
  const StackGrid* g = pack.stack();
  if (!g) throw Error(pack.name() + ": not a stack pack (no stack feature)");
  for (const TileIndexEntry& e : pack.tiles()) {
    uint64_t cell = 0;
    if (!g->cell_of(e.id, cell)) throw FormatError(pack.name() + ": " + describe_tile(e.id) + " names no stack cell");
    cells_.push_back(cell);
    buffers_.push_back(pack.read_raw(e.id));
    bytes_ += buffers_.back().size();
  }
  trees_.reserve(buffers_.size());
  for (size_t i = 0; i < buffers_.size(); ++i) {
    try {
      trees_.push_back(StackTile::open(buffers_[i]));
    } catch (const Error& err) {
      throw FormatError(pack.name() + ": " + describe_tile(pack.tiles()[i].id) + ": " + err.what());
    }
  }
  // Ids sort as cells do (one level), so cells_ is sorted.
  map_ = std::make_unique<StackMap>(*g, [this](uint64_t cell) -> StackTileRef {
    auto it = std::lower_bound(cells_.begin(), cells_.end(), cell);
    return it != cells_.end() && *it == cell ? trees_[size_t(it - cells_.begin())].ref() : StackTileRef();
  });
}

}  // namespace st

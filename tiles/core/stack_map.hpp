// Lookups in a stack pack (tiles/PACK.md "Stack packs"): a StackGrid (the octree's top
// levels and the level-K cells) plus the cells' tiles, each an MH octree buffer of the
// cell's subtree (MHOCT.md). The same contract as StackLookup (stack_lookup.hpp) for
// lit / visibility(p, time) / soft_visibility(p); where a cell's tile is not resident
// (still streaming) the cell's entry value answers, which is the level-K map of the
// stack: coarser, never missing.
//
// Thread safety: const lookups; the grid and whatever `tile` returns are borrowed.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "tiles/core/light.hpp"
#include "tiles/core/light_set.hpp"
#include "tiles/core/mh_octree.hpp"
#include "tiles/core/sample_texels.hpp"
#include "tiles/core/stack_grid.hpp"
#include "tiles/core/stack_slices.hpp"

namespace st {

class StackMap {
 public:
  // The tiles of cells[i] (dense indices of the grid's entries) for i < n: out[i] the
  // cell's MH octree or per-slice tiles (stack_slices.hpp), or nothing while absent. One
  // callback for every lookup: a soft (or time) lookup asks for all its distinct cells in
  // one call, so that a source keeps their loads in flight together (ResidentStack: one
  // loop over its dense array; the client: every page looked up, then the evaluators
  // prefetched, then the refs); a single-slice lookup asks for one. An empty source holds
  // no tile (every tiled cell answers its level-K value, `exact` cleared). A source writes
  // every out[i] (the lookups hand it room left unset).
  using TileSource = std::function<void(const uint64_t* cells, uint32_t n, StackTileRef* out)>;
  explicit StackMap(const StackGrid& grid, TileSource tiles = {});

  const StackGrid& grid() const { return grid_; }
  uint32_t slices() const { return grid_.slices; }
  uint32_t xy_level() const { return grid_.geo.n; }

  // Texel (x, y) of the level-`level` map of slice w (level <= n; x, y < 2^level).
  // Out of range: kLitDepth. `exact` (if given) is cleared when an absent tile answered.
  float depth(uint64_t x, uint64_t y, uint32_t w, uint32_t level, bool* exact = nullptr) const;
  // The cell (dense index) that texel (x, y, w) of the finest level lies in.
  uint64_t cell_of(uint64_t x, uint64_t y, uint32_t w) const;
  // Finest texel of point p in slice w, and its receiver depth (rounded to float).
  void texel(const Vec3d& p, uint32_t w, uint64_t& x, uint64_t& y, float& d) const;

  bool lit(const Vec3d& p, uint32_t w, bool* exact = nullptr) const;
  float visibility(const Vec3d& p, double time, bool* exact = nullptr) const;
  // The N samples' lit tests averaged; consecutive samples in one cell share the tile
  // walk (equal to N lit() calls bit for bit, tested).
  float soft_visibility(const Vec3d& p, bool* exact = nullptr) const;
  // out[i] = soft_visibility(points[i]) for i < min(points.size(), out.size()), bit for bit
  // (tested): each point's samples gathered as the single lookup does (lit_samples).
  // `exact` is cleared when an absent tile answered any.
  void soft_visibility(std::span<const Vec3d> points, std::span<float> out, bool* exact = nullptr) const;

  // PCF and the footprint level, as the 2D lookups (Evaluator::pcf / pcf_footprint,
  // filter_level.hpp): the fraction of the r x r kernel (r = 2 * pcf_radius + 1,
  // pcf_radius <= 4, taps clamped to the slice's edges) around p's texel in slice w whose
  // taps are lit for p's receiver depth; with footprint > 0 (world units: the side of the
  // receiver's pixel footprint) at the two levels where one texel of slice w is about that
  // wide, blended trilinearly (filter_levels, filter_blend). pcf_radius 0 with footprint
  // <= one finest texel is lit(p, w) exactly (1 or 0).
  float filtered(const Vec3d& p, uint32_t w, uint32_t pcf_radius, float footprint, bool* exact = nullptr) const;
  // visibility / soft_visibility with filtered() in place of lit(): the same time blend
  // (exact at the samples) and the same average over the N samples (sum in float / N).
  float visibility_filtered(const Vec3d& p, double time, uint32_t pcf_radius, float footprint,
                            bool* exact = nullptr) const;
  float soft_visibility_filtered(const Vec3d& p, uint32_t pcf_radius, float footprint, bool* exact = nullptr) const;
  // The same three with the receiver's surface normal (unit length, facing the light):
  // receiver-plane depth bias per slice (tiles/core/receiver_plane.hpp), what the 2D
  // Map::visibility_filtered with a normal does in the one light. In slice w the lookup
  // point is p moved along the normal by kOpenReceiverOffsetTexels (closed:
  // kClosedReceiverOffsetTexels) finest texels of that slice, and each tap compares the
  // receiver's plane over its own texel (receiver_plane_at in slice w's light) with the
  // stored value; a point outside slice w's map is lit there. The footprint picks the
  // levels as filtered() does (texel_size at p). Taps counted one by one
  // (stack_map_plane.cpp).
  float filtered_on_plane(const Vec3d& p, const Vec3d& normal, uint32_t w, uint32_t pcf_radius, float footprint,
                          bool closed = false, bool* exact = nullptr) const;
  float visibility_filtered_on_plane(const Vec3d& p, const Vec3d& normal, double time, uint32_t pcf_radius,
                                     float footprint, bool closed = false, bool* exact = nullptr) const;
  float soft_visibility_filtered_on_plane(const Vec3d& p, const Vec3d& normal, uint32_t pcf_radius, float footprint,
                                          bool closed = false, bool* exact = nullptr) const;

 private:
  // Where texel (x, y) of slice w (finest level) is answered: `value` (lit outside the
  // slice; a cell's level-K entry) unless `tiled`, when the tile of level-K cell `cell`
  // holds it at the tile's own texel (lx, ly, lw).
  struct CellTexel {
    float value;
    bool tiled;
    uint64_t cell, lx, ly;
    uint32_t lw;
  };
  CellTexel cell_texel(uint64_t x, uint64_t y, uint32_t w) const;
  // The most samples one lit_samples call settles: a 64-sample soft lookup at once.
  static constexpr uint32_t kGather = 2 * SampleTexels::kRun;
  // Samples w0 .. w0 + m - 1 (m <= kGather; sample w0 + i's texel and depth at
  // runs[i / kRun], entry i % kRun): bit i set when sample w0 + i is lit, d <= depth(x, y,
  // w0 + i, n) exactly, with their loads gathered across samples (stack_map.cpp). `exact`
  // is cleared when an absent tile answered.
  uint64_t lit_samples(const SampleTexels::Run* runs, uint32_t w0, uint32_t m, bool* exact) const;
  // Its body, and that body compiled for POPCNT (x86 builds without it, GCC and clang;
  // chosen at run time where the CPU has it; stack_map.cpp): declared where it is defined.
  inline uint64_t lit_samples_body(const SampleTexels::Run* runs, uint32_t w0, uint32_t m, bool* exact) const;
#if (defined(__x86_64__) || defined(__i386__)) && !defined(__POPCNT__) && defined(__GNUC__)
#define ST_STACK_MAP_POPCNT_CLONE 1
  uint64_t lit_samples_popcnt(const SampleTexels::Run* runs, uint32_t w0, uint32_t m, bool* exact) const;
#endif

  const StackGrid& grid_;
  TileSource tiles_;
  std::vector<LightSpace> lights_;
  SampleTexels texels_;  // the soft lookups' batched transforms (sample_texels.hpp)
};

}  // namespace st

namespace st {

class PackReader;

// Every tile of a stack pack read, inflated and opened (verify, export, tests, a local
// client map): lookups never miss a tile. Throws st::FormatError on a bad tile.
class ResidentStack {
 public:
  explicit ResidentStack(const PackReader& pack);
  const StackMap& map() const { return *map_; }
  uint64_t tile_bytes() const { return bytes_; }

 private:
  std::vector<uint64_t> cells_;  // sorted
  std::vector<std::vector<uint8_t>> buffers_;
  std::vector<StackTile> trees_;
  std::vector<StackTileRef> by_cell_;  // per cell of the grid: its tile, or none
  std::unique_ptr<StackMap> map_;
  uint64_t bytes_ = 0;
};

}  // namespace st

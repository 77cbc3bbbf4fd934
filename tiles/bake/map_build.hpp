// The out-of-core, parallel map build: level-K cells stream through
//   bounds (rasterizer or Embree) -> MH construction -> cut + encode -> compress -> append
// with memory bounded by the cell size and the thread count, never by the map's
// resolution. Cells larger than kMaxTraceSide are traced in sub-tiles whose hierarchies
// are stitched (MH §3.1 "Tiled construction").
//
//   MapBuildOptions o; o.map_level = 16; o.encoding = Encoding::dagmh;
//   MapBuildReport r = build_map(scene, light, o, "city.pack");
//
// Thread safety: one build per output path at a time. Errors: st::Error (bad options,
// I/O); a killed build leaves "<out>.tmp", which `resume` continues.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tiles/bake/depth_bounds.hpp"
#include "tiles/bake/raster_bounds.hpp"
#include "tiles/encode/plane_fit.hpp"
#include "scene/scene.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/light.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_merge.hpp"

namespace st {

inline constexpr uint32_t kMaxTraceSide = 4096;  // largest square traced in one call
// RasterSkip::regions: regions not proven by their corners split down to this side, then
// are rasterized texel by texel.
inline constexpr uint64_t kRegionLeafSide = 64;

struct TexelRegion {
  uint64_t x = 0, y = 0, w = 0, h = 0;  // texels of the finest level
};

// Which depth interval each texel gets (ARCHITECTURE.md "Definitions").
enum class IntervalRule : uint8_t {
  closed_objects,   // [first hit, exit of the closed objects]; hi = lo on open geometry
  static_geometry,  // also: an open first hit reaches to just below the next surface
                    // (receivers lie on surfaces; pack feature static_intervals)
};

// Which producer computes the depth bounds. Both evaluate the canonical depth
// (canonical_depth.hpp); the rasterizer also evaluates the canonical coverage
// (canonical_coverage.hpp) where Embree decides coverage in float, so the two can differ
// on a texel whose ray passes within float error of a triangle edge (ARCHITECTURE.md).
enum class BoundsBuilder : uint8_t {
  automatic,  // raster where it applies (a sun, either interval rule), else embree
  raster,     // the light-space rasterizer (raster_bounds.hpp)
  embree,     // the Embree tracer (depth_bounds.hpp): every light and interval rule
};
const char* to_string(BoundsBuilder b);  // "auto", "raster", "embree"
BoundsBuilder parse_bounds_builder(const std::string& text);  // st::Error naming the text
// The builder a build uses: automatic resolved; raster where it does not apply is an
// st::Error saying why.
BoundsBuilder resolve_builder(BoundsBuilder b, const LightSpace& light, IntervalRule rule);

// The tracer's mode for an interval rule.
inline TraceMode trace_mode_of(IntervalRule r) {
  return r == IntervalRule::static_geometry ? TraceMode::static_bounds : TraceMode::bounds;
}

// A distributed build's other processes (the MPI build, app/build_mpi.cpp). build_map()
// calls run() on a thread of its own once the cells are planned. run() takes cells with
// `take` from the same queue the local workers draw from (whoever is free takes the next
// cell: dynamic scheduling), has them built elsewhere (CellBuilder), hands the journal
// bytes that come back to `append` (which checks them record by record and appends
// them), and returns once every cell it took is appended. A throw fails the build; the
// .tmp keeps every cell appended so far, for --resume.
class PackWriter;

class RemoteCells {
 public:
  virtual ~RemoteCells() = default;
  using Take = std::function<std::optional<std::pair<uint32_t, uint32_t>>()>;
  using Append = std::function<void(std::span<const uint8_t>)>;
  virtual void run(const Take& take, const Append& append) = 0;
};

struct MapBuildOptions {
  uint32_t map_level = 12;
  Encoding encoding = Encoding::dagmh;
  uint32_t vsdag_z_bits = 16;  // vsdag only: 2^z depth slabs per tile (tiles/core/VSDAG.md), 3..20
  std::optional<uint32_t> skip_level;  // default: default_skip_level(map_level)
  uint32_t tile_bytes = 64 * 1024;
  MhConstruction construction = MhConstruction::bottom_up;
  IntervalRule intervals = IntervalRule::closed_objects;
  BoundsBuilder builder = BoundsBuilder::automatic;  // recorded in the pack's build params
  // The rasterizer's per-tile skip (raster_bounds.hpp): exact keeps the definition's bits;
  // narrow stores sub-intervals of the true ones (build parameter intervals_narrowed=yes).
  RasterSkip raster_skip = RasterSkip::exact;
  bool resume = false;  // continue "<out>.tmp" if present
  int compression_level = 6;
  // DAG-MH: finish with the pack-wide dictionary of shared subtrees (PackParams::
  // dagmh_dictionary; tiles/PACK.md "DAG-MH dictionary"). The CLI turns it on by default.
  bool dagmh_dictionary = false;
  // DAG-MH: a tile whose MMH encoding stores in fewer bytes is written as MMH instead
  // (TileCodec::dagmh_or_mmh; pack feature mixed_tiles, tiles/PACK.md "Mixed tiles"), so
  // no tile of the pack is larger than the MMH pack's would be (exhaustive below; else the
  // choice is predicted per tile and the pack measured). The CLI turns it on by default
  // (--dagmh-tiles mixed).
  bool dagmh_mixed_tiles = false;
  // MH, MMH, DAG-MH: a tile whose finest texels hold blocks of one plane each also tries
  // plane blocks over the encoding of the rest (TileCodec::with_planes; pack feature
  // plane_tiles, tiles/core/PLANES.md) and keeps what stores smaller. On, as in the CLI
  // (--planes auto); tiles of closed scenes are not searched (PlaneFitOptions::
  // min_zero_width_share), so they build as without. VS-DAG has no plane tiles: ignored there.
  bool planes = true;
  PlaneFitOptions plane_fit;  // which blocks are tried (plane_fit.hpp)
  // Plane tiles stored packed (PackParams::pack_plane_tiles, feature packed_plane_tiles).
  bool pack_plane_tiles = true;
  // Their labels predicted from their planes (PackParams::predict_plane_labels).
  bool predict_plane_labels = true;
  // With dagmh_mixed_tiles: encode every tile both ways (TileCodec::dagmh_or_mmh(true)),
  // instead of only where the share of zero-width intervals leaves the winner unsure.
  bool dagmh_mixed_exhaustive = false;
  // Build only the cells touching this region; every other cell is the constant
  // kLitDepth (a partial map: only texels inside the region are traced and lossless).
  std::optional<TexelRegion> region;
  // Build only this shard's cells into a part file at the output path (build parameter
  // shard=I/N, no grid or index: merge_parts() joins the parts into the pack).
  std::optional<BuildShard> shard;
  // Cells built by other processes as well as this one's threads (not owned).
  RemoteCells* remote = nullptr;
  std::string scene_spec, light_spec;  // provenance written into the pack's params
  // Called from a background thread about 5 times a second with the progress so far.
  std::function<void(uint64_t cells_done, uint64_t cells_total, uint64_t texels_done)> progress;
  // Called once every cell is appended, before the skip grid and index are written (not
  // for part files): appends the deep tiles (deep_build.hpp, append_deep_map).
  std::function<void(PackWriter&)> before_finish;
  // Test hook: stop (throw st::Error "interrupted") after this many cells were appended.
  std::optional<uint64_t> stop_after_cells;
  // Set from another thread (e.g. SIGINT) to stop at the next cell; "<out>.tmp" remains.
  std::atomic<bool>* cancel = nullptr;
};

struct MapBuildReport {
  uint32_t map_level = 0, skip_level = 0;
  std::string encoding;
  std::string builder;  // "raster" or "embree"
  uint64_t cells_total = 0, cells_built = 0, cells_resumed = 0, cells_outside_region = 0;
  uint64_t texels_traced = 0;
  uint64_t texels_in_regions = 0;  // RasterSkip::regions: texels answered by proven regions, not traced
  bool exit_depths = false;
  double wall_seconds = 0;
  // Thread-seconds per stage (summed over workers).
  double trace_seconds = 0, hierarchy_seconds = 0, cut_encode_seconds = 0, write_seconds = 0,
         finish_seconds = 0, bvh_seconds = 0;
  uint64_t pack_bytes = 0, tile_count = 0, index_tile_count = 0;
  uint64_t constant_entries = 0, grid_entries = 0;
  std::vector<uint64_t> stored_bytes_per_level;      // by tile root level
  std::vector<std::pair<uint64_t, uint64_t>> tile_size_histogram;  // (upper bound bytes, count)
  uint64_t peak_rss_bytes = 0;
  // The DAG-MH dictionary (PackWriter::dictionary_outcome): bytes 0 = none written.
  uint64_t dictionary_bytes = 0, dictionary_tiles_rewritten = 0, dictionary_raw_before = 0, dictionary_raw_after = 0;
  std::string dictionary_skipped;  // why none was written although asked
  std::string to_json() const;
};

// Builds the pack (or with options.shard, the part file) at `out_path` (written as "<out_path>.tmp", renamed when complete).
MapBuildReport build_map(const Scene& scene, const LightSpace& light, const MapBuildOptions& options,
                         const std::string& out_path);

// One cell's journal bytes (encode_cell_bytes), built exactly as build_map() builds it:
// the worker side of a distributed build. Construct it with the options build_map()
// gets (shard and region do not matter here); build() may run on several threads.
class CellBuilder {
 public:
  CellBuilder(const Scene& scene, const LightSpace& light, const MapBuildOptions& options);
  ~CellBuilder();
  CellBuilder(const CellBuilder&) = delete;
  CellBuilder& operator=(const CellBuilder&) = delete;
  std::vector<uint8_t> build(uint32_t cx, uint32_t cy) const;
  uint64_t texels_traced() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Peak resident set size of this process so far (getrusage), in bytes.
uint64_t peak_rss_bytes();

}  // namespace st

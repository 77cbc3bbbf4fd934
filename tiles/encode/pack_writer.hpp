// Writes a pack file (pack_format.hpp, tiles/PACK.md) cell by cell, so a map larger than
// memory is built one level-K cell at a time, and a killed build resumes.
//
//   auto w = PackWriter::create_or_resume("out.pack", pack_params);   // "out.pack.tmp"
//   TileCutter cutter(cut_params);
//   for each cell (cx, cy) with !w->is_done(cx, cy)       // any order, any thread
//     w->append_cell(cutter.cut_cell(cx, cy, build_hierarchy(intervals of the cell)));
//   w->finish(cutter.coarse_grid(w->cells(), build_coarse));  // fsync + rename
//
// Durability: append_cell writes the cell's tile records then its cell record; a cell
// counts as done only once its cell record is complete and its CRCs check. Nothing is
// fsynced per cell (a crash may lose the last cells, never corrupt earlier ones: resume
// cuts the torn tail). finish() fsyncs the file, renames it and fsyncs the directory.
// Destroying a writer without finish() leaves the .tmp for resume.
//
// A cell's journal bytes (its tile records, payloads included, then its cell record, one
// contiguous span: encode_cell_bytes) are also what a part file holds and what another
// build process hands over: append_cell_bytes() checks such a span record by record
// (CRCs, sizes, ids, the cell's own tile last) before it appends it.
//
// Thread safety: append_cell may be called concurrently (compression runs outside the
// lock; the records of one cell are written contiguously). Errors: st::Error naming the
// file; after an I/O error the writer refuses further appends.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/pack_format.hpp"
#include "tiles/encode/tile_cut.hpp"

namespace st {

inline constexpr uint32_t kDefaultPreviewLevels = 3;
inline constexpr uint64_t kDefaultPreviewMaxBytes = 4ull << 20;
// The DAG-MH dictionary pass holds every encoded tile's raw bytes and a key per node:
// above this many raw tile bytes finish() writes no dictionary (and says why).
inline constexpr uint64_t kDefaultDictionaryMaxInputBytes = 512ull << 20;

struct PackParams {
  LightKind light_kind = LightKind::sun;
  std::array<double, 18> light{};  // LightSpace::to_array()
  uint32_t map_level = 0, skip_level = 0;
  Encoding encoding = Encoding::mh;
  uint32_t tile_bytes = kDefaultTileBytes;
  uint64_t scene_hash = 0;
  uint32_t features = 0;  // what the builder knows: kFeatureExitDepths, kFeatureDeepShadow,
                          // kFeatureStaticIntervals
  PackParamList build_params;  // free-form provenance (scene path, light spec, tool version)
  int compression_level = 6;   // libdeflate 0..12: build speed vs. file size
  // The map preview (tiles/PACK.md "Map preview"): levels K+1 .. K+p below the skip grid,
  // p = min(preview_levels, L - K), one level fewer while it exceeds preview_max_bytes.
  uint32_t preview_levels = kDefaultPreviewLevels;
  uint64_t preview_max_bytes = kDefaultPreviewMaxBytes;
  // DAG-MH only: finish() moves every subtree found in two or more tiles into one
  // pack-wide dictionary and rewrites the tiles that use it as version 2 (tiles/PACK.md
  // "DAG-MH dictionary"); answers stay bit-identical. Not a resume parameter: the journal
  // always holds the tiles as encoded.
  bool dagmh_dictionary = false;
  uint64_t dictionary_max_input_bytes = kDefaultDictionaryMaxInputBytes;
  // Store the grid section as one zlib stream (feature compressed_grid, tiles/PACK.md
  // "Compressed grid section"); off writes it raw (tests that patch its bytes in place).
  bool compress_grid = true;
  // Keep the build journal's records in the finished pack (the layout before feature
  // payloads_only, with the plain tile index): tests of verify()'s cell-record checks.
  // Not with a DAG-MH dictionary that rewrites tiles (finish() throws).
  bool journal_records = false;
  // Store each plane tile packed ("STPQ", tiles/core/plane_pack.hpp, feature
  // packed_plane_tiles) where that deflates smaller; readers unpack it as they load, so
  // answers and raw sizes are unchanged. Off writes STPN as before.
  bool pack_plane_tiles = true;
  // Packed plane tiles store their labels against a prediction from their planes ("STPL",
  // feature predicted_plane_labels); off packs them as "STPQ".
  bool predict_plane_labels = true;

  static PackParams from(const LightSpace& light, const CutParams& cut);
};

// What finish() did about the DAG-MH dictionary (PackParams::dagmh_dictionary).
struct DictionaryOutcome {
  uint64_t bytes = 0;  // the dictionary written (0: none)
  uint64_t tiles = 0, tiles_rewritten = 0, raw_before = 0, raw_after = 0;  // encoded tiles' raw bytes
  uint32_t min_tiles = 0;  // subtrees shared by at least this many tiles (2, more if it had to shrink)
  std::string skipped;     // why none was written although asked; "" otherwise
};

class PackWriter {
 public:
  // Starts "<path>.tmp" afresh (an old one is overwritten).
  static std::unique_ptr<PackWriter> create(const std::string& path, const PackParams& params);
  // Reopens "<path>.tmp" left by a killed build: checks that it was started with the same
  // parameters (st::Error naming the field otherwise), keeps every complete cell and
  // truncates the rest.
  static std::unique_ptr<PackWriter> resume(const std::string& path, const PackParams& params);
  // resume() if "<path>.tmp" exists, else create().
  static std::unique_ptr<PackWriter> create_or_resume(const std::string& path, const PackParams& params);
  ~PackWriter();
  PackWriter(const PackWriter&) = delete;
  PackWriter& operator=(const PackWriter&) = delete;

  const std::string& path() const { return path_; }
  std::string tmp_path() const { return path_ + ".tmp"; }
  const PackParams& params() const { return params_; }

  // Cells done so far (resumed ones included) and what resume found.
  std::vector<CellRecord> cells() const;
  bool is_done(uint32_t cx, uint32_t cy) const;
  size_t resumed_cells() const { return resumed_cells_; }
  uint64_t truncated_bytes() const { return truncated_bytes_; }  // torn tail cut by resume

  // Compresses the cell's tiles and appends them and its cell record. Throws st::Error if
  // the cell is out of range or already done, or a tile breaks the tile_bytes bound.
  void append_cell(const CutCell& cell);

  // Appends a span encode_cell_bytes() made (here or in another process), after checking
  // every record in it; st::Error naming the cell or byte offset otherwise.
  void append_cell_bytes(std::span<const uint8_t> bytes);

  // A deep tile or the deep directory (tiles/PACK.md "Deep tiles", deep_pack.hpp), once
  // every cell is done and before finish(): `kind` deep or deep_directory with an id that
  // fits it (id_fits_kind), 1..tile_bytes raw bytes, compressed like any tile. finish()
  // sets the deep_shadow feature when they are there (the directory is then required).
  // Not journalled for resume: records after the last cell record are a torn tail to
  // replay, so a resumed build appends them again. st::Error otherwise.
  void append_deep_tile(uint64_t id, TileKind kind, std::span<const uint8_t> raw);

  // A part file (one shard of the cells, tiles/PACK.md "Part files"): fsyncs the journal
  // as it is (state building) and renames "<path>.tmp" to "<path>". No grid, no index.
  void finish_part();

  // Writes the finished pack (feature payloads_only, tiles/PACK.md "Payloads only") afresh
  // as "<path>.final.tmp": header and params, every tile's stored payload back to back in
  // id order (no journal records; with PackParams::dagmh_dictionary and something shared,
  // the rewritten tiles in place of theirs), the skip grid (entries must equal the cells'
  // entries), the map preview (read back from the journal's tiles), the dictionary, the
  // tile index; fsyncs it, renames it to "<path>" and only then removes "<path>.tmp", so
  // a build killed meanwhile still resumes from its untouched journal.
  void finish(const CutGrid& grid);
  const DictionaryOutcome& dictionary_outcome() const { return dictionary_; }

 private:
  void publish(const std::string& what);  // under mu_, after the last fsync
  PackWriter(std::string path, PackParams params);
  void open_new();
  void open_existing();
  void write_at(uint64_t offset, std::span<const uint8_t> bytes);
  PackHeader base_header() const;
  std::vector<uint8_t> preview_bytes(const CutGrid& grid) const;  // under mu_, tiles_ sorted
  // finish()'s dictionary pass (pack_writer_dictionary.cpp), under mu_ with tiles_ sorted:
  // the dictionary's raw bytes and in `rewritten` (sorted by id) the tiles that reference
  // it; empty (dictionary_.skipped says why) when none applies.
  using RewrittenTiles = std::vector<std::pair<uint64_t, std::vector<uint8_t>>>;
  // must_pay (mixed tiles): only a dictionary whose stored section is smaller than the
  // stored bytes it saves the tiles.
  std::vector<uint8_t> share_dictionary(RewrittenTiles& rewritten, bool must_pay);
  // The features the encoded tiles' kinds call for: kFeatureMixedTiles (a DAG-MH pack with
  // an MMH tile, also inside a plane tile), kFeaturePlaneTiles (a plane tile) and what its
  // stored form needs (plane_tile_features: packed forms, wide_plane_blocks for version 3).
  uint32_t tile_kind_features() const;  // under mu_
  // finish()'s file: `h` complete but for the offsets, sizes and CRCs it fills.
  void write_finished(PackHeader h, std::vector<uint8_t> grid_bytes, const RewrittenTiles& rewritten);
  // PackParams::journal_records: the old layout, finished in place.
  void finish_with_records(PackHeader h, std::vector<uint8_t> grid_bytes, const RewrittenTiles& rewritten);

  std::string path_;
  PackParams params_;
  int fd_ = -1;
  mutable std::mutex mu_;
  uint64_t end_ = 0;  // append position
  bool failed_ = false, finished_ = false;
  std::vector<uint8_t> done_;  // per cell, row-major
  std::vector<CellRecord> cells_;
  std::vector<TileIndexEntry> tiles_;
  size_t resumed_cells_ = 0;
  uint64_t truncated_bytes_ = 0;
  DictionaryOutcome dictionary_;
};

// The cell's journal bytes: each tile zlib-compressed at params.compression_level behind
// its tile record, then the cell record. Throws st::Error if a tile breaks the tile_bytes
// bound or the entry disagrees with the tiles. Const: call it from any thread or process.
std::vector<uint8_t> encode_cell_bytes(const CutCell& cell, const PackParams& params);

// Checks a span that holds exactly one cell's records for a pack of `params` (header and
// payload CRCs, tile sizes within tile_bytes, the cell inside the skip grid, its own tile
// last and of its entry's kind); fills the cell and its tiles (offsets of the payloads
// relative to the span). Throws st::Error naming `what` and the byte offset.
CellRecord parse_cell_bytes(std::span<const uint8_t> bytes, const PackParams& params, const std::string& what,
                            std::vector<TileIndexEntry>& tiles);

// Replays a journal read through `fd` from `begin` to `file_size`: calls `on_cell` with each
// complete cell (its record, its tiles with absolute offsets, and the byte span
// [span_begin, span_end) its records fill); stops at the first torn or corrupt record, or
// when `on_cell` returns false. Returns the end of the last complete cell.
using JournalCellFn = std::function<bool(const CellRecord& cell, std::vector<TileIndexEntry>&& tiles,
                                         uint64_t span_begin, uint64_t span_end)>;
uint64_t replay_journal(int fd, uint64_t begin, uint64_t file_size, const PackParams& params,
                        const std::string& what, const JournalCellFn& on_cell);

// Convenience for maps that fit in memory: cuts `h` (cut_hierarchy) and writes the pack.
void write_pack(const std::string& path, const Hierarchy& h, const CutParams& cut, const PackParams& params);

}  // namespace st
